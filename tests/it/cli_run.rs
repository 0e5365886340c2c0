//! `handeye run` as a person runs it: the binary, a real process, killed mid-run and resumed.

use std::path::{Path, PathBuf};
use std::process::Stdio;
use std::time::{Duration, Instant};

use handeye_records::dataset::Dataset;
use handeye_records::result::ResultFile;

use crate::util;
use util::handeye;

/// The demo config with a 10-pose plan and `move_duration_s` seconds per move.
fn slow_config(dir: &Path, move_duration_s: f64) -> PathBuf {
    let duration = format!("move_duration_s: {move_duration_s}");
    util::config_variant(
        dir,
        "sim-cell.yaml",
        "cell.yaml",
        &[
            ("count: 20", "count: 10"),
            ("move_duration_s: 0.0", &duration),
            // Every pose of the plan (generated plans are adaptive by default).
            ("plan:\n", "plan:\n  adaptive: false\n"),
        ],
    )
}

#[test]
fn killed_mid_run_resumes_from_the_last_sample_and_matches_a_solve_of_the_same_data() {
    let dir = tempfile::tempdir().unwrap();
    let config = slow_config(dir.path(), 0.3);
    let session = dir.path().join("session");
    let mut child = handeye()
        .args(["run", "--config"])
        .arg(&config)
        .arg("--output")
        .arg(&session)
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    // Kill it hard (no chance to clean up) once four poses are on disk.
    let deadline = Instant::now() + Duration::from_secs(120);
    while !session.join("poses/003.yaml").exists() {
        assert!(
            Instant::now() < deadline,
            "the run never recorded four poses"
        );
        assert!(
            child.try_wait().unwrap().is_none(),
            "the run ended before it was killed"
        );
        std::thread::sleep(Duration::from_millis(20));
    }
    child.kill().unwrap();
    child.wait().unwrap();
    let kept = std::fs::read_dir(session.join("poses")).unwrap().count();
    assert!(
        (4..10).contains(&kept),
        "{kept} poses on disk after the kill"
    );
    // Every file on disk is whole: the samples file parses.
    let before = Dataset::load(&session.join("samples.yaml")).unwrap();
    assert!(before.pairs.len() >= 3);

    let status = handeye()
        .args(["run", "--resume"])
        .arg(&session)
        .stdout(Stdio::null())
        .status()
        .unwrap();
    assert!(status.success());
    let dataset = Dataset::load(&session.join("samples.yaml")).unwrap();
    let ids: Vec<String> = dataset
        .pairs
        .iter()
        .map(|p| p.id.clone().unwrap())
        .collect();
    let expected: Vec<String> = (0..10).map(|i| format!("pose-{i:03}")).collect();
    assert_eq!(
        ids, expected,
        "each pose recorded exactly once, in plan order"
    );
    // The samples recorded before the kill are unchanged by the resume.
    for (a, b) in before.pairs.iter().zip(&dataset.pairs) {
        assert_eq!(a.id, b.id);
        assert!(
            (a.camera_from_target.translation.vector - b.camera_from_target.translation.vector)
                .norm()
                < 1e-15
        );
    }

    // The final result equals an uninterrupted solve of the same data.
    let result = ResultFile::load_mounts(&session.join("result.yaml")).unwrap();
    let config = handeye_config::CellConfig::load(&config).unwrap();
    let folder = handeye_records::SessionFolder::open(&session).unwrap();
    let space = config.solver.space;
    let inputs = handeye_records::SolveInputs::load(config).unwrap();
    let (direct, _) = handeye_records::load_and_solve(&folder, &inputs, space).unwrap();
    let direct = direct.calibration;
    assert!(
        (result.camera_mount.translation.vector - direct.camera_mount.translation.vector).norm()
            < 1e-12
    );
    assert!(
        result
            .camera_mount
            .rotation
            .angle_to(&direct.camera_mount.rotation)
            < 1e-12
    );
    assert!(
        (result.target_mount.translation.vector - direct.target_mount.translation.vector).norm()
            < 1e-12
    );
}

#[test]
fn run_refuses_a_bad_config_before_anything_moves_and_writes_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let config = util::config_variant(
        dir.path(),
        "sim-cell.yaml",
        "cell.yaml",
        &[
            ("count: 20", "count: 10"),
            ("max_tilt_deg: 30", "max_tilt_deg: 95"),
        ],
    );
    let session = dir.path().join("session");
    let output = util::run_cli(&config, &session);
    assert!(!output.status.success());
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(
        stderr.contains("cell.yaml")
            && stderr.contains("plan.generate")
            && stderr.contains("max_tilt_deg"),
        "{stderr}"
    );
    assert!(!session.exists(), "nothing is written for a refused config");
}
