//! Issue 16, arm time: plans ordered for travel time visit the same poses and keep every move
//! inside the joint ranges and the workspace box; settling by measured joint speeds never
//! captures a frame exposed while the arm still moved; the adaptive default stops at its target,
//! never before the minimum pose count, and at the maximum when the target is out of reach.

use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicBool;
use std::sync::{Arc, Mutex};
use std::time::Instant;

use handeye_camera::{Camera, CameraError, Frame};
use handeye_core::camera_model::CameraModel;
use handeye_core::geometry::Pose;
use handeye_plan::check::MoveCheck;
use handeye_records::SessionFolder;
use handeye_robot::sim::SimRobot;
use handeye_robot::Joints;
use handeye_session::cell;
use handeye_session::cell::run as cell_run;

use crate::util;

/// `configs/sim-cell.yaml` with edits, in `dir/name`.
fn sim_cell(dir: &Path, name: &str, edits: &[(&str, &str)]) -> PathBuf {
    util::config_variant(dir, "sim-cell.yaml", name, edits)
}

/// The pose index in `poses` within 1e-9 m and 1e-9 rad of `p`.
fn find(poses: &[(Pose, Joints)], p: &Pose) -> Option<usize> {
    poses.iter().position(|(q, _)| {
        (q.translation.vector - p.translation.vector).norm() < 1e-9
            && q.rotation.angle_to(&p.rotation) < 1e-9
    })
}

#[test]
fn the_reordered_plan_visits_the_same_poses_inside_the_ranges_and_the_box() {
    let dir = tempfile::tempdir().unwrap();
    for (count, seed) in [(20, 1), (30, 5)] {
        let generate = format!("count: {count}, distance: [0.55, 0.75], max_tilt_deg: 30, max_roll_deg: 20, seed: {seed}");
        let from = "count: 20, distance: [0.55, 0.75], max_tilt_deg: 30, max_roll_deg: 20, seed: 1";
        // Fixed plans (a generated plan is adaptive by default).
        let ordered = sim_cell(
            dir.path(),
            "ordered.yaml",
            &[(from, &generate), ("plan:\n", "plan:\n  adaptive: false\n")],
        );
        let scripted = sim_cell(
            dir.path(),
            "scripted.yaml",
            &[
                (from, &generate),
                ("plan:\n", "plan:\n  adaptive: false\n  reorder: false\n"),
            ],
        );
        let ordered = cell::prepare(&ordered).unwrap();
        let scripted = cell::prepare(&scripted).unwrap();
        let given = scripted.report.validated().expect("the plan checks");
        let plan = ordered
            .report
            .validated()
            .expect("the reordered plan checks");

        // The same poses, each once.
        assert_eq!(plan.len(), given.len());
        let mut seen = vec![false; given.len()];
        for (pose, _) in &plan {
            let i = find(&given, pose).expect("every visited pose is a plan pose");
            assert!(!seen[i], "pose {i} visited twice");
            seen[i] = true;
        }
        // Each pose line names its plan index: the order is a permutation of the plan.
        let mut indices: Vec<usize> = ordered.report.poses.iter().map(|p| p.index).collect();
        assert_ne!(indices, (0..count).collect::<Vec<_>>(), "not reordered");
        indices.sort_unstable();
        assert_eq!(indices, (0..count).collect::<Vec<_>>());

        // Every move from the start, in the order that runs, within the joint ranges and with its
        // whole joint path inside the workspace box (the checks the run applies before a move).
        let check = MoveCheck::with_model(
            ordered.arm.clone().expect("a UR model"),
            ordered.config.workspace,
        );
        let mut from = ordered.start_joints;
        for (pose, joints) in &plan {
            assert_eq!(check.problem(&from, joints), None);
            assert!(ordered.arm.as_ref().unwrap().within_limits(joints));
            assert!(ordered.config.workspace.contains(pose));
            from = *joints;
        }

        // Shorter in move time, and the summary says so.
        let total = ordered.report.total_move_time_s();
        let given_total = scripted.report.total_move_time_s();
        assert_eq!(ordered.report.given_order_move_time_s, Some(given_total));
        eprintln!(
            "{count} poses: total move time {total:.1} s, {given_total:.1} s in the given order"
        );
        assert!(
            total < 0.8 * given_total,
            "{total:.1} s vs {given_total:.1} s"
        );
        let summary = ordered.report.to_string();
        let expected =
            format!("total move time {total:.1} s ({given_total:.1} s in the given order)");
        assert!(summary.contains(&expected), "{summary}");
        // `reorder: false` keeps the scripted order.
        assert!(scripted
            .report
            .poses
            .iter()
            .enumerate()
            .all(|(k, p)| p.index == k));
    }
}

/// A camera that notes when each frame's exposure started.
struct NotingCamera<C: Camera> {
    inner: C,
    exposures: Arc<Mutex<Vec<Instant>>>,
}

impl<C: Camera> Camera for NotingCamera<C> {
    fn grab(&mut self, not_before: Instant) -> Result<Frame, CameraError> {
        let frame = self.inner.grab(not_before)?;
        self.exposures.lock().unwrap().push(frame.captured_at);
        Ok(frame)
    }
    fn model(&self) -> &CameraModel {
        self.inner.model()
    }
}

/// Runs a fixed 6-pose plan of `config` on the simulated cell (timed moves, ring-down) and
/// returns, for each frame, the fastest joint speed of the arm during its exposure (°/s), and
/// the session's settle threshold (°/s, 0 when off).
fn fastest_joint_during_exposures(config: &Path) -> (Vec<f64>, f64) {
    let prepared = cell::prepare(config).unwrap();
    let plan = prepared.report.validated().expect("valid plan");
    let dir = tempfile::tempdir().unwrap();
    let folder = SessionFolder::create(&dir.path().join("s")).unwrap();
    folder.write_manifest(&prepared.manifest(0, &plan)).unwrap();
    let truth = prepared.config.camera().simulation.unwrap();
    let robot = cell::sim::arm(
        &prepared.config,
        prepared.kinematics().unwrap(),
        prepared.start_joints,
    )
    .unwrap();
    let arm = robot.clone();
    let camera = cell::sim::camera(
        &prepared.config,
        truth,
        Box::new(move || arm.lock().true_base_from_flange()),
        prepared.camera().camera_model,
        prepared.camera().board.clone(),
    )
    .unwrap();
    let exposures = Arc::new(Mutex::new(Vec::new()));
    let mut camera = NotingCamera {
        inner: camera,
        exposures: exposures.clone(),
    };
    let setup = prepared.session_setup(folder.clone(), plan, Arc::new(AtomicBool::new(false)));
    let threshold = setup
        .settle_by_speed
        .map_or(0.0, |s| s.max_joint_speed.to_degrees());
    let mut driven = robot.clone();
    let outcome =
        handeye_session::run_session(setup, &mut driven, &mut [&mut camera], &mut |_| {}).unwrap();
    assert_eq!(outcome.visited_now, 6);
    assert!(outcome.moving_s > 0.0);
    let arm = robot.lock();
    let exposures = exposures.lock().unwrap();
    assert_eq!(exposures.len(), 6);
    let fastest = exposures.iter().map(|&t| fastest_over(&arm, t)).collect();
    (fastest, threshold)
}

/// The fastest joint speed over a 5 ms exposure starting at `t`, °/s.
fn fastest_over(arm: &SimRobot, t: Instant) -> f64 {
    (0..=10)
        .map(|k| {
            let (_, qd) = arm.joint_state_at(t + std::time::Duration::from_micros(500 * k));
            qd.iter().fold(0.0f64, |m, v| m.max(v.abs())).to_degrees()
        })
        .fold(0.0, f64::max)
}

#[test]
fn settling_by_measurement_never_captures_a_frame_exposed_while_the_arm_moved() {
    let dir = tempfile::tempdir().unwrap();
    let timed = "move_duration_s: 0.0\n  move_at_limits: true\n  ringing_deg: 0.1\n  ringing_hz: 8\n  ringing_decay_s: 0.12";
    let fast_limits = "limits: {linear_speed: 0.25, linear_acceleration: 1.0, joint_speed_deg: 90, joint_acceleration_deg: 180}";
    let limits = "limits: {linear_speed: 0.25, linear_acceleration: 1.0, joint_speed_deg: 60, joint_acceleration_deg: 120}";
    let settle = "session: {settle_s: 0.0,";
    let base = [
        ("move_duration_s: 0.0", timed),
        (limits, fast_limits),
        ("count: 20", "count: 6"),
        ("plan:\n", "plan:\n  adaptive: false\n"),
    ];
    // Measured (the default: 0.5 °/s for 0.1 s).
    let measured = sim_cell(dir.path(), "measured.yaml", &base);
    let (fastest, threshold) = fastest_joint_during_exposures(&measured);
    eprintln!("settled by measurement: fastest joint during each exposure {fastest:.3?} °/s");
    assert!(threshold > 0.0);
    for (i, v) in fastest.iter().enumerate() {
        assert!(*v < threshold, "frame {i} exposed at {v:.3} °/s");
    }
    // The same cell without it (no settle at all) does capture the arm ringing: the check above
    // can fail.
    let mut unsettled_edits = base.to_vec();
    unsettled_edits.push((settle, "session: {settle_s: 0.0, settle_speed_deg_s: 0,"));
    let unsettled = sim_cell(dir.path(), "unsettled.yaml", &unsettled_edits);
    let (fastest, threshold) = fastest_joint_during_exposures(&unsettled);
    eprintln!("no settling: fastest joint during each exposure {fastest:.3?} °/s");
    assert_eq!(threshold, 0.0);
    assert!(
        fastest.iter().filter(|v| **v >= 0.5).count() >= 3,
        "{fastest:?}"
    );
}

/// The worst translation 1-sigma of the two unknowns of a solved run, mm.
fn sigma_mm(run: &cell_run::CellRun) -> f64 {
    let u = run
        .solved
        .as_ref()
        .unwrap()
        .calibration
        .uncertainty
        .as_ref()
        .expect("the final solve has a covariance");
    u.camera_mount
        .translation_mm
        .max(u.target_mount.translation_mm)
}

#[test]
fn the_adaptive_default_stops_at_the_target_never_before_the_minimum() {
    let dir = tempfile::tempdir().unwrap();
    // The shipped demo: a generated plan with known intrinsics is adaptive without saying so;
    // its target is the verdict's accuracy (1 mm), reached early, so the minimum decides.
    let demo = sim_cell(dir.path(), "demo.yaml", &[]);
    let done = util::run_cell(&demo, &dir.path().join("demo"));
    let summary = done.adaptive.clone().expect("adaptive by default");
    eprintln!(
        "{summary}\n{}",
        done.arm_time.expect("a planned run keeps its arm time")
    );
    assert!(summary.reached, "{summary}");
    assert_eq!(summary.target_uncertainty_mm, 1.0);
    assert_eq!(summary.in_session, 8, "stops at the default minimum of 8");
    assert!(sigma_mm(&done) <= 1.0);
    assert_eq!(
        done.arm_time
            .expect("a planned run keeps its arm time")
            .poses,
        8
    );
    assert_eq!(
        done.arm_time
            .expect("a planned run keeps its arm time")
            .full_plan_poses,
        20
    );
    // The arm-time figures are kept in the session for the report.
    let kept = std::fs::read_to_string(done.folder.root().join(cell_run::ArmTime::FILE)).unwrap();
    assert!(kept.contains("full_plan_estimate_s"), "{kept}");
    // The demo's instant moves measure no arm time, and claim no saving (issue #30).
    assert!(
        !done
            .arm_time
            .expect("a planned run keeps its arm time")
            .measured(),
        "{}",
        done.arm_time.expect("a planned run keeps its arm time")
    );
    // ... and the report says so.
    let page = handeye_report::session::write_run_report(&done).unwrap();
    let html = std::fs::read_to_string(page).unwrap();
    assert!(
        html.contains("Arm time: not measured") && !html.contains("data-key=\"arm_time.saved_s\""),
        "the report claims a saving for instant moves"
    );

    // A tighter target needs more poses than the minimum, and stops as soon as it is met.
    let target = 0.08;
    let tight = sim_cell(
        dir.path(),
        "tight.yaml",
        &[(
            "plan:\n",
            "plan:\n  target_uncertainty_mm: 0.08\n  min_poses: 6\n",
        )],
    );
    let done = util::run_cell(&tight, &dir.path().join("tight"));
    let summary = done.adaptive.clone().unwrap();
    eprintln!("{summary}");
    assert!(summary.reached, "{summary}");
    assert!(
        summary.in_session > 6 && summary.in_session < 20,
        "{summary}"
    );
    let reached = summary.solved_sigma_mm.unwrap();
    assert!(reached <= target, "{summary}");

    // A raised minimum holds even though the target is met earlier.
    let minimum = sim_cell(
        dir.path(),
        "minimum.yaml",
        &[("plan:\n", "plan:\n  min_poses: 12\n")],
    );
    let done = util::run_cell(&minimum, &dir.path().join("minimum"));
    let summary = done.adaptive.clone().unwrap();
    assert!(summary.reached, "{summary}");
    assert_eq!(summary.in_session, 12, "{summary}");

    // Out of reach: the maximum ends the run, and the summary says why.
    let unreachable = sim_cell(
        dir.path(),
        "max.yaml",
        &[(
            "plan:\n",
            "plan:\n  target_uncertainty_mm: 0.0001\n  max_poses: 9\n",
        )],
    );
    let done = util::run_cell(&unreachable, &dir.path().join("max"));
    let summary = done.adaptive.clone().unwrap();
    assert!(!summary.reached, "{summary}");
    assert_eq!(summary.in_session, 9);
    assert!(
        summary
            .to_string()
            .contains("stopped at plan.max_poses = 9"),
        "{summary}"
    );

    // Today's behaviour on request: every pose of the plan.
    let fixed = sim_cell(
        dir.path(),
        "fixed.yaml",
        &[("plan:\n", "plan:\n  adaptive: false\n")],
    );
    let done = util::run_cell(&fixed, &dir.path().join("fixed"));
    assert!(done.adaptive.is_none());
    assert_eq!(done.outcome.accepted.len(), 20);
}

/// The same through the real UR driver (ur_rtde via FFI) against the mock UR controller, whose
/// arm moves on trapezoidal profiles and rings down after each move. Needs `--features ur-rtde`.
#[cfg(feature = "ur-rtde")]
mod through_ur_rtde {
    use super::*;
    use std::net::IpAddr;
    use std::sync::mpsc;
    use std::time::Duration;

    use handeye_robot::kinematics::UrModel;
    use handeye_robot::sim::Ringing;
    use mocks::{MockUr, MockUrConfig};

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

    fn start_mock(address: &str) -> MockUr {
        MockUr::start(MockUrConfig {
            address: address.parse::<IpAddr>().unwrap(),
            model: UrModel::ur10e(),
            start_joints: Joints::from([0.0, -90f64, 90.0, -90.0, -90.0, 0.0].map(f64::to_radians)),
            trapezoidal_moves: true,
            ringing: Some(Ringing {
                amplitude_rad: 0.1f64.to_radians(),
                frequency_hz: 8.0,
                decay_s: 0.12,
            }),
            ..MockUrConfig::default()
        })
        .expect("mock starts")
    }

    /// `configs/sim-cell-ur-mock.yaml` at `host`, with faster limits and edits.
    fn config(dir: &Path, name: &str, host: &str, edits: &[(&str, &str)]) -> PathBuf {
        let host = format!("host: {host}");
        let mut all = vec![
            ("host: 127.0.0.1", host.as_str()),
            (
                "joint_speed_deg: 60, joint_acceleration_deg: 120",
                "joint_speed_deg: 90, joint_acceleration_deg: 180",
            ),
        ];
        all.extend_from_slice(edits);
        util::config_variant(dir, "sim-cell-ur-mock.yaml", name, &all)
    }

    /// A camera that reads the mock's joint speeds right before and right after each exposure
    /// (the simulated camera exposes at once when the time asked for has come).
    struct ProbingCamera<P: Fn() -> Joints + Send> {
        inner: Box<dyn Camera>,
        probe: P,
        fastest: Arc<Mutex<Vec<f64>>>,
    }

    impl<P: Fn() -> Joints + Send> Camera for ProbingCamera<P> {
        fn grab(&mut self, not_before: Instant) -> Result<Frame, CameraError> {
            let now = Instant::now();
            if not_before > now {
                std::thread::sleep(not_before - now);
            }
            let top = |q: Joints| q.iter().fold(0.0f64, |m, v| m.max(v.abs())).to_degrees();
            let before = top((self.probe)());
            let frame = self.inner.grab(not_before)?;
            let after = top((self.probe)());
            self.fastest.lock().unwrap().push(before.max(after));
            Ok(frame)
        }
        fn model(&self) -> &CameraModel {
            self.inner.model()
        }
    }

    /// Runs a fixed 5-pose plan through ur_rtde; the fastest joint speed around each exposure
    /// (°/s) and the settle threshold (°/s, 0 when off).
    fn fastest_around_exposures(mock: &MockUr, config: &Path) -> (Vec<f64>, f64) {
        let mut prepared = cell::prepare(config).unwrap();
        let mut hardware = prepared.open_hardware().expect("connects to the mock");
        let start = hardware.robot.joint_positions().unwrap();
        let plan = prepared.recheck_from(start).expect("plan valid");
        let dir = tempfile::tempdir().unwrap();
        let folder = SessionFolder::create(&dir.path().join("s")).unwrap();
        folder.write_manifest(&prepared.manifest(0, &plan)).unwrap();
        let fastest = Arc::new(Mutex::new(Vec::new()));
        let mut camera = ProbingCamera {
            inner: hardware.cameras.remove(0),
            probe: mock.speed_probe(),
            fastest: fastest.clone(),
        };
        let setup = prepared.session_setup(folder.clone(), plan, Arc::new(AtomicBool::new(false)));
        let threshold = setup
            .settle_by_speed
            .map_or(0.0, |s| s.max_joint_speed.to_degrees());
        let outcome = handeye_session::run_session(
            setup,
            hardware.robot.as_mut(),
            &mut [&mut camera],
            &mut |_| {},
        )
        .unwrap();
        assert_eq!(outcome.accepted.len(), 5, "{:?}", outcome.skipped);
        let fastest = fastest.lock().unwrap().clone();
        (fastest, threshold)
    }

    #[test]
    fn settling_by_measured_actual_qd_never_captures_a_moving_arm() {
        with_timeout(Duration::from_secs(240), || {
            let mock = start_mock("127.0.0.161");
            let dir = tempfile::tempdir().unwrap();
            let fixed = [
                ("count: 20", "count: 5"),
                ("plan:\n", "plan:\n  adaptive: false\n"),
            ];
            let measured = config(dir.path(), "measured.yaml", "127.0.0.161", &fixed);
            let (fastest, threshold) = fastest_around_exposures(&mock, &measured);
            eprintln!("ur_rtde, settled by actual_qd: fastest joint around each exposure {fastest:.3?} °/s");
            assert!(threshold > 0.0);
            assert!(fastest.iter().all(|v| *v < threshold), "{fastest:?}");

            let mut edits = fixed.to_vec();
            edits.push((
                "session: {settle_s: 0.0,",
                "session: {settle_s: 0.0, settle_speed_deg_s: 0,",
            ));
            let unsettled = config(dir.path(), "unsettled.yaml", "127.0.0.161", &edits);
            let (fastest, _) = fastest_around_exposures(&mock, &unsettled);
            eprintln!("ur_rtde, no settling: fastest joint around each exposure {fastest:.3?} °/s");
            assert!(
                fastest.iter().filter(|v| **v >= 0.5).count() >= 2,
                "{fastest:?}"
            );
            mock.shutdown();
        });
    }

    #[test]
    fn the_adaptive_default_stops_at_the_target_through_ur_rtde() {
        with_timeout(Duration::from_secs(300), || {
            let mock = start_mock("127.0.0.162");
            let dir = tempfile::tempdir().unwrap();
            let cell = config(dir.path(), "cell.yaml", "127.0.0.162", &[]);
            let done = util::run_cell(&cell, &dir.path().join("s"));
            let summary = done.adaptive.clone().expect("adaptive by default");
            eprintln!(
                "{summary}\n{}",
                done.arm_time.expect("a planned run keeps its arm time")
            );
            assert!(summary.reached, "{summary}");
            assert!(
                summary.in_session >= 8 && summary.in_session < 20,
                "{summary}"
            );
            assert!(sigma_mm(&done) <= 1.0);
            // Every pose the session holds was a move of the mock, and the arm time was spent.
            assert_eq!(mock.moves_completed(), summary.in_session);
            assert!(
                done.arm_time
                    .expect("a planned run keeps its arm time")
                    .moving_s
                    > 0.5
                    && done
                        .arm_time
                        .expect("a planned run keeps its arm time")
                        .saved_s()
                        > 0.0
            );
            mock.shutdown();
        });
    }
}

/// Issue #30: the demo cell's instant moves (robot.move_duration_s: 0) measure only the loop's
/// own milliseconds; the run says arm time was not measured instead of "100 % saved".
#[test]
fn the_demo_cells_instant_moves_say_arm_time_was_not_measured() {
    let dir = tempfile::tempdir().unwrap();
    let config = util::sim_cell(dir.path(), 8);
    let done = util::run_cell(&config, &dir.path().join("session"));
    let arm_time = done.arm_time.expect("a planned run keeps its arm time");
    assert!(!arm_time.measured(), "{arm_time}");
    let text = arm_time.to_string();
    assert!(
        text.contains("not measured") && !text.contains("saved"),
        "{text}"
    );

    // Moves that take time are measured, and the report shows the saving.
    let timed = util::config_variant(
        dir.path(),
        "sim-cell.yaml",
        "timed.yaml",
        &[
            ("count: 20", "count: 8"),
            ("move_duration_s: 0.0", "move_duration_s: 0.05"),
        ],
    );
    let done = util::run_cell(&timed, &dir.path().join("timed"));
    let arm_time = done.arm_time.expect("a planned run keeps its arm time");
    assert!(arm_time.measured() && arm_time.moving_s > 0.3, "{arm_time}");
    let page = handeye_report::session::write_run_report(&done).unwrap();
    let html = std::fs::read_to_string(page).unwrap();
    assert!(
        html.contains("data-key=\"arm_time.saved_s\""),
        "no arm time in the report"
    );
}
