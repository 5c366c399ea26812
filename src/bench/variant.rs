//! Model variants by name (`yolo-n-p45-w0.5`, `mrcnn-r50`, `mrcnn-r50-paper`, `m2f-r18`,
//! …): what `bench models --variants` parses, what a `bench model-worker` child is told to
//! build, and what a checkpoint's model config is timed as. Each family names its own
//! variants (`Family::parse_variant`, `variant_name`, `variant_config` in
//! `model/<family>/family.rs`); this wrapper keeps the round trip through
//! [`std::fmt::Display`] and the one error text that lists every family's names.

use std::str::FromStr;

use anyhow::{bail, Result};

use crate::infer::detector::DetectorConfig;

/// A model variant by name: the one-class model it names, at its family's default size.
#[derive(Clone, Debug, PartialEq)]
pub struct Variant {
    config: DetectorConfig,
}

impl FromStr for Variant {
    type Err = anyhow::Error;
    fn from_str(s: &str) -> Result<Variant> {
        let help = DetectorConfig::variant_help();
        match DetectorConfig::parse_variant(s) {
            Some(Ok(config)) => Ok(Variant { config }),
            Some(Err(e)) => bail!("{e}; expected {help}"),
            None => bail!("unknown model variant {s:?}; expected {help}"),
        }
    }
}

impl std::fmt::Display for Variant {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.config.variant_name())
    }
}

impl Variant {
    /// The variant of a model config (e.g. a checkpoint's): the family's preset that the
    /// config's sizes match (see each family's `variant_name`).
    pub fn of_detector(c: &DetectorConfig) -> Variant {
        Variant {
            config: c.variant_config(),
        }
    }

    /// The one-class model this variant names at `size` px.
    pub fn config(&self, size: usize) -> DetectorConfig {
        let mut c = self.config.clone();
        c.set_input_size(size);
        c
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::mask2former::Mask2FormerConfig;
    use crate::model::maskrcnn::MaskRcnnConfig;
    use crate::model::yolo::{HeadLevels, Scale, YoloSegConfig};

    #[test]
    fn variant_names_round_trip_and_reject_junk() {
        for s in [
            "yolo-n",
            "yolo-s-p45",
            "yolo-n-nopsa-w0.5-m16",
            "mrcnn-r101",
            "m2f-r50",
            "m2f-r18-paper",
        ] {
            assert_eq!(s.parse::<Variant>().unwrap().to_string(), s);
        }
        let v: Variant = "yolo-n-m16-p45".parse().unwrap();
        assert_eq!(v.to_string(), "yolo-n-p45-m16");
        assert_eq!(
            v.config(320),
            DetectorConfig::Yolo(
                YoloSegConfig::new(Scale::N, 1)
                    .with_input_size(320)
                    .with_levels(HeadLevels::P4P5)
                    .with_num_masks(16)
            )
        );
        for bad in [
            "yolo",
            "yolo-x",
            "yolo-n-q",
            "yolo-n-w0",
            "yolo-n-m0",
            "mrcnn-r19",
            "m2f-r42",
            "m2f-r50-big",
            "rcnn",
        ] {
            let e = bad.parse::<Variant>().unwrap_err().to_string();
            assert!(e.contains(bad), "{e}");
            assert!(
                e.contains("yolo-n / yolo-s") && e.contains("or m2f-r18"),
                "every family's names in the message: {e}"
            );
        }
    }

    #[test]
    fn mask2former_variants_build_their_presets() {
        let v: Variant = "m2f-r50-paper".parse().unwrap();
        let mut want = Mask2FormerConfig::paper(50, 1);
        want.input_size = 640;
        assert_eq!(v.config(640), DetectorConfig::Mask2former(want.clone()));
        assert_eq!(Variant::of_detector(&DetectorConfig::Mask2former(want)), v);
        let c = Mask2FormerConfig::new(18, 1);
        assert_eq!(
            Variant::of_detector(&DetectorConfig::Mask2former(c)).to_string(),
            "m2f-r18"
        );
    }

    #[test]
    fn paper_variant_parses_round_trips_and_builds_the_paper_preset() {
        for d in [18, 34, 50, 101] {
            let s = format!("mrcnn-r{d}-paper");
            let v: Variant = s.parse().unwrap();
            assert_eq!(
                v.config(800),
                DetectorConfig::Maskrcnn(MaskRcnnConfig::paper(d, 1))
            );
            assert_eq!(v.to_string(), s);
        }
        let v: Variant = "mrcnn-r50-paper".parse().unwrap();
        assert_eq!(
            v.config(512),
            DetectorConfig::Maskrcnn(MaskRcnnConfig::paper(50, 1).with_input_size(512))
        );
        let compact: Variant = "mrcnn-r50".parse().unwrap();
        assert_eq!(
            compact.config(512),
            DetectorConfig::Maskrcnn(MaskRcnnConfig::new(50, 1).with_input_size(512))
        );
        for bad in [
            "mrcnn-r50-Paper",
            "mrcnn-r50-paper-x",
            "mrcnn-r50-p45",
            "mrcnn-r19-paper",
        ] {
            let e = bad.parse::<Variant>().unwrap_err().to_string();
            assert!(e.contains(bad), "{e}");
        }
    }

    #[test]
    fn a_checkpoint_config_maps_to_its_preset() {
        let of = |c: MaskRcnnConfig| Variant::of_detector(&DetectorConfig::Maskrcnn(c));
        assert_eq!(
            of(MaskRcnnConfig::paper(50, 3)).to_string(),
            "mrcnn-r50-paper"
        );
        assert_eq!(of(MaskRcnnConfig::new(101, 1)).to_string(), "mrcnn-r101");
        assert_eq!(
            of(MaskRcnnConfig::new(34, 1).with_fpn_channels(256)).to_string(),
            "mrcnn-r34-paper"
        );
        assert_eq!(
            of(MaskRcnnConfig::paper(50, 3).with_input_size(640)),
            "mrcnn-r50-paper".parse().unwrap(),
            "timed as the one-class preset"
        );
        let y = YoloSegConfig::new(Scale::S, 4)
            .with_input_size(256)
            .with_c2psa(false)
            .with_width_mult(0.5);
        let v = Variant::of_detector(&DetectorConfig::Yolo(y));
        assert_eq!(v.to_string(), "yolo-s-nopsa-w0.5");
        assert_eq!(v, "yolo-s-nopsa-w0.5".parse().unwrap());
    }
}
