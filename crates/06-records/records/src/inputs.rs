//! What a session was started from, by content: the sha256 of each input file (cell config,
//! board, intrinsics, plan), recorded in `session.yaml` so a resume can tell when a file changed
//! under it — new intrinsics or a moved board would silently mix two cells in one dataset.
//!
//! Depends on the session's error type only.

use std::fmt;
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};
use sha2::{Digest, Sha256};

use super::SessionError;

/// One input file of a session and the hash of its bytes when the session used it.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct InputFile {
    /// What the file is to the cell: `config`, `target`, `intrinsics` or `plan` (the config key).
    pub role: String,
    /// The file, as the config names it (absolute when it could be resolved).
    pub path: PathBuf,
    /// sha256 of the file's bytes, lowercase hex.
    pub sha256: String,
}

impl InputFile {
    /// Hashes the file `path` as the input `role`.
    pub fn hash(role: &str, path: &Path) -> Result<InputFile, SessionError> {
        let bytes = std::fs::read(path).map_err(|source| SessionError::Io {
            path: path.to_path_buf(),
            source: handeye_core::yaml_file::name_symlink_loop(path, source),
        })?;
        Ok(InputFile {
            role: role.to_string(),
            path: std::fs::canonicalize(path).unwrap_or_else(|_| path.to_path_buf()),
            sha256: sha256_hex(&bytes),
        })
    }
}

/// sha256 of `bytes`, lowercase hex.
pub fn sha256_hex(bytes: &[u8]) -> String {
    format!("{:x}", Sha256::digest(bytes))
}

/// An input whose content differs from what the session recorded.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct InputChange {
    /// The input's role (`config`, `target`, `intrinsics`, `plan`).
    pub role: String,
    /// The file the session recorded (`None`: the session had no such input).
    pub recorded: Option<InputFile>,
    /// The file the cell uses now (`None`: the cell has no such input any more).
    pub current: Option<InputFile>,
}

impl fmt::Display for InputChange {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let short = |h: &str| h.chars().take(16).collect::<String>();
        match (&self.recorded, &self.current) {
            (Some(old), Some(new)) if old.path == new.path => write!(
                f,
                "{} {}: sha256 {} when recorded, {} now",
                self.role,
                new.path.display(),
                short(&old.sha256),
                short(&new.sha256)
            ),
            (Some(old), Some(new)) => write!(
                f,
                "{}: was {} (sha256 {}), now {} (sha256 {})",
                self.role,
                old.path.display(),
                short(&old.sha256),
                new.path.display(),
                short(&new.sha256)
            ),
            (Some(old), None) => write!(
                f,
                "{}: was {} (sha256 {}), the cell has none now",
                self.role,
                old.path.display(),
                short(&old.sha256)
            ),
            (None, Some(new)) => write!(
                f,
                "{}: none when recorded, now {} (sha256 {})",
                self.role,
                new.path.display(),
                short(&new.sha256)
            ),
            (None, None) => write!(f, "{}: unchanged", self.role),
        }
    }
}

/// The inputs whose content (or presence) differs between `recorded` and `current`, by role.
/// A file at another path with the same bytes is not a change.
pub fn changed_inputs(recorded: &[InputFile], current: &[InputFile]) -> Vec<InputChange> {
    let mut roles: Vec<&str> = recorded
        .iter()
        .chain(current)
        .map(|i| i.role.as_str())
        .collect();
    roles.sort_unstable();
    roles.dedup();
    roles
        .into_iter()
        .filter_map(|role| {
            let old = recorded.iter().find(|i| i.role == role);
            let new = current.iter().find(|i| i.role == role);
            let same = matches!((old, new), (Some(a), Some(b)) if a.sha256 == b.sha256);
            (!same).then(|| InputChange {
                role: role.to_string(),
                recorded: old.cloned(),
                current: new.cloned(),
            })
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sha256_of_known_bytes() {
        assert_eq!(
            sha256_hex(b"abc"),
            "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad"
        );
    }

    #[test]
    fn an_edited_file_is_a_change_and_a_moved_copy_is_not() {
        let dir = tempfile::tempdir().unwrap();
        let a = dir.path().join("camera.yaml");
        std::fs::write(&a, "fx: 800").unwrap();
        let recorded = vec![InputFile::hash("intrinsics", &a).unwrap()];
        let b = dir.path().join("copy.yaml");
        std::fs::write(&b, "fx: 800").unwrap();
        assert!(
            changed_inputs(&recorded, &[InputFile::hash("intrinsics", &b).unwrap()]).is_empty()
        );
        std::fs::write(&a, "fx: 840").unwrap();
        let changes = changed_inputs(&recorded, &[InputFile::hash("intrinsics", &a).unwrap()]);
        assert_eq!(changes.len(), 1);
        let text = changes[0].to_string();
        assert!(
            text.contains("camera.yaml") && text.contains("intrinsics"),
            "{text}"
        );
        assert!(text.contains(&recorded[0].sha256[..16]), "{text}");
    }
}
