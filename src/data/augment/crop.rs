//! The paper's random `crop × crop` window: one uniform position per item from the main
//! stream; instances left without a pixel are dropped (and, when the pipeline warps,
//! pastes or flips vertically, those under [`MIN_INSTANCE_PX`]: a sliver is not a target).

use std::borrow::Cow;

use rand::Rng;

use super::step::{Augment, AugmentState, MIN_INSTANCE_PX};
use crate::annotations::mask::Mask;
use crate::data::dataset::{Instance, Sample};

/// A random window of at most `size × size` (the whole image along a shorter side).
pub struct Crop {
    pub size: u32,
    /// Also drop instances under [`MIN_INSTANCE_PX`] pixels.
    pub drop_slivers: bool,
}

impl Augment for Crop {
    fn name(&self) -> &'static str {
        "crop"
    }
    fn apply<'s>(&self, s: Cow<'s, Sample>, st: &mut AugmentState) -> Cow<'s, Sample> {
        let (w, h) = s.image.dimensions();
        let cw = self.size.min(w);
        let ch = self.size.min(h);
        let x0 = st.rng.random_range(0..=w - cw);
        let y0 = st.rng.random_range(0..=h - ch);
        let image = image::imageops::crop_imm(&s.image, x0, y0, cw, ch).to_image();
        let mut instances: Vec<Instance> = s
            .instances
            .iter()
            .filter_map(|inst| {
                let mut m = Mask::new(ch, cw);
                for y in 0..ch {
                    let row = ((y0 + y) * inst.mask.width + x0) as usize;
                    m.data[(y * cw) as usize..((y + 1) * cw) as usize]
                        .copy_from_slice(&inst.mask.data[row..row + cw as usize]);
                }
                (m.area() > 0).then_some(Instance {
                    class: inst.class,
                    mask: m,
                })
            })
            .collect();
        if self.drop_slivers {
            instances.retain(|i| i.mask.area() >= MIN_INSTANCE_PX);
        }
        Cow::Owned(Sample { image, instances })
    }
}
