//! A tensor on the host as every weight reader returns it: shape, elements (floats as
//! f32, integers as i64) and the element type the file stored. Its own file so that the
//! readers ([`super::pytorch`], [`super::safetensors`]) and the dispatcher
//! ([`super::state_dict`]) all stand on it without importing each other.

/// Elements of a host tensor, row-major.
#[derive(Debug, Clone, PartialEq)]
pub enum HostData {
    F32(Vec<f32>),
    I64(Vec<i64>),
}

/// One tensor of a state dict.
#[derive(Debug, Clone, PartialEq)]
pub struct HostTensor {
    pub shape: Vec<usize>,
    pub data: HostData,
    /// The element type in the file (`float16`, `float32`, `int64`, …).
    pub source_dtype: &'static str,
}

impl HostTensor {
    pub fn f32(shape: Vec<usize>, v: Vec<f32>) -> Self {
        Self {
            shape,
            data: HostData::F32(v),
            source_dtype: "float32",
        }
    }

    pub fn numel(&self) -> usize {
        self.shape.iter().product()
    }

    /// The elements as f32 (integers converted).
    pub fn to_f32(&self) -> Vec<f32> {
        match &self.data {
            HostData::F32(v) => v.clone(),
            HostData::I64(v) => v.iter().map(|&x| x as f32).collect(),
        }
    }
}
