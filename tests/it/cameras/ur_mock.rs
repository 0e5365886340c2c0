//! The three-camera cell with its arm behind the real UR driver (ur_rtde via FFI) against the mock
//! UR controller: the run is `cell::run::run`, as for one camera, so the confirmation a real arm
//! needs, the controller's protective stop (every camera's records kept, the resume hint naming
//! the session's root) and the resume all hold for several cameras. The cameras are simulated
//! and render from the pose the controller reports. Needs the `ur-rtde` feature, as
//! `tests/it/ur_session.rs`.
#![cfg(feature = "ur-rtde")]

use std::net::IpAddr;
use std::path::Path;
use std::sync::atomic::AtomicBool;
use std::sync::{mpsc, Arc};
use std::time::Duration;

use handeye_core::geometry::Pose;
use handeye_records::SessionError;
use handeye_robot::kinematics::UrModel;
use handeye_session::cell::cameras::camera_folder;
use handeye_session::cell::run::{run, RunError, RunRequest, SessionTarget, Strategy};
use mocks::{MockFaults, MockUr, MockUrConfig};

use crate::util;

const SIM_ARM: &str = "robot:
  backend: sim
  model: ur10e
  start_joints_deg: [0, -90, 90, -90, -90, 0]
  move_duration_s: 0.0
  repeatability_mm: 0.02
  repeatability_deg: 0.002
  seed: 7
";

const MOCK_ARM: &str = "robot:
  backend: ur
  host: 127.0.0.76
  model: ur10e
  connect_timeout_s: 5
";

#[test]
fn three_cameras_through_ur_rtde_confirm_stop_cleanly_resume_and_recover_every_mount() {
    let (tx, rx) = mpsc::channel();
    std::thread::spawn(move || {
        body();
        let _ = tx.send(());
    });
    rx.recv_timeout(Duration::from_secs(300))
        .expect("test timed out");
}

fn body() {
    let mock = MockUr::start(MockUrConfig {
        address: "127.0.0.76".parse::<IpAddr>().unwrap(),
        model: UrModel::ur10e(),
        start_joints: handeye_robot::Joints::from(
            [0.0, -90f64, 90.0, -90.0, -90.0, 0.0].map(f64::to_radians),
        ),
        flange_from_tcp: Pose::identity(),
        instant_moves: true,
        faults: MockFaults {
            protective_stop_after_moves: Some(4),
            ..MockFaults::default()
        },
        ..MockUrConfig::default()
    })
    .expect("mock starts");
    let dir = tempfile::tempdir().unwrap();
    let config = super::three_cameras(
        dir.path(),
        &[("count: 20", "count: 12"), (SIM_ARM, MOCK_ARM)],
    );
    let out = dir.path().join("session");
    let request = |target: SessionTarget, confirmed: bool| RunRequest {
        config: Some(config.clone()),
        target,
        motion_confirmed: confirmed,
        accept_changed: false,
        stop: Arc::new(AtomicBool::new(false)),
        jobs: None,
    };

    // A real arm: without `--yes` the run asks, and a refusal moves nothing and writes nothing.
    let refused = run(
        &request(SessionTarget::New(out.clone()), false),
        Strategy::Planned,
        &mut util::QuietObserver,
    );
    assert!(
        matches!(&refused, Err(RunError::NotConfirmed(_))),
        "{:?}",
        refused.err().map(|e| e.to_string())
    );
    assert!(!out.exists(), "a refused run wrote {}", out.display());

    // The controller's protective stop mid-run: a clean stop, every camera's records kept.
    let stopped = run(
        &request(SessionTarget::New(out.clone()), true),
        Strategy::Planned,
        &mut util::QuietObserver,
    );
    let error = match stopped {
        Err(RunError::Session(e @ SessionError::Robot { .. })) => e.to_string(),
        other => panic!(
            "expected the protective stop, got {:?}",
            other.map(|_| ()).map_err(|e| e.to_string())
        ),
    };
    assert!(
        error.contains(&format!("--resume {}", out.display())),
        "the hint names the session's root: {error}"
    );
    for name in ["wrist", "left", "right"] {
        let records = records(&camera_folder(&out, name));
        assert_eq!(records, 4, "{name}: the records before the stop are kept");
    }

    // Cleared on the pendant; the resume finishes and every mount is found.
    mock.clear_stops();
    let done = run(
        &request(SessionTarget::Resume(out.clone()), true),
        Strategy::Planned,
        &mut util::QuietObserver,
    )
    .unwrap_or_else(|e| panic!("resume: {e}"));
    assert_eq!(done.outcome.visited_now, 8);
    let result = done.result;
    for (name, truth) in super::truth(&config) {
        let solved = result.transform(&name).unwrap();
        let (mm, deg) = util::pose_error_mm_deg(&solved.pose, &truth);
        eprintln!("{name}: {mm:.3} mm, {deg:.4}° from the truth");
        assert!(mm < 0.5 && deg < 0.05, "{name}: {mm:.3} mm, {deg:.4}°");
    }
    for name in ["wrist", "left", "right"] {
        assert_eq!(records(&camera_folder(&out, name)), 12, "{name}");
    }
    mock.shutdown();
}

fn records(folder: &Path) -> usize {
    std::fs::read_dir(folder.join("poses"))
        .map(|d| d.filter_map(|e| e.ok()).count())
        .unwrap_or(0)
}
