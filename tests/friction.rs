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
