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

/// A Python with numpy and OpenCV (`opencv-python-headless<5`, with the ArUco module) for the
/// tests that compare against OpenCV or render with it, or `None` (reason printed) without
/// `python3`. scripts/test.sh installs the packages for python3 itself; otherwise a venv of the
/// test binary's own is made under its temp dir. Set up once per test binary (tests run in
/// parallel).
pub fn python_with_opencv() -> Option<PathBuf> {
    static PYTHON: std::sync::OnceLock<Option<PathBuf>> = std::sync::OnceLock::new();
    PYTHON
        .get_or_init(|| {
            if Command::new("python3").arg("--version").output().is_err() {
                skip("python3 is absent, the OpenCV comparison is not run (CI has it: scripts/test.sh)");
                return None;
            }
            let ready = |python: &Path| {
                Command::new(python)
                    .args(["-c", "import numpy, cv2; cv2.aruco.ArucoDetector"])
                    .output()
                    .is_ok_and(|o| o.status.success())
            };
            if ready(Path::new("python3")) {
                return Some(PathBuf::from("python3"));
            }
            let temp = option_env!("CARGO_TARGET_TMPDIR")
                .map(PathBuf::from)
                .unwrap_or_else(std::env::temp_dir);
            let venv = temp.join("opencv-venv");
            let python = venv.join("bin/python");
            if !ready(&python) {
                let status = Command::new("python3")
                    .args(["-m", "venv"])
                    .arg(&venv)
                    .status()
                    .expect("python3 -m venv");
                assert!(status.success(), "python3 -m venv {} failed", venv.display());
                let status = Command::new(&python)
                    .args(["-m", "pip", "install", "--quiet", "numpy", "opencv-python-headless<5"])
                    .status()
                    .expect("pip");
                assert!(
                    status.success() && ready(&python),
                    "pip install numpy opencv-python-headless<5 into {} failed",
                    venv.display()
                );
            }
            Some(python)
        })
        .clone()
}

/// Reports a test skipped for a missing tool (python3, chromium). Under `scripts/test.sh`, which
/// installs every such tool and sets `HANDEYE_REQUIRE_TOOLS=1`, a skip is a failure instead: a CI
/// run must not pass green without having compared against the independent implementation.
pub fn skip(why: &str) {
    assert!(
        std::env::var_os("HANDEYE_REQUIRE_TOOLS").is_none(),
        "HANDEYE_REQUIRE_TOOLS is set but the test would skip: {why}"
    );
    eprintln!("SKIP: {why}");
}
