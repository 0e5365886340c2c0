//! Shared by the integration tests and the benchmarks: copies of the repo's cell configs
//! with their relative paths made absolute and a few keys edited.

// Test helpers are `pub` for the test modules; no crate sees them.
#![allow(dead_code, unreachable_pub)]

use std::path::{Path, PathBuf};
use std::process::Command;

use std::sync::atomic::AtomicBool;
use std::sync::Arc;

use handeye_core::geometry::{translation_distance, Pose};
use handeye_session::cell::run::{CellRun, RunObserver, RunRequest, SessionTarget};
use handeye_session::cell::PreparedCell;

pub mod cameras;
pub mod fakes;
pub mod live;

/// A DDS domain id no other test of this process uses: live ROS 2 tests run side by side, and two
/// on one domain hear each other's nodes (a second action server of one name, a domain that was
/// to be empty). 20..=101: clear of the shipped configs' 42 and, on the RTPS port formula
/// (7400 + 250·id), below Linux's ephemeral ports (32768 on).
pub fn ros_domain() -> u16 {
    static NEXT: std::sync::atomic::AtomicU16 = std::sync::atomic::AtomicU16::new(20);
    loop {
        let id = NEXT.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        assert!(
            id <= 101,
            "more live ROS 2 tests than free DDS domain ids (20..=101)"
        );
        if id != 42 {
            return id;
        }
    }
}

/// The crate root.
pub fn repo() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// The `handeye` binary of this build, as a command to add arguments to.
pub fn handeye() -> Command {
    Command::new(env!("CARGO_BIN_EXE_handeye"))
}

/// Runs `command` and returns its standard output; fails the test with its output and errors
/// when it does not succeed.
pub fn succeeds(command: &mut Command) -> String {
    let output = command.output().unwrap();
    let stdout = String::from_utf8_lossy(&output.stdout).to_string();
    assert!(
        output.status.success(),
        "{stdout}{}",
        String::from_utf8_lossy(&output.stderr)
    );
    stdout
}

/// A public data set folder, or `None` (with the reason printed) when it is absent. The data
/// sets live in `../shared/datasets` beside the crate; a clone made elsewhere from a local
/// checkout (CI clones main into a scratch folder) finds them beside that checkout, its
/// `origin`; `HANDEYE_DATASETS` points anywhere else.
pub fn dataset(name: &str) -> Option<PathBuf> {
    let roots: Vec<PathBuf> = match std::env::var_os("HANDEYE_DATASETS") {
        Some(root) => vec![PathBuf::from(root)],
        None => std::iter::once(repo())
            .chain(local_origin())
            .map(|checkout| checkout.join("../shared/datasets"))
            .collect(),
    };
    if let Some(path) = roots
        .iter()
        .map(|root| root.join(name))
        .find(|p| p.exists())
    {
        return Some(path);
    }
    let tried: Vec<String> = roots
        .iter()
        .map(|root| root.join(name).display().to_string())
        .collect();
    say_skip(&format!("data set absent (looked in {})", tried.join(", ")));
    None
}

/// The checkout this crate was cloned from, when its `origin` is a folder on this machine.
fn local_origin() -> Option<PathBuf> {
    let output = Command::new("git")
        .arg("-C")
        .arg(repo())
        .args(["remote", "get-url", "origin"])
        .output()
        .ok()?;
    let url = String::from_utf8(output.stdout).ok()?;
    let path = PathBuf::from(url.trim().trim_start_matches("file://"));
    (output.status.success() && path.is_dir()).then_some(path)
}

/// Prints why a test skips where a passing run shows it too: straight to stderr, past the test
/// harness's capture (which keeps `eprintln!` of a passing test out of the log).
fn say_skip(why: &str) {
    use std::io::Write;
    let _ = writeln!(std::io::stderr(), "SKIP: {why}");
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
    say_skip(why);
}

/// Prints the run's notes to stderr and nothing else; refuses to move a real arm (a run that
/// needs a person's confirmation is not what a test means to run).
pub struct QuietObserver;

impl RunObserver for QuietObserver {
    fn confirm_motion(
        &mut self,
        _: &PreparedCell,
        _: usize,
    ) -> Result<(), Box<dyn std::error::Error + Send + Sync>> {
        Err("no one to confirm".into())
    }
    fn note(&mut self, message: &str) {
        eprintln!("note: {message}");
    }
}

/// `handeye run --config CONFIG --output SESSION`, its output (status, stdout, stderr).
pub fn run_cli(config: &Path, session: &Path) -> std::process::Output {
    handeye()
        .args(["run", "--config"])
        .arg(config)
        .arg("--output")
        .arg(session)
        .output()
        .unwrap()
}

/// `handeye run --yes` of the cell `config` into the new session folder `out` (a mock
/// controller's arm moves without asking).
pub fn new_run(config: &Path, out: &Path) -> RunRequest {
    RunRequest {
        config: Some(config.to_path_buf()),
        target: SessionTarget::New(out.to_path_buf()),
        motion_confirmed: true,
        accept_changed: false,
        stop: Arc::new(AtomicBool::new(false)),
        jobs: None,
    }
}

/// A new session of the cell `config` run into `out` in-process and solved, as `handeye run
/// --yes` does.
pub fn run_cell(config: &Path, out: &Path) -> CellRun {
    handeye_session::cell::run::run(
        &new_run(config, out),
        handeye_session::cell::run::Strategy::Planned,
        &mut QuietObserver,
    )
    .unwrap_or_else(|e| panic!("run of {}: {e}", config.display()))
}

/// The WebSocket request a console's own page makes, from the URL the console printed
/// (`http://ADDR/?token=SECRET`): `/ws` with the secret, and the page's Origin.
pub fn console_socket(url: &str) -> tokio_tungstenite::tungstenite::handshake::client::Request {
    use tokio_tungstenite::tungstenite::client::IntoClientRequest;
    let rest = url
        .strip_prefix("http://")
        .unwrap_or_else(|| panic!("not an http:// console URL: {url}"));
    let (authority, query) = rest
        .split_once("/?")
        .unwrap_or_else(|| panic!("the console URL carries no secret: {url}"));
    let mut request = format!("ws://{authority}/ws?{query}")
        .into_client_request()
        .unwrap();
    request
        .headers_mut()
        .insert("Origin", format!("http://{authority}").parse().unwrap());
    request
}

/// The median of `values` (the mean of the middle two for an even count).
pub fn median(mut values: Vec<f64>) -> f64 {
    values.sort_by(f64::total_cmp);
    let n = values.len();
    if n % 2 == 1 {
        values[n / 2]
    } else {
        0.5 * (values[n / 2 - 1] + values[n / 2])
    }
}

/// Runs `f` on its own thread and fails the test if it takes longer than `limit` (a hang is a
/// failure with a message, not a stuck CI run).
pub fn within<T: Send + 'static>(
    limit: std::time::Duration,
    f: impl FnOnce() -> T + Send + 'static,
) -> T {
    let (tx, rx) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        let _ = tx.send(std::panic::catch_unwind(std::panic::AssertUnwindSafe(f)));
    });
    match rx.recv_timeout(limit) {
        Ok(Ok(v)) => v,
        Ok(Err(panic)) => std::panic::resume_unwind(panic),
        Err(_) => panic!("test did not finish within {limit:?}"),
    }
}

/// The python of the venv `name` under the test target's tmp dir, made (with `packages` from
/// PyPI) when `imports` cannot be imported there yet; `None` (printed, with `why` python3 is
/// needed) without python3. Callers keep the answer in a `OnceLock` (tests run in parallel).
pub fn venv_python(name: &str, imports: &str, packages: &[&str], why: &str) -> Option<PathBuf> {
    if Command::new("python3").arg("--version").output().is_err() {
        skip(&format!("python3 is absent ({why})"));
        return None;
    }
    let venv = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join(name);
    let python = venv.join("bin/python");
    let ready = Command::new(&python)
        .args(["-c", &format!("import {imports}")])
        .output()
        .is_ok_and(|o| o.status.success());
    if !ready {
        let status = Command::new("python3")
            .args(["-m", "venv"])
            .arg(&venv)
            .status()
            .expect("python3 -m venv");
        assert!(status.success(), "python3 -m venv {}", venv.display());
        let status = Command::new(venv.join("bin/pip"))
            .args(["install", "--quiet"])
            .args(packages)
            .status()
            .expect("pip");
        assert!(
            status.success(),
            "pip install {} (needs PyPI)",
            packages.join(" ")
        );
    }
    Some(python)
}

/// Every file under `root` (relative path) with its bytes.
pub fn folder_bytes(root: &Path) -> std::collections::BTreeMap<PathBuf, Vec<u8>> {
    let mut files = std::collections::BTreeMap::new();
    let mut todo = vec![root.to_path_buf()];
    while let Some(dir) = todo.pop() {
        for entry in std::fs::read_dir(&dir).unwrap() {
            let path = entry.unwrap().path();
            if path.is_dir() {
                todo.push(path);
            } else {
                let bytes = std::fs::read(&path).unwrap();
                files.insert(path.strip_prefix(root).unwrap().to_path_buf(), bytes);
            }
        }
    }
    files
}

/// A copy of the folder `from` (every file, same relative paths) at `to`, for a test that writes
/// into a session other tests of its binary read.
pub fn copy_folder(from: &Path, to: &Path) {
    for (file, bytes) in folder_bytes(from) {
        let path = to.join(file);
        std::fs::create_dir_all(path.parent().unwrap()).unwrap();
        std::fs::write(path, bytes).unwrap();
    }
}

/// Every tag corner of `board` a camera `camera` sees from `camera_from_target`, its pixel off
/// by `pixel_noise` (per axis), kept 5 px inside the image: a synthetic frame's detections.
pub fn seen_corners(
    board: &handeye_vision::Board,
    camera: &handeye_core::camera_model::CameraModel,
    camera_from_target: &Pose,
    pixel_noise: &rand_distr::Normal<f64>,
    rng: &mut rand::rngs::StdRng,
) -> Vec<handeye_solve::Corner> {
    use rand_distr::Distribution;
    let mut corners = Vec::new();
    for tag in board.tags() {
        for point in board.tag_corners_in_target(tag.id).unwrap() {
            let Some(pixel) = camera.project(&(camera_from_target * point)) else {
                continue;
            };
            let noisy = nalgebra::Point2::new(
                pixel.x + pixel_noise.sample(rng),
                pixel.y + pixel_noise.sample(rng),
            );
            if noisy.x > 5.0
                && noisy.y > 5.0
                && noisy.x < f64::from(camera.width) - 5.0
                && noisy.y < f64::from(camera.height) - 5.0
            {
                corners.push(handeye_solve::Corner {
                    point_in_target: point,
                    pixel: noisy,
                });
            }
        }
    }
    corners
}

/// Asserts that the leave-one-out figures `verify --session` printed (`stdout`) are the run's
/// held-out ones (`held`, its result's verdict figures) to the printed digit: one figure for one
/// session.
pub fn assert_leave_one_out_is_held_out(stdout: &str, held: &handeye_solve::verdict::HeldOut) {
    let rotation = format!(
        "{} poses: rotation RMS {:.4}°",
        held.poses, held.rotation_rms_deg
    );
    let translation = format!(
        "translation at the target RMS {:.3} mm",
        held.translation_rms_mm
    );
    assert!(
        stdout.contains(&rotation) && stdout.contains(&translation),
        "{stdout}\nagainst the run's {held:?}"
    );
}

/// `handeye verify --config CONFIG --result RESULT -o OUT`: a held-out run of an answer on the
/// cell.
pub fn holdout_command(config: &Path, result: &Path, out: &Path) -> Command {
    let mut command = handeye();
    command
        .args(["verify", "--config"])
        .arg(config)
        .arg("--result")
        .arg(result)
        .arg("-o")
        .arg(out);
    command
}
