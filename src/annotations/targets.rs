//! The ground truth the loader hands to every model family: per image, boxes (xyxy in
//! input pixels), class indices and instance masks at the network input size. Host data,
//! no tensors: each model moves what it needs to its device. It sits in the foundation, not
//! in `data/`, so that the models import nothing of the loader (issue 40).

/// Ground truth of one image. Masks are row-major `H × W` at the network input size,
/// non-zero inside the instance; pixels shared by several instances go to the smaller one.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ImageTargets {
    /// xyxy in input pixels.
    pub boxes: Vec<[f32; 4]>,
    pub classes: Vec<usize>,
    /// One mask per instance, `H · W` bytes each.
    pub masks: Vec<Vec<u8>>,
}

/// Ground truth of a batch, one entry per image in batch order.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Targets {
    pub images: Vec<ImageTargets>,
}
