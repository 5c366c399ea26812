//! Domain-randomisation groups: which families of render choices are widened beyond the
//! preset's base look. Each group draws from its own RNG stream
//! ([`crate::render::group_rng`], `Streams::rng(opts, name)` with the group's name), so turning
//! one off leaves every other choice of the image unchanged — which is what the
//! per-group ablation (`train` with one group off in turn, scored cross-domain) needs.
//! All off is the renderer as it was before the groups existed (same pixels, same cache
//! key). The ranges each group draws from are documented in one table in README.md.
//!
//! It lives in `config` because it is a config table (`[data.randomize]`) and the
//! config is the foundation layer; the renderer reads it.

use serde::{Deserialize, Serialize};

/// On/off per randomisation group (`[data.randomize]` in a config).
///
/// A group a table leaves out keeps its training default ([`Randomize::TRAINING`]:
/// `[data.randomize]` with only `lighting = true` adds lighting to carcass + physics), so
/// one `--set data.randomize.X=…` changes exactly one group. `Randomize::default()` is
/// every group off (the base look).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Randomize {
    /// Body families, sizes, proportions, missing / cut parts, skin tone, fat, bruises,
    /// feather remnants, torn skin (stream "carcass").
    #[serde(default = "on")]
    pub carcass: bool,
    /// Surfaces under the pile: steel plates, belts and crates of several colours, wet and
    /// dry, smears; empty scenes and piles cut by the frame (stream "scene").
    #[serde(default)]
    pub scene: bool,
    /// Non-carcass objects: gloves, hands, shackles, tools, water (stream "distractors").
    #[serde(default)]
    pub distractors: bool,
    /// Number, kind, colour temperature and hardness of lights, glare, exposure, white
    /// balance (stream "lighting").
    #[serde(default)]
    pub lighting: bool,
    /// Camera height, tilt, field of view, lens distortion, motion blur, sensor noise,
    /// JPEG quality (stream "camera").
    #[serde(default)]
    pub camera: bool,
    /// Piles dropped and settled by rigid-body physics (rapier3d) instead of the
    /// height-field drop (stream "physics").
    #[serde(default = "on")]
    pub physics: bool,
}

fn on() -> bool {
    true
}

impl Randomize {
    /// What training renders use unless a config says otherwise: the geometry groups
    /// (carcass variety and rigid-body piles). The appearance groups (scene,
    /// distractors, lighting, camera) are opt-in: at the CPU schedule (350 optimiser
    /// steps) turning them on lowered cross-domain segm AP (BENCHMARKS.md "Transfer").
    pub const TRAINING: Randomize = Randomize {
        carcass: true,
        scene: false,
        distractors: false,
        lighting: false,
        camera: false,
        physics: true,
    };

    /// Every group on.
    pub const ALL: Randomize = Randomize {
        carcass: true,
        scene: true,
        distractors: true,
        lighting: true,
        camera: true,
        physics: true,
    };

    /// The group names, in table order (the ablation turns them off one at a time).
    pub const GROUPS: [&'static str; 6] = [
        "carcass",
        "scene",
        "distractors",
        "lighting",
        "camera",
        "physics",
    ];

    /// True when no group is on (the renderer's base look; omitted from cache keys).
    pub fn is_off(&self) -> bool {
        *self == Randomize::default()
    }

    /// A copy with group `name` set to `on`; an unknown name is an error listing the groups.
    pub fn with(mut self, name: &str, on: bool) -> anyhow::Result<Randomize> {
        let slot = match name {
            "carcass" => &mut self.carcass,
            "scene" => &mut self.scene,
            "distractors" => &mut self.distractors,
            "lighting" => &mut self.lighting,
            "camera" => &mut self.camera,
            "physics" => &mut self.physics,
            other => anyhow::bail!(
                "unknown randomisation group {other:?}; expected one of {}",
                Randomize::GROUPS.join(", ")
            ),
        };
        *slot = on;
        Ok(self)
    }

    /// Groups from a command line: `none`, `all`, or comma-separated group names (each
    /// turned on); an unknown name is an error listing the groups.
    pub fn parse_list(list: &str) -> anyhow::Result<Randomize> {
        match list.trim() {
            "" | "none" => Ok(Randomize::default()),
            "all" => Ok(Randomize::ALL),
            names => names
                .split(',')
                .try_fold(Randomize::default(), |r, n| r.with(n.trim(), true)),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn groups_toggle_by_name_and_unknown_names_are_refused() {
        let mut r = Randomize::default();
        assert!(r.is_off());
        for g in Randomize::GROUPS {
            r = r.with(g, true).unwrap();
        }
        assert_eq!(r, Randomize::ALL);
        let off = Randomize::ALL.with("lighting", false).unwrap();
        assert!(!off.lighting && off.camera && !off.is_off());
        let e = r.with("colour", true).unwrap_err().to_string();
        assert!(e.contains("colour") && e.contains("physics"), "{e}");
        assert_eq!(Randomize::parse_list("none").unwrap(), Randomize::default());
        assert_eq!(Randomize::parse_list("all").unwrap(), Randomize::ALL);
        let two = Randomize::parse_list("physics, camera").unwrap();
        assert!(two.physics && two.camera && !two.lighting);
        // A table that names one group leaves the others at their training default.
        let one: Randomize = toml::from_str("lighting = true").unwrap();
        assert_eq!(one, Randomize::TRAINING.with("lighting", true).unwrap());
        let off: Randomize = toml::from_str("physics = false").unwrap();
        assert_eq!(off, Randomize::TRAINING.with("physics", false).unwrap());
        assert!(Randomize::parse_list("physics,wind").is_err());
    }
}
