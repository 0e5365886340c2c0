//! Shared by the integration tests and the session benchmark: copies of the repo's cell configs
//! with their relative paths made absolute and a few keys edited.

#![allow(dead_code)]

use std::path::{Path, PathBuf};
use std::process::Command;

use handeye::geometry::{translation_distance, Pose};

/// The crate root.
pub fn repo() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// The `handeye` binary of this build, as a command to add arguments to.
pub fn handeye() -> Command {
    Command::new(env!("CARGO_BIN_EXE_handeye"))
}

/// A public data set folder, or `None` (with the reason printed) when it is absent. The data
/// sets live in `../shared/datasets` beside the crate; `HANDEYE_DATASETS` points elsewhere (a
/// worktree whose parent has no `shared/`).
pub fn dataset(name: &str) -> Option<PathBuf> {
    let root = std::env::var_os("HANDEYE_DATASETS")
        .map(PathBuf::from)
        .unwrap_or_else(|| repo().join("../shared/datasets"));
    let path = root.join(name);
    if path.exists() {
        Some(path)
    } else {
        eprintln!("SKIP: {} is absent", path.display());
        None
    }
}

/// How far `a` is from `b`: translation (mm) and rotation angle (degrees).
pub fn pose_error_mm_deg(a: &Pose, b: &Pose) -> (f64, f64) {
    (
        translation_distance(a, b) * 1e3,
        a.rotation.angle_to(&b.rotation).to_degrees(),
    )
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

/// `configs/sim-cell.yaml` with a plan of `poses` poses instead of 20, written to
/// `dir/cell.yaml`.
pub fn sim_cell(dir: &Path, poses: usize) -> PathBuf {
    let count = format!("count: {poses}");
    config_variant(dir, "sim-cell.yaml", "cell.yaml", &[("count: 20", &count)])
}
