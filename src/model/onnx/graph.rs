//! A small ONNX graph builder over tract-onnx's generated protobuf types, encoded with
//! prost (no protoc, no Python). It knows the dozen opset-17 operators an exported
//! detector needs; every node gets a unique, readable name (`/l4/cv1/Conv`), as the
//! PyTorch exporter names them, so a graph viewer shows where a node came from.

use anyhow::{ensure, Result};
use prost::Message;
use tract_onnx::pb::{
    attribute_proto::AttributeType, tensor_proto::DataType, tensor_shape_proto, type_proto,
    AttributeProto, GraphProto, ModelProto, NodeProto, OperatorSetIdProto, StringStringEntryProto,
    TensorProto, TensorShapeProto, TypeProto, ValueInfoProto,
};

/// The opset the exported graphs declare (ultralytics' export supports ≥ 17 for
/// segmentation; 17 is the oldest that every current runtime reads).
pub const OPSET: i64 = 17;
/// IR version 8 goes with opset 17 (ONNX 1.12); ultralytics caps its files at 10.
pub const IR_VERSION: i64 = 8;

/// One dimension of a graph input or output: fixed or named (symbolic).
#[derive(Debug, Clone, PartialEq)]
pub enum Dim {
    Fixed(usize),
    Named(String),
}

/// Builds a graph node by node. Values are referred to by name (`String`).
#[derive(Default)]
pub struct GraphBuilder {
    nodes: Vec<NodeProto>,
    initializers: Vec<TensorProto>,
    inputs: Vec<ValueInfoProto>,
    outputs: Vec<ValueInfoProto>,
    used: std::collections::HashSet<String>,
}

fn attr_int(name: &str, v: i64) -> AttributeProto {
    AttributeProto {
        name: name.into(),
        r#type: AttributeType::Int as i32,
        i: v,
        ..Default::default()
    }
}

fn attr_ints(name: &str, v: &[i64]) -> AttributeProto {
    AttributeProto {
        name: name.into(),
        r#type: AttributeType::Ints as i32,
        ints: v.to_vec(),
        ..Default::default()
    }
}

fn attr_str(name: &str, v: &str) -> AttributeProto {
    AttributeProto {
        name: name.into(),
        r#type: AttributeType::String as i32,
        s: v.as_bytes().to_vec(),
        ..Default::default()
    }
}

fn value_info(name: &str, dims: &[Dim]) -> ValueInfoProto {
    let dim = dims
        .iter()
        .map(|d| tensor_shape_proto::Dimension {
            denotation: String::new(),
            value: Some(match d {
                Dim::Fixed(n) => tensor_shape_proto::dimension::Value::DimValue(*n as i64),
                Dim::Named(s) => tensor_shape_proto::dimension::Value::DimParam(s.clone()),
            }),
        })
        .collect();
    ValueInfoProto {
        name: name.into(),
        r#type: Some(TypeProto {
            denotation: String::new(),
            value: Some(type_proto::Value::TensorType(type_proto::Tensor {
                elem_type: DataType::Float as i32,
                shape: Some(TensorShapeProto { dim }),
            })),
        }),
        ..Default::default()
    }
}

impl GraphBuilder {
    pub fn new() -> Self {
        Self::default()
    }

    /// A name not used yet: `base`, else `base_1`, `base_2`, …
    fn unique(&mut self, base: &str) -> String {
        let mut name = base.to_string();
        let mut k = 0;
        while self.used.contains(&name) {
            k += 1;
            name = format!("{base}_{k}");
        }
        self.used.insert(name.clone());
        name
    }

    pub fn input(&mut self, name: &str, dims: &[Dim]) -> String {
        self.used.insert(name.into());
        self.inputs.push(value_info(name, dims));
        name.into()
    }

    /// Marks `value` as the graph output `name` (through an Identity node when the value
    /// already carries another name).
    pub fn output(&mut self, value: &str, name: &str, dims: &[Dim]) {
        if value != name {
            self.used.insert(name.into());
            self.nodes.push(NodeProto {
                input: vec![value.into()],
                output: vec![name.into()],
                name: format!("{name}/Identity"),
                op_type: "Identity".into(),
                ..Default::default()
            });
        }
        self.outputs.push(value_info(name, dims));
    }

    /// A float initializer (little-endian raw data).
    pub fn constant_f32(&mut self, base: &str, dims: &[usize], data: &[f32]) -> String {
        assert_eq!(
            dims.iter().product::<usize>(),
            data.len(),
            "initializer {base}: shape {dims:?} does not hold {} values",
            data.len()
        );
        let name = self.unique(base);
        let mut raw = Vec::with_capacity(data.len() * 4);
        for v in data {
            raw.extend_from_slice(&v.to_le_bytes());
        }
        self.initializers.push(TensorProto {
            dims: dims.iter().map(|&d| d as i64).collect(),
            data_type: DataType::Float as i32,
            name: name.clone(),
            raw_data: raw,
            ..Default::default()
        });
        name
    }

    /// A 1-D int64 initializer (shapes, split sizes, axes).
    pub fn constant_i64(&mut self, base: &str, data: &[i64]) -> String {
        let name = self.unique(base);
        let mut raw = Vec::with_capacity(data.len() * 8);
        for v in data {
            raw.extend_from_slice(&v.to_le_bytes());
        }
        self.initializers.push(TensorProto {
            dims: vec![data.len() as i64],
            data_type: DataType::Int64 as i32,
            name: name.clone(),
            raw_data: raw,
            ..Default::default()
        });
        name
    }

    /// Adds a node and returns its output names (`n_out` of them).
    pub fn node(
        &mut self,
        scope: &str,
        op: &str,
        inputs: &[&str],
        n_out: usize,
        attributes: Vec<AttributeProto>,
    ) -> Vec<String> {
        let name = self.unique(&format!("{scope}/{op}"));
        let outputs: Vec<String> = (0..n_out)
            .map(|k| self.unique(&format!("{name}_output_{k}")))
            .collect();
        self.nodes.push(NodeProto {
            input: inputs.iter().map(|s| s.to_string()).collect(),
            output: outputs.clone(),
            name,
            op_type: op.into(),
            attribute: attributes,
            ..Default::default()
        });
        outputs
    }

    fn one(
        &mut self,
        scope: &str,
        op: &str,
        inputs: &[&str],
        attrs: Vec<AttributeProto>,
    ) -> String {
        self.node(scope, op, inputs, 1, attrs).remove(0)
    }

    /// The inputs of a convolution node: `x`, the weight initializer and, if given, the
    /// bias initializer of `bias_len` values (`scope.weight`, `scope.bias`).
    fn weighted_inputs(
        &mut self,
        scope: &str,
        x: &str,
        (wd, wv): (&[usize; 4], &[f32]),
        bias: Option<&[f32]>,
        bias_len: usize,
    ) -> Vec<String> {
        let w = self.constant_f32(&format!("{scope}.weight"), wd, wv);
        let mut inputs = vec![x.to_string(), w];
        if let Some(b) = bias {
            inputs.push(self.constant_f32(&format!("{scope}.bias"), &[bias_len], b));
        }
        inputs
    }

    /// `Conv` with symmetric padding `pad`, `stride`, `groups`; `weight` is
    /// `[c_out, c_in / groups, kh, kw]` (the layout of both Burn and ONNX).
    #[allow(clippy::too_many_arguments)]
    pub fn conv(
        &mut self,
        scope: &str,
        x: &str,
        weight: (&[usize; 4], &[f32]),
        bias: Option<&[f32]>,
        stride: [usize; 2],
        pad: [usize; 2],
        groups: usize,
    ) -> String {
        let wd = weight.0;
        let inputs = self.weighted_inputs(scope, x, weight, bias, wd[0]);
        let refs: Vec<&str> = inputs.iter().map(String::as_str).collect();
        self.one(
            scope,
            "Conv",
            &refs,
            vec![
                attr_ints("dilations", &[1, 1]),
                attr_int("group", groups as i64),
                attr_ints("kernel_shape", &[wd[2] as i64, wd[3] as i64]),
                attr_ints(
                    "pads",
                    &[pad[0] as i64, pad[1] as i64, pad[0] as i64, pad[1] as i64],
                ),
                attr_ints("strides", &[stride[0] as i64, stride[1] as i64]),
            ],
        )
    }

    /// `ConvTranspose` without padding; `weight` is `[c_in, c_out / groups, kh, kw]`.
    pub fn conv_transpose(
        &mut self,
        scope: &str,
        x: &str,
        weight: (&[usize; 4], &[f32]),
        bias: Option<&[f32]>,
        stride: [usize; 2],
    ) -> String {
        let wd = weight.0;
        let inputs = self.weighted_inputs(scope, x, weight, bias, wd[1]);
        let refs: Vec<&str> = inputs.iter().map(String::as_str).collect();
        self.one(
            scope,
            "ConvTranspose",
            &refs,
            vec![
                attr_ints("dilations", &[1, 1]),
                attr_int("group", 1),
                attr_ints("kernel_shape", &[wd[2] as i64, wd[3] as i64]),
                attr_ints("pads", &[0, 0, 0, 0]),
                attr_ints("strides", &[stride[0] as i64, stride[1] as i64]),
            ],
        )
    }

    /// SiLU as PyTorch exports it at opset 17: `x · sigmoid(x)`.
    pub fn silu(&mut self, scope: &str, x: &str) -> String {
        let s = self.sigmoid(scope, x);
        self.binary(scope, "Mul", x, &s)
    }

    pub fn relu(&mut self, scope: &str, x: &str) -> String {
        self.one(scope, "Relu", &[x], vec![])
    }

    pub fn sigmoid(&mut self, scope: &str, x: &str) -> String {
        self.one(scope, "Sigmoid", &[x], vec![])
    }

    /// `Add`, `Sub`, `Mul`, `Div` or `MatMul` (numpy broadcasting).
    pub fn binary(&mut self, scope: &str, op: &str, a: &str, b: &str) -> String {
        self.one(scope, op, &[a, b], vec![])
    }

    pub fn concat(&mut self, scope: &str, xs: &[&str], axis: i64) -> String {
        self.one(scope, "Concat", xs, vec![attr_int("axis", axis)])
    }

    /// `Split` along `axis` into pieces of `sizes` (opset ≥ 13: sizes as an input).
    pub fn split(&mut self, scope: &str, x: &str, axis: i64, sizes: &[usize]) -> Vec<String> {
        let s = self.constant_i64(
            &format!("{scope}.split"),
            &sizes.iter().map(|&v| v as i64).collect::<Vec<_>>(),
        );
        self.node(
            scope,
            "Split",
            &[x, &s],
            sizes.len(),
            vec![attr_int("axis", axis)],
        )
    }

    /// `Reshape` to `shape` (0 copies the input's dimension, −1 is inferred: with a
    /// symbolic batch the batch dimension is always written as 0).
    pub fn reshape(&mut self, scope: &str, x: &str, shape: &[i64]) -> String {
        let s = self.constant_i64(&format!("{scope}.shape"), shape);
        self.one(scope, "Reshape", &[x, &s], vec![])
    }

    pub fn transpose(&mut self, scope: &str, x: &str, perm: &[i64]) -> String {
        self.one(scope, "Transpose", &[x], vec![attr_ints("perm", perm)])
    }

    pub fn softmax(&mut self, scope: &str, x: &str, axis: i64) -> String {
        self.one(scope, "Softmax", &[x], vec![attr_int("axis", axis)])
    }

    pub fn max_pool(
        &mut self,
        scope: &str,
        x: &str,
        k: usize,
        stride: usize,
        pad: usize,
    ) -> String {
        let (k, s, p) = (k as i64, stride as i64, pad as i64);
        self.one(
            scope,
            "MaxPool",
            &[x],
            vec![
                attr_int("ceil_mode", 0),
                attr_ints("dilations", &[1, 1]),
                attr_ints("kernel_shape", &[k, k]),
                attr_ints("pads", &[p, p, p, p]),
                attr_ints("strides", &[s, s]),
            ],
        )
    }

    /// Nearest 2× upsampling as `nn.Upsample(scale_factor=2)` exports it: output pixel
    /// `i` reads input `floor(i / 2)` (asymmetric coordinates, floor), which is also
    /// Burn's nearest `interpolate`.
    pub fn upsample2x(&mut self, scope: &str, x: &str) -> String {
        let scales = self.constant_f32(&format!("{scope}.scales"), &[4], &[1.0, 1.0, 2.0, 2.0]);
        self.one(
            scope,
            "Resize",
            &[x, "", &scales],
            vec![
                attr_str("coordinate_transformation_mode", "asymmetric"),
                attr_str("mode", "nearest"),
                attr_str("nearest_mode", "floor"),
            ],
        )
    }

    /// Multiplies by a scalar constant.
    pub fn mul_scalar(&mut self, scope: &str, x: &str, v: f32) -> String {
        let c = self.constant_f32(&format!("{scope}.scalar"), &[], &[v]);
        self.binary(scope, "Mul", x, &c)
    }

    /// The finished model: `graph_name`, opset [`OPSET`], string metadata (ultralytics
    /// keeps its `names`, `stride`, `imgsz`, … there).
    pub fn finish(self, graph_name: &str, metadata: &[(String, String)]) -> Result<ModelProto> {
        ensure!(
            !self.inputs.is_empty() && !self.outputs.is_empty(),
            "ONNX graph {graph_name} has no inputs or no outputs"
        );
        Ok(ModelProto {
            ir_version: IR_VERSION,
            opset_import: vec![OperatorSetIdProto {
                domain: String::new(),
                version: OPSET,
            }],
            producer_name: "chicktrain".into(),
            producer_version: env!("CARGO_PKG_VERSION").into(),
            graph: Some(GraphProto {
                node: self.nodes,
                name: graph_name.into(),
                initializer: self.initializers,
                input: self.inputs,
                output: self.outputs,
                ..Default::default()
            }),
            metadata_props: metadata
                .iter()
                .map(|(k, v)| StringStringEntryProto {
                    key: k.clone(),
                    value: v.clone(),
                })
                .collect(),
            ..Default::default()
        })
    }
}

/// The protobuf bytes of `model`.
pub fn encode(model: &ModelProto) -> Vec<u8> {
    model.encode_to_vec()
}

/// Parses ONNX bytes (only the protobuf; no operator checks), naming `origin` on error.
pub fn decode(bytes: &[u8], origin: &std::path::Path) -> Result<ModelProto> {
    ModelProto::decode(bytes)
        .map_err(|e| anyhow::anyhow!("{} is not an ONNX model (protobuf: {e})", origin.display()))
}

/// The model's metadata entry `key`, if present.
pub fn metadata<'a>(model: &'a ModelProto, key: &str) -> Option<&'a str> {
    model
        .metadata_props
        .iter()
        .find(|e| e.key == key)
        .map(|e| e.value.as_str())
}
