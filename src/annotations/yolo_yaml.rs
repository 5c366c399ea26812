//! A YOLO dataset's `data.yaml` (ultralytics, Roboflow): the dataset root, where each
//! split's images are, and the class names, resolved by ultralytics' rules
//! (`ultralytics/data/utils.py`, `check_det_dataset`). Reading the images and labels it
//! points to is [`super::yolo`]'s job.
//!
//! Keys: `train` and `val` (or `validation`) are required, `test` optional, each a folder,
//! a `.txt` list of images, or a list of those. `names` is a list or a `{0: a, 1: b}`
//! map with keys `0..n`; without it `nc` gives `class_0`, `class_1`, …; with both they must
//! agree. Other keys (`download`, `roboflow`, …) are ignored, as ultralytics does.
//!
//! Paths: `path` is the root; without it, the yaml's folder. Where ultralytics resolves a
//! relative `path` against the working directory and then its global datasets folder,
//! chicktrain tries the yaml's folder and then the working directory, so a dataset folder
//! can be moved. A split path that does not exist and starts with `../` is retried
//! without it (ultralytics' rule for Roboflow exports, whose `data.yaml` says
//! `../train/images`).

use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use yaml_rust2::{Yaml, YamlLoader};

use super::split::Part;

/// `data.yaml`, resolved: every path is the root joined with what the file says.
#[derive(Clone, Debug, PartialEq)]
pub struct DataYaml {
    /// The file itself (named in errors).
    pub file: PathBuf,
    /// The dataset root (`path`, else the yaml's folder).
    pub root: PathBuf,
    /// Per part: the folders or `.txt` lists its images come from (empty: not given).
    pub train: Vec<PathBuf>,
    pub val: Vec<PathBuf>,
    pub test: Vec<PathBuf>,
    /// Class names in class-index order.
    pub names: Vec<String>,
}

impl DataYaml {
    pub fn part(&self, p: Part) -> &[PathBuf] {
        match p {
            Part::Train => &self.train,
            Part::Val => &self.val,
            Part::Test => &self.test,
        }
    }

    /// Reads and resolves `file`; errors name it and the key.
    pub fn load(file: &Path) -> Result<DataYaml> {
        let text = std::fs::read_to_string(file)
            .with_context(|| format!("cannot read YOLO dataset file {}", file.display()))?;
        DataYaml::parse(&text, file).with_context(|| format!("in {}", file.display()))
    }

    /// [`DataYaml::load`] on `text`; `file` locates relative paths.
    pub fn parse(text: &str, file: &Path) -> Result<DataYaml> {
        let docs = YamlLoader::load_from_str(text).map_err(|e| {
            anyhow::anyhow!(
                "invalid YAML at line {}, column {}: {}",
                e.marker().line(),
                e.marker().col() + 1,
                e.info()
            )
        })?;
        let doc = match docs.as_slice() {
            [d @ Yaml::Hash(_)] => d,
            [] => bail!("is empty: a YOLO data.yaml needs `train`, `val` and `names`"),
            _ => bail!("must be one mapping of keys (`path`, `train`, `val`, `test`, `names`)"),
        };
        let names = class_names(doc)?;
        let dir = file.parent().unwrap_or(Path::new(""));
        let root = match &doc["path"] {
            Yaml::BadValue | Yaml::Null => dir.to_path_buf(),
            Yaml::String(p) => resolve_root(Path::new(p), dir)?,
            other => bail!("`path` must be a folder name, not {}", describe(other)),
        };
        let val_key = if doc["val"].is_badvalue() && !doc["validation"].is_badvalue() {
            "validation"
        } else {
            "val"
        };
        let train = sources(&doc["train"], "train", &root)?;
        let val = sources(&doc[val_key], val_key, &root)?;
        let test = sources(&doc["test"], "test", &root)?;
        for (k, v) in [("train", &train), (val_key, &val)] {
            if v.is_empty() {
                bail!("has no `{k}`: a YOLO data.yaml needs `train` and `val` (images folders or .txt lists)");
            }
        }
        Ok(DataYaml {
            file: file.to_path_buf(),
            root,
            train,
            val,
            test,
            names,
        })
    }
}

/// `path` relative to the yaml's folder when it exists there, else to the working
/// directory (ultralytics' first try).
fn resolve_root(p: &Path, yaml_dir: &Path) -> Result<PathBuf> {
    if p.is_absolute() {
        return Ok(p.to_path_buf());
    }
    let beside = yaml_dir.join(p);
    if beside.is_dir() || !p.is_dir() {
        return Ok(beside);
    }
    Ok(p.to_path_buf())
}

/// One split's sources: a string, a list of strings, or nothing (absent or null).
fn sources(v: &Yaml, key: &str, root: &Path) -> Result<Vec<PathBuf>> {
    let one = |s: &str| -> PathBuf {
        let x = root.join(s);
        match s.strip_prefix("../") {
            Some(rest) if !x.exists() => root.join(rest),
            _ => x,
        }
    };
    Ok(match v {
        Yaml::BadValue | Yaml::Null => Vec::new(),
        Yaml::String(s) if s.is_empty() => Vec::new(),
        Yaml::String(s) => vec![one(s)],
        Yaml::Array(items) => {
            let mut out = Vec::with_capacity(items.len());
            for (i, it) in items.iter().enumerate() {
                match it {
                    // A list keeps each entry as written (ultralytics does not retry
                    // `../` inside lists).
                    Yaml::String(s) => out.push(root.join(s)),
                    other => bail!(
                        "`{key}` entry {i} must be a folder or .txt file name, not {}",
                        describe(other)
                    ),
                }
            }
            out
        }
        other => bail!(
            "`{key}` must be a folder, a .txt list of images or a list of those, not {}",
            describe(other)
        ),
    })
}

/// `names` (list or `{index: name}` map with keys `0..n`) or `nc`, checked against each
/// other.
fn class_names(doc: &Yaml) -> Result<Vec<String>> {
    let nc = match &doc["nc"] {
        Yaml::BadValue | Yaml::Null => None,
        Yaml::Integer(n) if *n > 0 => Some(*n as usize),
        other => bail!(
            "`nc` must be a positive whole number, not {}",
            describe(other)
        ),
    };
    let names: Vec<String> = match &doc["names"] {
        Yaml::BadValue | Yaml::Null => match nc {
            Some(n) => (0..n).map(|i| format!("class_{i}")).collect(),
            None => bail!(
                "has neither `names` nor `nc`: one of them is required (e.g. `names: [carcass]`)"
            ),
        },
        Yaml::Array(items) => items
            .iter()
            .enumerate()
            .map(|(i, it)| scalar(it).with_context(|| format!("`names` entry {i}")))
            .collect::<Result<_>>()?,
        Yaml::Hash(map) => {
            let mut named: Vec<Option<String>> = vec![None; map.len()];
            for (k, v) in map {
                let i = match k {
                    Yaml::Integer(i) if *i >= 0 && (*i as usize) < map.len() => *i as usize,
                    _ => bail!(
                        "`names` keys must be the class indices 0..{} (e.g. `0: carcass`), found {}",
                        map.len(),
                        describe(k)
                    ),
                };
                named[i] = Some(scalar(v).with_context(|| format!("`names` entry {i}"))?);
            }
            // n distinct keys in 0..n: every slot is filled.
            named.into_iter().map(Option::unwrap_or_default).collect()
        }
        other => bail!(
            "`names` must be a list or a map of class names, not {}",
            describe(other)
        ),
    };
    if names.is_empty() {
        bail!("`names` is empty: the dataset needs at least one class");
    }
    if let Some(n) = nc {
        if n != names.len() {
            bail!(
                "`names` has {} classes but `nc` is {n}: they must match",
                names.len()
            );
        }
    }
    Ok(names)
}

/// A class name written as a string, number or boolean (`names: [0, 1]` happens).
fn scalar(v: &Yaml) -> Result<String> {
    Ok(match v {
        Yaml::String(s) => s.clone(),
        Yaml::Integer(i) => i.to_string(),
        Yaml::Real(r) => r.clone(),
        Yaml::Boolean(b) => b.to_string(),
        other => bail!("a class name must be a string, not {}", describe(other)),
    })
}

fn describe(v: &Yaml) -> String {
    match v {
        Yaml::Real(r) => format!("the number {r}"),
        Yaml::Integer(i) => format!("the number {i}"),
        Yaml::String(s) => format!("{s:?}"),
        Yaml::Boolean(b) => format!("{b}"),
        Yaml::Array(_) => "a list".into(),
        Yaml::Hash(_) => "a map".into(),
        Yaml::Alias(_) => "an alias".into(),
        Yaml::Null => "null".into(),
        Yaml::BadValue => "nothing".into(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(text: &str) -> Result<DataYaml> {
        DataYaml::parse(text, Path::new("ds/data.yaml"))
    }

    fn err(text: &str) -> String {
        format!("{:#}", parse(text).unwrap_err())
    }

    #[test]
    fn keys_paths_and_names_as_ultralytics_reads_them() {
        let d = parse("path: root\ntrain: images/train\nval: [images/val, extra.txt]\nnames:\n  0: carcass\n  1: wing\n").unwrap();
        assert_eq!(d.root, Path::new("ds/root"));
        assert_eq!(d.train, vec![PathBuf::from("ds/root/images/train")]);
        assert_eq!(
            d.val,
            vec![
                PathBuf::from("ds/root/images/val"),
                PathBuf::from("ds/root/extra.txt")
            ]
        );
        assert!(d.test.is_empty());
        assert_eq!(d.names, ["carcass", "wing"]);
        // Roboflow: no `path`, a flow list of names, `nc`, `../` paths, extra keys.
        let r = parse("train: ../train/images\nvalidation: ../valid/images\ntest: ../test/images\nnc: 2\nnames: ['a', \"b\"]\nroboflow:\n  workspace: w\n  version: 3\n").unwrap();
        assert_eq!(r.root, Path::new("ds"));
        // `ds/../train/images` does not exist here: retried as `ds/train/images`.
        assert_eq!(r.train, vec![PathBuf::from("ds/train/images")]);
        assert_eq!(r.val, vec![PathBuf::from("ds/valid/images")]);
        assert_eq!(r.names, ["a", "b"]);
        assert_eq!(
            parse("train: a\nval: b\nnc: 2\n").unwrap().names,
            ["class_0", "class_1"]
        );
        // `test:` left empty, as ultralytics' templates do: no test part.
        assert!(parse("train: a\nval: b\ntest:\nnames: [x]\n")
            .unwrap()
            .test
            .is_empty());
    }

    #[test]
    fn bad_files_say_which_key_is_wrong() {
        for (text, needle) in [
            ("", "is empty"),
            ("- a\n- b\n", "one mapping"),
            ("train: [a\n", "invalid YAML at line"),
            ("val: b\nnames: [x]\n", "has no `train`"),
            ("train: a\nnames: [x]\n", "has no `val`"),
            ("train: a\nval: b\n", "neither `names` nor `nc`"),
            ("train: a\nval: b\nnames: [x, y]\nnc: 3\n", "`nc` is 3"),
            (
                "train: a\nval: b\nnames: {0: x, 2: y}\n",
                "class indices 0..2",
            ),
            ("train: a\nval: b\nnames: {a: x}\n", "class indices"),
            ("train: a\nval: b\nnames: []\n", "`names` is empty"),
            ("train: a\nval: b\nnames: [[x]]\n", "`names` entry 0"),
            ("train: 3\nval: b\nnames: [x]\n", "`train` must be"),
            (
                "train: [a, {b: 1}]\nval: b\nnames: [x]\n",
                "`train` entry 1",
            ),
            (
                "path: [a]\ntrain: a\nval: b\nnames: [x]\n",
                "`path` must be",
            ),
            ("train: a\nval: b\nnc: -1\n", "`nc` must be"),
        ] {
            let e = err(text);
            assert!(e.contains(needle), "{text:?}: {e}");
        }
    }
}
