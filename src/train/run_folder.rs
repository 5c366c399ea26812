//! Which folder a run writes to: `runs/<name>` is never overwritten. A second run of
//! the same config goes to `runs/<name>-2`, then `-3`, … (ultralytics'
//! `increment_path` in `ultralytics/utils/files.py`, with `-` as the separator);
//! `--exist-ok` reuses `runs/<name>`, `--resume` continues the named folder, and an
//! explicit `--run-dir` is used as given.
//!
//! A folder is claimed by creating it (`create_dir` fails on an existing one), so two
//! runs started at once never share a folder.

use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};

/// How many suffixes are tried before giving up (ultralytics stops at 9999 too).
const MAX_SUFFIX: usize = 9999;

/// `base` itself when it does not exist yet, else the first free `base-2`, `base-3`, …;
/// the returned folder has just been created by this call.
pub fn increment_path(base: &Path) -> Result<PathBuf> {
    if let Some(parent) = base.parent().filter(|p| !p.as_os_str().is_empty()) {
        std::fs::create_dir_all(parent)
            .with_context(|| format!("cannot create {}", parent.display()))?;
    }
    let name = base
        .file_name()
        .with_context(|| format!("run folder {} has no name", base.display()))?
        .to_string_lossy()
        .into_owned();
    for n in 1..=MAX_SUFFIX {
        let p = if n == 1 {
            base.to_path_buf()
        } else {
            base.with_file_name(format!("{name}-{n}"))
        };
        match std::fs::create_dir(&p) {
            Ok(()) => return Ok(p),
            Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => continue,
            Err(e) => return Err(e).with_context(|| format!("cannot create {}", p.display())),
        }
    }
    bail!(
        "{} and {name}-2 … {name}-{MAX_SUFFIX} all exist: remove old runs, or pass --exist-ok to reuse {}",
        base.display(),
        base.display()
    )
}

/// The run folder, created: `explicit` (`--run-dir`) as given; otherwise `runs/<name>`
/// when resuming or with `exist_ok`, else the next free `runs/<name>[-N]`.
pub fn run_folder(
    explicit: Option<&Path>,
    name: &str,
    resume: bool,
    exist_ok: bool,
) -> Result<PathBuf> {
    let dir = match explicit {
        Some(d) => d.to_path_buf(),
        None if resume || exist_ok => PathBuf::from("runs").join(name),
        None => return increment_path(&PathBuf::from("runs").join(name)),
    };
    std::fs::create_dir_all(&dir)
        .with_context(|| format!("cannot create run folder {}", dir.display()))?;
    Ok(dir)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tmp(name: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("ct-runfolder-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        d
    }

    #[test]
    fn the_next_free_suffix_is_taken_and_nothing_is_reused() {
        let d = tmp("inc");
        let base = d.join("runs").join("exp");
        assert_eq!(increment_path(&base).unwrap(), base);
        assert_eq!(increment_path(&base).unwrap(), d.join("runs/exp-2"));
        assert_eq!(increment_path(&base).unwrap(), d.join("runs/exp-3"));
        // A gap is filled first, as ultralytics does: it takes the lowest free number.
        std::fs::remove_dir(d.join("runs/exp-2")).unwrap();
        assert_eq!(increment_path(&base).unwrap(), d.join("runs/exp-2"));
        // A file in the way counts as taken.
        std::fs::write(d.join("runs/exp-4"), b"x").unwrap();
        assert_eq!(increment_path(&base).unwrap(), d.join("runs/exp-5"));
        assert!(d.join("runs/exp-5").is_dir());
        std::fs::remove_dir_all(&d).unwrap();
    }

    #[test]
    fn explicit_folders_are_used_as_given() {
        let d = tmp("explicit");
        let p = d.join("mine");
        assert_eq!(run_folder(Some(&p), "x", false, false).unwrap(), p);
        assert_eq!(run_folder(Some(&p), "x", false, false).unwrap(), p);
        std::fs::remove_dir_all(&d).unwrap();
    }
}
