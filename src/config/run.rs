//! The run config: the root [`Config`] (`name`, `seed`, `device`, `[data]`, `[model]`,
//! `[train]`), how it is read ([`load`]: a file or a shipped config, its `base` chain,
//! `--set` overrides) and the checks that span its tables. Built with the `train` feature
//! only: its `[model]` table is the model layer's [`ModelConfig`].
//!
//! `base = "other.toml"` (detectron2's `_BASE_`) starts a config from another one, so a
//! variant states only what differs; see [`BASE_KEY`].

use std::path::Path;

use anyhow::{bail, Context, Result};
use serde::{Deserialize, Serialize};

use super::data::DataConfig;
use super::device::DeviceKind;
use super::shipped::SHIPPED;
use super::train::TrainConfig;
use crate::model::ModelConfig;

#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Config {
    /// Run name: outputs go to `runs/<name>/`.
    pub name: String,
    #[serde(default)]
    pub seed: u64,
    #[serde(default = "default_device")]
    pub device: DeviceKind,
    pub data: DataConfig,
    #[serde(default)]
    pub model: ModelConfig,
    #[serde(default)]
    pub train: TrainConfig,
}

fn default_device() -> DeviceKind {
    DeviceKind::Flex
}

/// Finds a config: an existing path, else a shipped config by name (`yolo_syn1000` or
/// `yolo_syn1000.toml`). Returns the text and where it came from.
pub fn locate(name: &str) -> Result<(String, String)> {
    let path = Path::new(name);
    if path.exists() {
        let text = std::fs::read_to_string(path)
            .with_context(|| format!("cannot read config {}", path.display()))?;
        return Ok((text, path.display().to_string()));
    }
    let file = path
        .file_name()
        .map(|f| f.to_string_lossy().into_owned())
        .unwrap_or_default();
    let want = if file.ends_with(".toml") {
        file
    } else {
        format!("{file}.toml")
    };
    if let Some((n, text)) = SHIPPED.iter().find(|(n, _)| *n == want) {
        return Ok((text.to_string(), format!("<shipped>/configs/{n}")));
    }
    let names: Vec<&str> = SHIPPED.iter().map(|(n, _)| *n).collect();
    bail!(
        "config {name:?} is neither a file nor a shipped config (shipped: {})",
        names.join(", ")
    )
}

/// Parses, applies `key.path=value` overrides, types and validates a config.
pub fn load(name: &str, overrides: &[String]) -> Result<Config> {
    let (text, origin) = locate(name)?;
    parse(&text, &origin, overrides)
}

/// The top-level key that names the config this one extends: a path relative to this
/// file (else to the working directory), or a shipped config's name. The base is read
/// first (recursively) and this file's keys are laid over it table by table, as
/// detectron2's `_BASE_` does; a table that names a `kind` other than the base's (a
/// `[model]` of another family, a `[data.real]` of another format) replaces the base's
/// table instead, because the keys of one kind mean nothing to another.
pub const BASE_KEY: &str = "base";

/// Chains of `base` longer than this are refused (they are almost surely a cycle).
const MAX_BASE_DEPTH: usize = 8;

/// Resolves `tree`'s [`BASE_KEY`] chain; `true` when there was one.
fn with_base(mut tree: toml::Table, origin: &str, depth: usize) -> Result<(toml::Table, bool)> {
    let Some(base) = tree.remove(BASE_KEY) else {
        return Ok((tree, false));
    };
    let Some(name) = base.as_str() else {
        bail!("config {origin}: `{BASE_KEY}` must be a string (a config file or a shipped config's name), got {base}");
    };
    if depth >= MAX_BASE_DEPTH {
        bail!("config {origin}: more than {MAX_BASE_DEPTH} levels of `{BASE_KEY}` (does a config extend itself?)");
    }
    let beside = Path::new(origin).parent().map(|dir| dir.join(name));
    let (text, base_origin) = match beside {
        Some(p) if p.is_file() => locate(&p.to_string_lossy()),
        _ => locate(name),
    }
    .with_context(|| format!("{BASE_KEY} = {name:?} of config {origin}"))?;
    let base_tree: toml::Table = toml::from_str(&text).with_context(|| {
        format!("config {base_origin} (the {BASE_KEY} of {origin}) is not valid TOML")
    })?;
    let (mut merged, _) = with_base(base_tree, &base_origin, depth + 1)?;
    overlay(&mut merged, tree);
    Ok((merged, true))
}

/// Lays `over` onto `base` (see [`BASE_KEY`]).
fn overlay(base: &mut toml::Table, over: toml::Table) {
    for (key, value) in over {
        match (base.get_mut(&key), value) {
            (Some(toml::Value::Table(b)), toml::Value::Table(o))
                if o.get("kind").is_none() || o.get("kind") == b.get("kind") =>
            {
                overlay(b, o)
            }
            (_, value) => {
                base.insert(key, value);
            }
        }
    }
}

pub fn parse(text: &str, origin: &str, overrides: &[String]) -> Result<Config> {
    let tree: toml::Table =
        toml::from_str(text).with_context(|| format!("config {origin} is not valid TOML"))?;
    let (mut tree, has_base) = with_base(tree, origin, 0)?;
    // Typed from text (not from the tree) so errors quote the offending `key = value`
    // line; with overrides or a base, from the re-serialised (merged) tree, which quotes
    // the override or the merged line.
    for o in overrides {
        apply_override(&mut tree, o).with_context(|| format!("bad override --set {o}"))?;
    }
    // `[model]` without `kind` is a YOLO, as in ultralytics.
    let default_kind = match tree.get_mut("model").and_then(|m| m.as_table_mut()) {
        Some(m) if !m.contains_key("kind") => {
            m.insert("kind".into(), toml::Value::String("yolo".into()));
            true
        }
        _ => false,
    };
    let typed_text = if overrides.is_empty() && !default_kind && !has_base {
        text.to_string()
    } else {
        toml::to_string(&tree)?
    };
    let cfg: Config = toml::from_str(&typed_text).with_context(|| {
        if overrides.is_empty() && !has_base {
            format!("in config {origin}")
        } else if overrides.is_empty() {
            format!("in config {origin} laid over its {BASE_KEY}")
        } else {
            format!("in config {origin} with overrides {}", overrides.join(" "))
        }
    })?;
    cfg.validate()
        .with_context(|| format!("in config {origin}"))?;
    Ok(cfg)
}

fn apply_override(tree: &mut toml::Table, o: &str) -> Result<()> {
    let (key, raw) = o
        .split_once('=')
        .context("expected KEY=VALUE, e.g. train.epochs=5")?;
    let value: toml::Value = toml::from_str::<toml::Table>(&format!("v = {raw}"))
        .ok()
        .and_then(|mut t| t.remove("v"))
        .unwrap_or_else(|| toml::Value::String(raw.to_string()));
    let parts: Vec<&str> = key.trim().split('.').collect();
    let mut table = tree;
    for p in &parts[..parts.len() - 1] {
        table = table
            .entry(p.to_string())
            .or_insert_with(|| toml::Value::Table(toml::Table::new()))
            .as_table_mut()
            .with_context(|| format!("{p} is not a table"))?;
    }
    table.insert(parts[parts.len() - 1].to_string(), value);
    Ok(())
}

impl Config {
    /// Range and consistency checks, with messages that say what to change.
    pub fn validate(&self) -> Result<()> {
        if self.name.is_empty() || self.name.contains(['/', '\\']) {
            bail!("name {:?} must be a non-empty folder name", self.name);
        }
        self.data.validate()?;
        self.train.validate()?;
        self.model.validate(self.data.crop)?;
        if let Some(f) = self.train.real_fraction {
            let real = (f * self.train.batch as f64).round() as usize;
            if real < self.train.batch && self.data.synthetic == 0 {
                bail!(
                    "train.real_fraction = {f} leaves {} of train.batch = {} places to synthetic images, but data.synthetic = 0 (set data.synthetic > 0, or train.real_fraction = 1)",
                    self.train.batch - real,
                    self.train.batch
                );
            }
            if real > 0 && self.data.split[0] <= 0.0 {
                bail!(
                    "train.real_fraction = {f} needs real train images, but data.split = {:?} has no train part",
                    self.data.split
                );
            }
        }
        match (&self.data.unlabeled, &self.train.self_training) {
            (None, Some(_)) => bail!("[train.self_training] is set but there is no [data.unlabeled] (images = \"DIR\"): self-training needs the unlabeled photos"),
            (Some(_), st) => st
                .clone()
                .unwrap_or_default()
                .validate(self.train.epochs, self.train.batch)?,
            (None, None) => {}
        }
        self.model.validate_freeze(self.train.freeze)?;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::maskrcnn::MaskRcnnPreset;
    use crate::model::yolo::YoloScale;

    #[test]
    fn shipped_configs_parse_and_validate() {
        for (name, text) in SHIPPED {
            parse(text, name, &[]).unwrap_or_else(|e| panic!("{name}: {e:#}"));
        }
    }

    #[test]
    fn errors_name_the_key() {
        let base = SHIPPED[0].1;
        let cases: Vec<(String, Vec<String>, &str)> = vec![
            (
                format!("{base}\nepoch = 3\n"),
                vec![],
                "unknown field `epoch`",
            ),
            (
                base.replace("[train]", "[train]\nepoch = 3"),
                vec![],
                "unknown field `epoch`",
            ),
            (
                base.to_string(),
                vec!["train.epochs=0".into()],
                "train.epochs",
            ),
            (
                base.to_string(),
                vec!["train.epochs=-3".into()],
                "epochs = -3",
            ),
            (
                base.to_string(),
                vec!["train.real_fraction=0.5".into(), "data.synthetic=0".into()],
                "but data.synthetic = 0",
            ),
            (
                base.to_string(),
                vec!["data.train_limit=0".into()],
                "data.train_limit = 0",
            ),
            (
                base.to_string(),
                vec!["train.mosaic=1.5".into()],
                "train.mosaic = 1.5",
            ),
            (
                base.to_string(),
                vec!["train.lr=\"fast\"".into()],
                "invalid type",
            ),
            (
                base.to_string(),
                vec!["data.image_size=100".into()],
                "data.image_size",
            ),
            (
                base.to_string(),
                vec!["model.scale=\"x\"".into()],
                "unknown variant `x`, expected `n` or `s`",
            ),
            (
                base.to_string(),
                vec!["data.real.kind=\"coco\"".into()],
                "data.real.annotations",
            ),
            (
                base.to_string(),
                vec![
                    "data.real.kind=\"labelme\"".into(),
                    "data.real.dir=\"/nonexistent/x\"".into(),
                ],
                "does not exist",
            ),
            ("name = ".to_string(), vec![], "not valid TOML"),
        ];
        for (text, ov, needle) in cases {
            let err = format!("{:#}", parse(&text, "test.toml", &ov).unwrap_err());
            assert!(err.contains(needle), "{err:?} should mention {needle:?}");
            assert!(err.contains("test.toml"), "{err:?} should name the file");
        }
    }

    #[test]
    fn model_keys_belong_to_their_kind() {
        let yolo = SHIPPED[0].1;
        let (mrcnn, _) = locate("maskrcnn_r101_syn1000").unwrap();
        let cases: Vec<(&str, Vec<String>, &str)> = vec![
            (yolo, vec!["model.depth=50".into()], "unknown field `depth`"),
            (
                &mrcnn,
                vec!["model.scale=\"n\"".into()],
                "unknown field `scale`",
            ),
            (
                &mrcnn,
                vec!["model.depth=42".into()],
                "model.depth = 42 must be 18, 34, 50 or 101",
            ),
            (
                &mrcnn,
                vec!["model.anchor_sizes=[8.0, 16.0]".into()],
                "model.anchor_sizes",
            ),
            (
                &mrcnn,
                vec!["model.roi_batch=0".into()],
                "model.roi_batch = 0",
            ),
            (
                &mrcnn,
                vec!["model.preset=\"huge\"".into()],
                "unknown variant",
            ),
            (
                yolo,
                vec!["model.kind=\"mlp\"".into()],
                "unknown variant `mlp`",
            ),
            (yolo, vec!["model.init=\"\"".into()], "model.init is empty"),
            (
                &mrcnn,
                vec!["train.freeze=6".into()],
                "train.freeze = 6 must be at most 5 for model.kind = \"maskrcnn\"",
            ),
            (
                yolo,
                vec!["train.freeze=24".into()],
                "train.freeze = 24 must be at most 23",
            ),
        ];
        for (text, ov, needle) in cases {
            let err = format!("{:#}", parse(text, "test.toml", &ov).unwrap_err());
            assert!(err.contains(needle), "{err:?} should mention {needle:?}");
        }
        // The resolved config (what a run folder holds) parses back to the same model.
        let cfg = parse(&mrcnn, "m", &["model.depth=50".into()]).unwrap();
        let ModelConfig::Maskrcnn(m) = &cfg.model else {
            panic!("not a Mask R-CNN: {:?}", cfg.model)
        };
        assert_eq!((m.depth, m.preset), (50, MaskRcnnPreset::Compact));
        let back = parse(&toml::to_string(&cfg).unwrap(), "resolved", &[]).unwrap();
        assert_eq!(back.model, cfg.model);
        assert_eq!(back.train.warmup_iters, 500);
        // `model.init` and `train.freeze` belong to both families and survive the round trip.
        for text in [yolo, mrcnn.as_str()] {
            let ov = ["model.init=runs/x/best.bpk".into(), "train.freeze=2".into()];
            let c = parse(text, "i", &ov).unwrap();
            assert_eq!(c.model.init(), Some("runs/x/best.bpk"));
            let back = parse(&toml::to_string(&c).unwrap(), "resolved", &[]).unwrap();
            assert_eq!(
                (back.model.init(), back.train.freeze),
                (Some("runs/x/best.bpk"), 2)
            );
        }
        let y = parse(yolo, "q", &[]).unwrap();
        let ModelConfig::Yolo(m) = &y.model else {
            panic!("not a YOLO: {:?}", y.model)
        };
        assert_eq!((m.scale, m.prototypes), (YoloScale::N, 32));
        // A `[model]` table without `kind` is a YOLO with every default written out.
        let no_kind = parse(&yolo.replace("kind = \"yolo\"", ""), "k", &[]).unwrap();
        assert_eq!(no_kind.model, y.model);
        let text = toml::to_string(&no_kind.model).unwrap();
        assert!(
            text.starts_with("kind = \"yolo\"\nwidth_mult = 1.0\nscale = \"n\""),
            "{text}"
        );
    }

    #[test]
    fn devices_parse_print_and_round_trip() {
        for (text, d) in [
            ("flex", DeviceKind::Flex),
            ("ndarray", DeviceKind::Ndarray),
            ("cuda", DeviceKind::Cuda(0)),
            ("cuda:3", DeviceKind::Cuda(3)),
            ("wgpu", DeviceKind::Wgpu),
        ] {
            assert_eq!(text.parse::<DeviceKind>(), Ok(d));
            let cfg = parse(SHIPPED[0].1, "q", &[format!("device=\"{text}\"")]).unwrap();
            assert_eq!(cfg.device, d);
            let back = parse(&toml::to_string(&cfg).unwrap(), "resolved", &[]).unwrap();
            assert_eq!(back.device, d);
        }
        assert_eq!(DeviceKind::Cuda(0).to_string(), "cuda");
        for bad in ["gpu", "cuda:x", "cuda:-1", ""] {
            assert!(bad.parse::<DeviceKind>().is_err(), "{bad}");
        }
        let e = format!(
            "{:#}",
            parse(SHIPPED[0].1, "q.toml", &["device=\"tpu\"".into()]).unwrap_err()
        );
        assert!(
            e.contains("unknown device \"tpu\"") && e.contains("cuda:N"),
            "{e}"
        );
    }

    #[test]
    fn an_all_test_split_is_valid_but_one_empty_part_is_not() {
        let cfg = parse(SHIPPED[0].1, "q", &["data.split=[0.0, 0.0]".into()]).unwrap();
        assert_eq!(cfg.data.split, [0.0, 0.0]);
        for bad in ["[0.5, 0.0]", "[0.0, 0.5]", "[0.6, 0.4]"] {
            let e = format!(
                "{:#}",
                parse(SHIPPED[0].1, "q.toml", &[format!("data.split={bad}")]).unwrap_err()
            );
            assert!(
                e.contains("data.split") && e.contains("[0, 0]"),
                "{bad}: {e}"
            );
        }
    }

    /// Writes `files` into a fresh folder and returns it.
    fn config_dir(tag: &str, files: &[(&str, &str)]) -> std::path::PathBuf {
        let dir = std::env::temp_dir().join(format!("ct-base-{tag}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        for (name, text) in files {
            std::fs::write(dir.join(name), text).unwrap();
        }
        dir
    }

    #[test]
    fn base_is_laid_under_the_config_table_by_table() {
        let dir = config_dir(
            "merge",
            &[
                (
                    "child.toml",
                    "base = \"quickstart\"\nname = \"child\"\n[train]\nepochs = 3\n",
                ),
                (
                    "grandchild.toml",
                    "base = \"child.toml\"\n[data]\nsynthetic = 7\n",
                ),
            ],
        );
        let quick = parse(
            SHIPPED
                .iter()
                .find(|(n, _)| *n == "quickstart.toml")
                .unwrap()
                .1,
            "q",
            &[],
        )
        .unwrap();
        let cfg = load(
            dir.join("grandchild.toml").to_str().unwrap(),
            &["train.batch=4".into()],
        )
        .unwrap();
        assert_eq!(cfg.name, "child");
        assert_eq!(
            (cfg.train.epochs, cfg.train.batch, cfg.data.synthetic),
            (3, 4, 7)
        );
        // Everything not restated comes from the shipped quickstart, two levels down.
        assert_eq!(cfg.train.lr, quick.train.lr);
        assert_eq!(cfg.train.copy_paste, quick.train.copy_paste);
        assert_eq!(cfg.data.image_size, quick.data.image_size);
        assert_eq!(cfg.model, quick.model);
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn a_table_of_another_kind_replaces_the_base_table() {
        let dir = config_dir(
            "kind",
            &[(
                "mr.toml",
                "base = \"quickstart\"\n[model]\nkind = \"maskrcnn\"\ndepth = 18\npreset = \"compact\"\n",
            )],
        );
        // The quickstart's YOLO keys (scale, levels, c2psa) would be refused by a Mask
        // R-CNN model table: they must not be merged into it.
        let cfg = load(dir.join("mr.toml").to_str().unwrap(), &[]).unwrap();
        assert!(
            matches!(cfg.model, ModelConfig::Maskrcnn(_)),
            "{:?}",
            cfg.model
        );
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn bad_bases_are_clear_errors() {
        let dir = config_dir(
            "bad",
            &[
                ("loop_a.toml", "base = \"loop_b.toml\"\n"),
                ("loop_b.toml", "base = \"loop_a.toml\"\n"),
                ("missing.toml", "base = \"no_such_config.toml\"\n"),
                ("number.toml", "base = 3\n"),
                ("broken.toml", "base = \"not_toml.toml\"\n"),
                ("not_toml.toml", "[train\n"),
            ],
        );
        for (file, want) in [
            ("loop_a.toml", "levels of `base`"),
            ("missing.toml", "no_such_config.toml"),
            ("number.toml", "must be a string"),
            ("broken.toml", "is not valid TOML"),
        ] {
            let e = load(dir.join(file).to_str().unwrap(), &[]).unwrap_err();
            assert!(format!("{e:#}").contains(want), "{file}: {e:#}");
        }
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn overrides_set_nested_keys() {
        let cfg = parse(
            SHIPPED[0].1,
            "q",
            &["train.epochs=5".into(), "data.synthetic=7".into()],
        )
        .unwrap();
        assert_eq!(cfg.train.epochs, 5);
        assert_eq!(cfg.data.synthetic, 7);
    }
}
