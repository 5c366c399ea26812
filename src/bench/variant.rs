//! Model variants by name (`yolo-n-p45-w0.5`, `mrcnn-r50`, `mrcnn-r50-paper`, …): what
//! `bench models --variants` parses, what a `bench model-worker` child is told to build,
//! and what a checkpoint's model config is timed as. Kept apart from the measuring so the
//! naming rules — and their round trip through [`std::fmt::Display`] — live in one place.

use std::str::FromStr;

use anyhow::{bail, Context, Result};

use crate::infer::detector::DetectorConfig;
use crate::model::mask2former::Mask2FormerConfig;
use crate::model::maskrcnn::MaskRcnnConfig;
use crate::model::yolo::{HeadLevels, Scale, YoloSegConfig};

/// A model variant by name: `yolo-<n|s>` with optional suffixes `-p45` (heads on P4–P5
/// only), `-nopsa` (no C2PSA attention), `-w<f>` (width multiplier), `-m<k>` (mask
/// prototypes); or `mrcnn-r<depth>` (the compact Mask R-CNN, [`MaskRcnnConfig::new`],
/// ResNet 18/34/50/101), `mrcnn-r<depth>-paper` (the detectron2-sized preset,
/// [`MaskRcnnConfig::paper`]); or `m2f-r<depth>` (the compact Mask2Former,
/// [`Mask2FormerConfig::new`]), `m2f-r<depth>-paper` ([`Mask2FormerConfig::paper`]).
#[derive(Clone, Debug, PartialEq)]
pub enum Variant {
    Yolo {
        scale: Scale,
        levels: HeadLevels,
        c2psa: bool,
        width: f64,
        protos: usize,
    },
    MaskRcnn {
        depth: usize,
        /// The paper preset instead of the compact one.
        paper: bool,
    },
    Mask2Former {
        depth: usize,
        paper: bool,
    },
}

const HELP: &str = "expected yolo-n / yolo-s with optional -p45 -nopsa -w<f> -m<k> (e.g. yolo-n-p45-w0.5), or mrcnn-r18 / r34 / r50 / r101 with optional -paper, or m2f-r18 / r34 / r50 / r101 with optional -paper";

impl FromStr for Variant {
    type Err = anyhow::Error;
    fn from_str(s: &str) -> Result<Variant> {
        let mut parts = s.split('-');
        match (parts.next(), parts.next()) {
            (Some("yolo"), Some(sc)) => parse_yolo(s, sc, parts),
            (Some(fam @ ("mrcnn" | "m2f")), Some(r)) => {
                let paper = match (parts.next(), parts.next()) {
                    (None, _) => false,
                    (Some("paper"), None) => true,
                    (Some(p), _) => bail!("variant {s:?}: unknown option {p:?}; {HELP}"),
                };
                let depth = r
                    .strip_prefix('r')
                    .and_then(|d| d.parse().ok())
                    .filter(|d| [18, 34, 50, 101].contains(d))
                    .with_context(|| format!("variant {s:?}: unknown depth; {HELP}"))?;
                Ok(if fam == "mrcnn" {
                    Variant::MaskRcnn { depth, paper }
                } else {
                    Variant::Mask2Former { depth, paper }
                })
            }
            _ => bail!("unknown model variant {s:?}; {HELP}"),
        }
    }
}

/// `yolo-<sc>` followed by the option `parts` (`s` is the whole name, for messages).
fn parse_yolo<'a>(s: &str, sc: &str, parts: impl Iterator<Item = &'a str>) -> Result<Variant> {
    let scale: Scale = sc
        .parse()
        .map_err(|e: String| anyhow::anyhow!("variant {s:?}: {e}"))?;
    let (mut levels, mut c2psa, mut width, mut protos) = (HeadLevels::P3P5, true, 1.0, 32);
    for p in parts {
        match p {
            "p45" => levels = HeadLevels::P4P5,
            "nopsa" => c2psa = false,
            _ if p.starts_with('w') => {
                width = p[1..]
                    .parse()
                    .ok()
                    .filter(|w: &f64| w.is_finite() && *w > 0.0)
                    .with_context(|| format!("variant {s:?}: bad width {p:?}; {HELP}"))?
            }
            _ if p.starts_with('m') => {
                protos =
                    p[1..].parse().ok().filter(|&k| k > 0).with_context(|| {
                        format!("variant {s:?}: bad prototype count {p:?}; {HELP}")
                    })?
            }
            _ => bail!("variant {s:?}: unknown option {p:?}; {HELP}"),
        }
    }
    Ok(Variant::Yolo {
        scale,
        levels,
        c2psa,
        width,
        protos,
    })
}

impl std::fmt::Display for Variant {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Variant::Yolo {
                scale,
                levels,
                c2psa,
                width,
                protos,
            } => {
                write!(f, "yolo-{}", scale.name())?;
                if *levels == HeadLevels::P4P5 {
                    write!(f, "-p45")?;
                }
                if !c2psa {
                    write!(f, "-nopsa")?;
                }
                if *width != 1.0 {
                    write!(f, "-w{width}")?;
                }
                if *protos != 32 {
                    write!(f, "-m{protos}")?;
                }
                Ok(())
            }
            Variant::MaskRcnn { depth, paper } | Variant::Mask2Former { depth, paper } => {
                let fam = if matches!(self, Variant::MaskRcnn { .. }) {
                    "mrcnn"
                } else {
                    "m2f"
                };
                write!(f, "{fam}-r{depth}")?;
                if *paper {
                    write!(f, "-paper")?;
                }
                Ok(())
            }
        }
    }
}

impl Variant {
    /// The variant of a model config (e.g. a checkpoint's). A Mask R-CNN is timed as the
    /// preset of its depth that its FPN width matches: `-paper` when `fpn_channels` is the
    /// paper preset's (256), the compact model otherwise. The FPN width is the size that
    /// tells the presets apart and costs the most; other per-field overrides (proposal
    /// counts, head widths) are not reproduced.
    pub fn of_detector(c: &DetectorConfig) -> Variant {
        match c {
            DetectorConfig::Yolo(c) => Variant::Yolo {
                scale: c.scale,
                levels: c.levels,
                c2psa: c.c2psa,
                width: c.width_mult,
                protos: c.num_masks,
            },
            DetectorConfig::Maskrcnn(c) => Variant::MaskRcnn {
                depth: c.depth,
                paper: c.fpn_channels == MaskRcnnConfig::paper(c.depth, c.num_classes).fpn_channels,
            },
            // As for Mask R-CNN: the decoder width tells the presets apart.
            DetectorConfig::Mask2former(c) => Variant::Mask2Former {
                depth: c.depth,
                paper: c.hidden_dim == Mask2FormerConfig::paper(c.depth, 1).hidden_dim,
            },
        }
    }

    /// The one-class YOLO this variant names at `size` px (None for a Mask R-CNN).
    pub(super) fn yolo_config(&self, size: usize) -> Option<YoloSegConfig> {
        match *self {
            Variant::Yolo {
                scale,
                levels,
                c2psa,
                width,
                protos,
            } => Some(
                YoloSegConfig::new(scale, 1)
                    .with_input_size(size)
                    .with_levels(levels)
                    .with_c2psa(c2psa)
                    .with_width_mult(width)
                    .with_num_masks(protos),
            ),
            Variant::MaskRcnn { .. } | Variant::Mask2Former { .. } => None,
        }
    }

    /// The one-class Mask R-CNN this variant names at `size` px (None for a YOLO).
    pub(super) fn maskrcnn_config(&self, size: usize) -> Option<MaskRcnnConfig> {
        match *self {
            Variant::MaskRcnn { depth, paper } => {
                let c = if paper {
                    MaskRcnnConfig::paper(depth, 1)
                } else {
                    MaskRcnnConfig::new(depth, 1)
                };
                Some(c.with_input_size(size))
            }
            Variant::Yolo { .. } | Variant::Mask2Former { .. } => None,
        }
    }

    /// The one-class Mask2Former this variant names at `size` px (None otherwise).
    pub(super) fn mask2former_config(&self, size: usize) -> Option<Mask2FormerConfig> {
        match *self {
            Variant::Mask2Former { depth, paper } => {
                let mut c = if paper {
                    Mask2FormerConfig::paper(depth, 1)
                } else {
                    Mask2FormerConfig::new(depth, 1)
                };
                c.input_size = size;
                Some(c)
            }
            _ => None,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

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
        }
    }

    #[test]
    fn mask2former_variants_build_their_presets() {
        let v: Variant = "m2f-r50-paper".parse().unwrap();
        let mut want = Mask2FormerConfig::paper(50, 1);
        want.input_size = 640;
        assert_eq!(v.mask2former_config(640), Some(want.clone()));
        assert_eq!(v.maskrcnn_config(640), None);
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
                v,
                Variant::MaskRcnn {
                    depth: d,
                    paper: true
                }
            );
            assert_eq!(v.to_string(), s);
        }
        let v: Variant = "mrcnn-r50-paper".parse().unwrap();
        assert_eq!(
            v.maskrcnn_config(512),
            Some(MaskRcnnConfig::paper(50, 1).with_input_size(512))
        );
        let compact: Variant = "mrcnn-r50".parse().unwrap();
        assert_eq!(
            compact.maskrcnn_config(512),
            Some(MaskRcnnConfig::new(50, 1).with_input_size(512))
        );
        assert_eq!(v.yolo_config(512), None);
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
    }
}
