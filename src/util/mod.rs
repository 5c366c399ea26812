//! Small helpers shared across stages, one concept per file: atomic writes (here),
//! stable hashing ([`hash`]), PNG encoding ([`png`]), progress bars ([`progress`]),
//! summary statistics ([`stats`]), host copies of tensors ([`tensor`], feature `train`) and
//! the Hungarian assignment ([`hungarian`]). Weight files of other frameworks are
//! `crate::weights`.

pub mod hash;
pub mod hungarian;
pub mod png;
pub mod progress;
pub mod stats;
#[cfg(feature = "train")]
pub mod tensor;

use std::io::Write;
use std::path::Path;

use anyhow::{Context, Result};

/// Threads that use every core of this machine (1 when the count is unknown).
pub fn all_cores() -> usize {
    std::thread::available_parallelism().map_or(1, |n| n.get())
}

/// Writes `bytes` to `path` through a temp file in the same folder and a rename, so a
/// crash at any moment leaves either the old file or the new one, never a torn one.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<()> {
    let dir = path.parent().filter(|p| !p.as_os_str().is_empty());
    if let Some(dir) = dir {
        std::fs::create_dir_all(dir)
            .with_context(|| format!("cannot create folder {}", dir.display()))?;
    }
    let name = path
        .file_name()
        .with_context(|| format!("{} is not a file path", path.display()))?;
    let tmp = path.with_file_name(format!(
        ".{}.tmp{}",
        name.to_string_lossy(),
        std::process::id()
    ));
    let mut f =
        std::fs::File::create(&tmp).with_context(|| format!("cannot create {}", tmp.display()))?;
    f.write_all(bytes)
        .and_then(|_| f.sync_all())
        .with_context(|| format!("cannot write {}", tmp.display()))?;
    drop(f);
    std::fs::rename(&tmp, path)
        .with_context(|| format!("cannot move {} to {}", tmp.display(), path.display()))?;
    Ok(())
}

#[cfg(test)]
mod tests {
    #[test]
    fn atomic_write_replaces_and_leaves_no_temp() {
        let dir = std::env::temp_dir().join(format!("ct-atomic-{}", std::process::id()));
        let path = dir.join("x.json");
        super::write_atomic(&path, b"one").unwrap();
        super::write_atomic(&path, b"two").unwrap();
        assert_eq!(std::fs::read(&path).unwrap(), b"two");
        assert_eq!(std::fs::read_dir(&dir).unwrap().count(), 1);
        std::fs::remove_dir_all(dir).unwrap();
    }
}
