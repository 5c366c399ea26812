//! The training loader, above the renderer: sources (`dataset`: the real set and the
//! synthetic renders), augmentation (`augment`, with its parts `affine`, `mosaic` and
//! `copy_paste`), batching (`batch`) into the model-neutral
//! ground truth [`crate::annotations::targets::Targets`], the letterbox between image
//! and network input, and the unlabeled photos of self-training with their pseudo-labels
//! (`unlabeled`). The COCO types it reads live in [`crate::annotations`].

#[cfg(feature = "train")]
pub mod affine;
#[cfg(feature = "train")]
pub mod augment;
#[cfg(feature = "train")]
pub mod batch;
#[cfg(feature = "train")]
pub mod copy_paste;
#[cfg(feature = "train")]
pub mod dataset;
pub mod ellipses;
pub mod letterbox;
#[cfg(feature = "train")]
pub mod mosaic;
#[cfg(feature = "train")]
pub mod unlabeled;
