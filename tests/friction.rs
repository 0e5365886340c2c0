//! Friction a new user hits (issue #14, item 4): each test reproduces one complaint with the
//! binary, as a person runs it, and checks the fix.

use std::path::Path;
use std::process::{Command, Output};

mod util;

fn handeye() -> Command {
    Command::new(env!("CARGO_BIN_EXE_handeye"))
}

fn text(bytes: &[u8]) -> String {
    String::from_utf8_lossy(bytes).into_owned()
}

/// `handeye run --config <config> --out <session>`, output captured (not a terminal).
fn run_session(config: &Path, session: &Path) -> Output {
    handeye()
        .args(["run", "--config"])
        .arg(config)
        .arg("--out")
        .arg(session)
        .output()
        .unwrap()
}

#[test]
fn the_no_intrinsics_demo_writes_its_report() {
    let dir = tempfile::tempdir().unwrap();
    let session = dir.path().join("session");
    let config = util::repo().join("configs/sim-cell-no-intrinsics.yaml");
    let out = run_session(&config, &session);
    let (stdout, stderr) = (text(&out.stdout), text(&out.stderr));
    assert!(out.status.success(), "{stdout}\n{stderr}");
    assert!(
        !stderr.contains("could not be written"),
        "the report failed:\n{stderr}"
    );
    let report = std::fs::read_to_string(session.join("report.html")).unwrap();
    // The samples the solve used (board poses by PnP with the estimated intrinsics) are in the
    // session, so the report has one thumbnail per frame.
    let samples = handeye::dataset::Dataset::load(&session.join("samples.yaml")).unwrap();
    assert_eq!(samples.pairs.len(), 20);
    assert!(
        report.contains("pose-019"),
        "the report lacks the last sample"
    );
}

#[test]
fn piped_output_has_one_line_per_pose() {
    let dir = tempfile::tempdir().unwrap();
    let config = util::config_variant(
        dir.path(),
        "sim-cell.yaml",
        "cell.yaml",
        &[("count: 20", "count: 6")],
    );
    let out = run_session(&config, &dir.path().join("session"));
    let stdout = text(&out.stdout);
    assert!(out.status.success(), "{stdout}\n{}", text(&out.stderr));
    // Output captured here is a pipe, as with `| tee log`: the bar is hidden, the lines are not.
    for pose in 0..6 {
        let prefix = format!("pose {pose:>3}: ok, ");
        assert!(
            stdout.lines().any(|l| l.starts_with(&prefix)),
            "no line for pose {pose} in:\n{stdout}"
        );
    }
}

#[test]
fn detect_exits_2_with_a_message_when_no_image_shows_the_board() {
    let dir = tempfile::tempdir().unwrap();
    let mut images = Vec::new();
    for (name, grey) in [("blank.png", 180u8), ("dark.png", 20)] {
        let path = dir.path().join(name);
        image::GrayImage::from_pixel(1280, 720, image::Luma([grey]))
            .save(&path)
            .unwrap();
        images.push(path);
    }
    let results = dir.path().join("detections.yaml");
    let out = handeye()
        .arg("detect")
        .args(&images)
        .arg("--target")
        .arg(util::repo().join("configs/targets/aprilgrid-6x6.yaml"))
        .arg("--intrinsics")
        .arg(util::repo().join("configs/cameras/sim-1280x720.yaml"))
        .arg("-o")
        .arg(&results)
        .output()
        .unwrap();
    let stderr = text(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{stderr}");
    assert!(
        stderr.contains("aprilgrid-6x6.yaml") && stderr.contains("none of the 2 images"),
        "{stderr}"
    );
    // The per-image results are still written (each says why).
    let written = std::fs::read_to_string(&results).unwrap();
    assert_eq!(written.matches("found: false").count(), 2, "{written}");
}
