//! Shared by the integration tests and the session benchmark: copies of the repo's cell configs
//! with their relative paths made absolute and a few keys edited.

#![allow(dead_code)]

use std::path::{Path, PathBuf};

/// The crate root.
pub fn repo() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// A copy of `configs/<base>` written to `dir/<name>`, with the board and intrinsics paths made
/// absolute and each `(from, to)` edit applied (each `from` must occur).
pub fn config_variant(dir: &Path, base: &str, name: &str, edits: &[(&str, &str)]) -> PathBuf {
    let configs = repo().join("configs");
    let mut text = std::fs::read_to_string(configs.join(base)).unwrap();
    for key in ["target: ", "intrinsics: "] {
        for folder in ["targets/", "cameras/"] {
            text = text.replace(
                &format!("{key}{folder}"),
                &format!("{key}{}/{folder}", configs.display()),
            );
        }
    }
    for (from, to) in edits {
        assert!(text.contains(from), "config {base} has no {from:?}");
        text = text.replace(from, to);
    }
    let path = dir.join(name);
    std::fs::write(&path, text).unwrap();
    path
}
