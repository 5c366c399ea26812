//! The training loader, above the renderer: sources (`dataset`: the real set and the
//! synthetic renders), augmentation (`augment`), batching (`batch`) into the model-neutral
//! ground truth [`targets::Targets`], and the letterbox between image and network input.
//! The COCO types it reads live in [`crate::annotations`].

#[cfg(feature = "train")]
pub mod augment;
#[cfg(feature = "train")]
pub mod batch;
#[cfg(feature = "train")]
pub mod dataset;
pub mod ellipses;
pub mod letterbox;
pub mod targets;
