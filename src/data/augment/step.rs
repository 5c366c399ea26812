//! One augmentation of the training pipeline ([`Augment`]: a type with one `apply`, as
//! ultralytics' transforms in `Compose` and detectron2's `Augmentation`s in an
//! `AugmentationList`) and what the list hands from one augmentation to the next
//! ([`AugmentState`]: the item's two random streams, its partner samples, and the canvas
//! a mosaic leaves for the affine warp).

use std::borrow::Cow;

use rand::RngCore;

use crate::data::dataset::Sample;

/// Instances with fewer visible pixels after a warp, mosaic or paste are dropped: a few
/// pixels of a carcass is not a fair target (ultralytics' `box_candidates` does the same
/// after `RandomPerspective`).
pub const MIN_INSTANCE_PX: u64 = 4;

/// The samples an item's [`super::Partners`] named, loaded.
#[derive(Default)]
pub struct PartnerSamples<'a> {
    pub copy_paste: Option<&'a Sample>,
    pub mosaic: Option<Vec<&'a Sample>>,
}

/// What the augmentations of one item share.
pub struct AugmentState<'r, 'p> {
    /// The item's main stream: crop, horizontal flip and HSV draw from it, in that order,
    /// exactly as before the other augmentations existed.
    pub rng: &'r mut dyn RngCore,
    /// The second stream: copy-paste, mosaic, affine warp and vertical flip draw from it,
    /// so a config with them all off draws from `rng` as it always did.
    pub extra: &'r mut dyn RngCore,
    pub partners: &'p PartnerSamples<'p>,
    /// Set by a mosaic: the canvas it made (the affine warp's source size) and the item's
    /// size, which the warp maps back to.
    pub canvas: Option<((u32, u32), (u32, u32))>,
}

/// One augmentation.
pub trait Augment {
    /// Its name in the list (`"crop"`, `"fliplr"`, …).
    fn name(&self) -> &'static str;
    /// The augmented sample; `s` itself (still borrowed) when this one did nothing.
    fn apply<'s>(&self, s: Cow<'s, Sample>, st: &mut AugmentState) -> Cow<'s, Sample>;
}
