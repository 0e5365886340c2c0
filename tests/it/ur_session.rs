//! `handeye run` through the real UR driver (ur_rtde via FFI) against the mock UR controller,
//! with the simulated camera rendering from the pose the controller reports. Needs the
//! `ur-rtde` feature (CI builds ur_rtde and runs these).
#![cfg(feature = "ur-rtde")]

use std::net::IpAddr;
use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicBool;
use std::sync::{mpsc, Arc};
use std::time::Duration;

use handeye_core::geometry::{pose_from_rotvec, Pose};
use handeye_records::{SessionError, SessionFolder};
use handeye_robot::kinematics::UrModel;
use handeye_session::cell;
use handeye_session::SessionOutcome;
use mocks::{MockFaults, MockUr, MockUrConfig};
use nalgebra::Vector3;

/// Runs `body` on its own thread and fails the test if it takes longer than `limit`: a broken
/// mock or driver must fail, not hang CI.
fn with_timeout<T: Send + 'static>(
    limit: Duration,
    body: impl FnOnce() -> T + Send + 'static,
) -> T {
    let (tx, rx) = mpsc::channel();
    std::thread::spawn(move || {
        let _ = tx.send(body());
    });
    rx.recv_timeout(limit).expect("test timed out")
}

use crate::util;

fn config_for(dir: &Path, host: &str, count: usize) -> PathBuf {
    let (host, count) = (format!("host: {host}"), format!("count: {count}"));
    util::config_variant(
        dir,
        "sim-cell-ur-mock.yaml",
        "cell.yaml",
        &[("host: 127.0.0.1", &host), ("count: 20", &count)],
    )
}

fn start_mock(address: &str, flange_from_tcp: Pose, faults: MockFaults) -> MockUr {
    MockUr::start(MockUrConfig {
        address: address.parse::<IpAddr>().unwrap(),
        model: UrModel::ur10e(),
        start_joints: handeye_robot::Joints::from([
            0.0,
            -90f64.to_radians(),
            90f64.to_radians(),
            -90f64.to_radians(),
            -90f64.to_radians(),
            0.0,
        ]),
        flange_from_tcp,
        instant_moves: true,
        faults,
        ..MockUrConfig::default()
    })
    .expect("mock starts")
}

fn run(
    config: &Path,
    folder: &SessionFolder,
) -> (cell::PreparedCell, Result<SessionOutcome, SessionError>) {
    let mut prepared = cell::prepare(config).unwrap();
    let mut hardware = prepared.open_hardware().expect("connects to the mock");
    let start = hardware.robot.joint_positions().unwrap();
    let plan = prepared
        .recheck_from(start)
        .expect("plan valid from the mock's start");
    if folder.read_manifest().is_err() {
        folder.write_manifest(&prepared.manifest(0, &plan)).unwrap();
    }
    let setup = prepared.session_setup(folder.clone(), plan, Arc::new(AtomicBool::new(false)));
    let outcome = handeye_session::run_session(
        setup,
        hardware.robot.as_mut(),
        &mut [hardware.cameras[0].as_mut()],
        &mut |_| {},
    );
    (prepared, outcome)
}

fn assert_close(estimate: &Pose, truth: &Pose, what: &str) {
    let (mm, deg) = util::pose_error_mm_deg(estimate, truth);
    eprintln!("{what}: {mm:.3} mm, {deg:.4}°");
    assert!(mm < 0.5 && deg < 0.05, "{what}: {mm:.3} mm, {deg:.4}°");
}

#[test]
fn full_run_through_ur_rtde_recovers_the_truth_with_a_tcp_offset_set() {
    with_timeout(Duration::from_secs(240), || {
        // A TCP offset on the controller: the driver must still report the flange, or the
        // calibration would absorb the offset.
        let tcp = pose_from_rotvec(Vector3::new(0.01, -0.02, 0.15), Vector3::new(0.0, 0.2, 0.1));
        let mock = start_mock("127.0.0.71", tcp, MockFaults::default());
        let dir = tempfile::tempdir().unwrap();
        let config = config_for(dir.path(), "127.0.0.71", 12);
        let folder = SessionFolder::create(&dir.path().join("s")).unwrap();
        let (prepared, outcome) = run(&config, &folder);
        let outcome = outcome.unwrap();
        assert_eq!(outcome.accepted.len(), 12, "skipped {:?}", outcome.skipped);
        let solved = handeye_records::solve_folder(&folder, &prepared.solve_inputs()).unwrap();
        let truth = prepared.config.camera().simulation.unwrap();
        let [(camera_key, camera_mount), (target_key, target_mount)] =
            solved.calibration.unknowns();
        assert_close(&camera_mount, &truth.camera_mount, camera_key);
        assert_close(&target_mount, &truth.target_mount, target_key);
        // The recorded flange poses are the mock's flange, not its TCP.
        let visits = folder.read_visits().unwrap();
        let last_recorded = visits.last().unwrap().base_from_flange;
        let flange = mock.base_from_flange();
        assert!((last_recorded.translation.vector - flange.translation.vector).norm() < 1e-6);
        mock.shutdown();
    });
}

#[test]
fn protective_stop_stops_cleanly_keeps_samples_and_resume_completes() {
    with_timeout(Duration::from_secs(240), || {
        let faults = MockFaults {
            protective_stop_after_moves: Some(4),
            ..MockFaults::default()
        };
        let mock = start_mock("127.0.0.72", Pose::identity(), faults);
        let dir = tempfile::tempdir().unwrap();
        let config = config_for(dir.path(), "127.0.0.72", 10);
        let folder = SessionFolder::create(&dir.path().join("s")).unwrap();
        let (_, outcome) = run(&config, &folder);
        let error = outcome.unwrap_err();
        assert!(matches!(error, SessionError::Robot { .. }), "{error}");
        assert!(error.to_string().contains("--resume"));
        assert_eq!(
            folder.read_visits().unwrap().len(),
            4,
            "samples before the stop are kept"
        );

        // A person clears the stop on the pendant; the run resumes and finishes.
        mock.clear_stops();
        let (_, outcome) = run(&config, &folder);
        let outcome = outcome.unwrap();
        assert_eq!(outcome.accepted, (0..10).collect::<Vec<_>>());
        mock.shutdown();
    });
}

#[test]
fn lost_connection_stops_cleanly_and_keeps_samples() {
    with_timeout(Duration::from_secs(240), || {
        let faults = MockFaults {
            drop_connection_after_moves: Some(3),
            ..MockFaults::default()
        };
        let mock = start_mock("127.0.0.73", Pose::identity(), faults);
        let dir = tempfile::tempdir().unwrap();
        let config = config_for(dir.path(), "127.0.0.73", 8);
        let folder = SessionFolder::create(&dir.path().join("s")).unwrap();
        let (_, outcome) = run(&config, &folder);
        let error = outcome.unwrap_err();
        assert!(matches!(error, SessionError::Robot { .. }), "{error}");
        let kept = folder.read_visits().unwrap().len();
        assert!((2..=3).contains(&kept), "kept {kept}");
        mock.shutdown();

        // The cable is back (a fresh controller at the same place): resume completes.
        let mock = start_mock("127.0.0.73", Pose::identity(), MockFaults::default());
        let (_, outcome) = run(&config, &folder);
        assert_eq!(outcome.unwrap().accepted, (0..8).collect::<Vec<_>>());
        mock.shutdown();
    });
}

#[test]
fn connecting_where_nothing_listens_fails_within_the_timeout() {
    with_timeout(Duration::from_secs(30), || {
        let dir = tempfile::tempdir().unwrap();
        let config = util::config_variant(
            dir.path(),
            "sim-cell-ur-mock.yaml",
            "cell.yaml",
            &[
                ("host: 127.0.0.1", "host: 127.0.0.74"),
                ("count: 20", "count: 6"),
                ("connect_timeout_s: 5", "connect_timeout_s: 2"),
            ],
        );
        let prepared = cell::prepare(&config).unwrap();
        let started = std::time::Instant::now();
        let error = match prepared.open_hardware() {
            Ok(_) => panic!("connected to nothing"),
            Err(e) => format!("{:#}", anyhow::Error::new(e)),
        };
        assert!(
            started.elapsed() < Duration::from_secs(4),
            "took {:?}",
            started.elapsed()
        );
        assert!(error.contains("127.0.0.74"), "{error}");
    });
}
