//! Unit tests of the session driver (`session::run_session`) on strict scripted fakes
//! (`tests/util/fakes.rs`): every robot call and every grab is expected in order with its reply,
//! nothing sleeps (settle 0), and frames are rendered once from known board poses. Each test
//! checks what the driver asked of the hardware, what it returned, and what it kept on disk.
//!
//! The cell: eye-in-hand, a 6x6 AprilGrid, a 640x480 pinhole camera. For each plan pose the board
//! pose `T_camera_target` is chosen first (board in front of the camera, tilted a little), and the
//! flange pose the fake robot reports follows from the true mounts:
//! `T_base_flange = T_base_target * inv(T_camera_target) * inv(T_flange_camera)`.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, OnceLock};
use std::time::Duration;

use handeye_camera::render::{render, RenderOptions};
use handeye_camera::CameraError;
use handeye_core::camera_model::{CameraModel, Distortion};
use handeye_core::geometry::{pose_from_rotvec, Pose};
use handeye_core::setup::{CellTransforms, Setup};
use handeye_records::dataset::Dataset;
use handeye_records::{SessionError, SessionFolder};
use handeye_robot::{Joints, MotionLimits, RobotError};
use handeye_session::{run_session, SessionCamera, SessionEvent, SessionOutcome, SessionSetup};
use handeye_vision::{Board, DetectorOptions};
use image::{GrayImage, Luma};
use nalgebra::{Rotation3, Translation3, UnitQuaternion, Vector3};
use rand::SeedableRng;

use crate::util;
use crate::util::fakes;

use fakes::{Expect, Grab, ScriptedCamera, ScriptedRobot};
use util::{pose_error_mm_deg, repo};

/// Plan poses of the test cell.
const POSES: usize = 4;

fn camera_model() -> CameraModel {
    CameraModel {
        width: 640,
        height: 480,
        fx: 520.0,
        fy: 520.0,
        cx: 319.5,
        cy: 239.5,
        distortion: Distortion::None,
    }
}

fn board() -> Board {
    Board::load(&repo().join("configs/targets/aprilgrid-6x6.yaml")).unwrap()
}

/// The true mounts: `T_flange_camera` and `T_base_target`.
fn truth() -> CellTransforms {
    CellTransforms {
        setup: Setup::EyeInHand,
        camera_mount: pose_from_rotvec(
            Vector3::new(0.03, -0.07, 0.04),
            Vector3::new(0.02, -0.01, 1.55),
        ),
        target_mount: pose_from_rotvec(Vector3::new(0.5, -0.15, 0.0), Vector3::new(0.0, 0.0, 0.3)),
    }
}

/// The board pose of plan pose `i`: its centre 0.5-0.6 m in front of the camera, facing it
/// (target z towards the camera), tilted by up to ~15°.
fn camera_from_target(i: usize) -> Pose {
    let board = board();
    let extent = board.extent();
    let centre = Vector3::new(
        (extent.min.x + extent.max.x) / 2.0,
        (extent.min.y + extent.max.y) / 2.0,
        0.0,
    );
    let tilts = [
        Vector3::new(0.0, 0.0, 0.0),
        Vector3::new(0.2, -0.1, 0.3),
        Vector3::new(-0.15, 0.2, -0.4),
        Vector3::new(0.1, 0.25, 1.2),
    ];
    let facing = UnitQuaternion::from_rotation_matrix(&Rotation3::from_axis_angle(
        &Vector3::x_axis(),
        std::f64::consts::PI,
    ));
    let rotation = facing * UnitQuaternion::from_scaled_axis(tilts[i % tilts.len()]);
    let where_centre = Vector3::new(0.01 * i as f64, -0.01 * i as f64, 0.5 + 0.03 * i as f64);
    Pose::from_parts(
        Translation3::from(where_centre - rotation * centre),
        rotation,
    )
}

/// The flange pose the robot reports at plan pose `i` (consistent with the true mounts).
fn base_from_flange(i: usize) -> Pose {
    let t = truth();
    t.target_mount * camera_from_target(i).inverse() * t.camera_mount.inverse()
}

/// The joints of plan pose `i` (the fakes only compare them).
fn joints(i: usize) -> Joints {
    let k = i as f64;
    Joints::from([
        0.1 * k,
        -1.5 + 0.05 * k,
        1.5,
        -1.5,
        -1.5 - 0.02 * k,
        0.3 * k,
    ])
}

/// The frame of plan pose `i`, rendered once per test binary.
fn frame(i: usize) -> GrayImage {
    static FRAMES: OnceLock<Vec<GrayImage>> = OnceLock::new();
    FRAMES.get_or_init(|| {
        let board = board();
        let camera = camera_model();
        let options = RenderOptions {
            supersample: 2,
            noise_sigma: 1.0,
            ..RenderOptions::default()
        };
        let mut rng = rand::rngs::StdRng::seed_from_u64(5);
        (0..POSES)
            .map(|i| render(&board, &camera, &camera_from_target(i), &options, &mut rng))
            .collect()
    })[i]
        .clone()
}

/// A frame without the board (a flat wall).
fn empty_frame() -> GrayImage {
    let model = camera_model();
    GrayImage::from_pixel(model.width, model.height, Luma([120]))
}

fn session_setup(folder: SessionFolder, stop: Arc<AtomicBool>) -> SessionSetup {
    SessionSetup {
        resume_folder: folder.root().to_path_buf(),
        cameras: vec![SessionCamera {
            name: "camera".into(),
            folder,
            setup: Setup::EyeInHand,
            board: board().into(),
            estimate_intrinsics: false,
        }],
        named_cameras: false,
        plan: (0..POSES)
            .map(|i| (base_from_flange(i), joints(i)))
            .collect(),
        limits: MotionLimits::default(),
        settle: Duration::ZERO,
        settle_by_speed: None,
        reorder: false,
        max_reprojection_rms_px: 1.0,
        // One detector thread: with more, the AprilTag C worker pool races now and then (see
        // tests/it/fuzz.rs, `crash_detector_worker_pool_race`); the driver does not care.
        detector: DetectorOptions {
            threads: 1,
            ..DetectorOptions::default()
        },
        stop,
        move_check: None,
    }
}

/// The robot calls of one complete visit of plan pose `i`: move, then read the flange pose.
fn visit(i: usize) -> [Expect; 2] {
    [
        Expect::move_to(joints(i)),
        Expect::pose(base_from_flange(i)),
    ]
}

struct Run {
    result: Result<SessionOutcome, SessionError>,
    events: Vec<SessionEvent>,
    folder: SessionFolder,
    _dir: tempfile::TempDir,
}

/// Runs the driver on a fresh session folder with the scripted robot and camera; both fakes are
/// dropped (and so checked for calls not made) before this returns.
fn run(robot: Vec<Expect>, grabs: Vec<Grab>) -> Run {
    let dir = tempfile::tempdir().unwrap();
    let folder = SessionFolder::create(&dir.path().join("session")).unwrap();
    let mut robot = ScriptedRobot::new(robot).with_limits(MotionLimits::default());
    let mut camera = ScriptedCamera::new(camera_model(), grabs);
    let mut events = Vec::new();
    let result = run_session(
        session_setup(folder.clone(), Arc::new(AtomicBool::new(false))),
        &mut robot,
        &mut [&mut camera],
        &mut |e| events.push(e),
    );
    drop(robot);
    drop(camera);
    Run {
        result,
        events,
        folder,
        _dir: dir,
    }
}

/// The samples the driver wrote, by id.
fn samples(folder: &SessionFolder) -> Vec<(String, Pose, Pose)> {
    let dataset = Dataset::load(&folder.samples_path()).unwrap();
    assert_eq!(dataset.setup, Setup::EyeInHand);
    dataset
        .pairs
        .into_iter()
        .map(|p| (p.id.unwrap(), p.base_from_flange, p.camera_from_target))
        .collect()
}

/// Checks that sample `id` of plan pose `i` holds the reported flange pose exactly and a board
/// pose within 2 mm and 0.2° of the rendered one.
fn assert_sample(sample: &(String, Pose, Pose), i: usize) {
    let (id, flange, board) = sample;
    assert_eq!(id, &format!("pose-{i:03}"));
    let (mm, deg) = pose_error_mm_deg(flange, &base_from_flange(i));
    assert!(
        mm < 1e-6 && deg < 1e-6,
        "{id}: T_base_flange off by {mm} mm, {deg}°"
    );
    let (mm, deg) = pose_error_mm_deg(board, &camera_from_target(i));
    assert!(
        mm < 2.0 && deg < 0.2,
        "{id}: T_camera_target off by {mm:.3} mm, {deg:.3}°"
    );
}

fn recorded(events: &[SessionEvent]) -> Vec<(usize, Option<String>, bool)> {
    events
        .iter()
        .filter_map(|e| match e {
            SessionEvent::Recorded {
                plan_index,
                rejected,
                will_retry,
                ..
            } => Some((*plan_index, rejected.clone(), *will_retry)),
            SessionEvent::Moving { .. } | SessionEvent::CameraLost(_) => None,
        })
        .collect()
}

fn moving(events: &[SessionEvent]) -> Vec<usize> {
    events
        .iter()
        .filter_map(|e| match e {
            SessionEvent::Moving { plan_index, .. } => Some(*plan_index),
            SessionEvent::Recorded { .. } | SessionEvent::CameraLost(_) => None,
        })
        .collect()
}

#[test]
fn scripted_fakes_render_boards_where_the_truth_says() {
    // The test cell is consistent: the flange poses and mounts predict the rendered board poses.
    let t = truth();
    for i in 0..POSES {
        let (mm, deg) = pose_error_mm_deg(
            &t.camera_from_target(&base_from_flange(i)),
            &camera_from_target(i),
        );
        assert!(mm < 1e-9 && deg < 1e-9, "pose {i}: {mm} mm, {deg}°");
    }
}

#[test]
fn a_normal_visit_sequence_records_every_sample() {
    let mut script = vec![Expect::SetInterrupt];
    script.extend((0..POSES).flat_map(visit));
    let r = run(script, (0..POSES).map(|i| Grab::Frame(frame(i))).collect());
    let outcome = r.result.unwrap();
    assert_eq!(outcome.accepted, vec![0, 1, 2, 3]);
    assert!(outcome.skipped.is_empty(), "{:?}", outcome.skipped);
    assert_eq!(outcome.visited_now, POSES);

    let samples = samples(&r.folder);
    assert_eq!(samples.len(), POSES);
    for (i, sample) in samples.iter().enumerate() {
        assert_sample(sample, i);
    }
    // One record and one frame per pose, each accepted with its RMS.
    let visits = r.folder.read_visits().unwrap();
    assert_eq!(visits.len(), POSES);
    for (i, v) in visits.iter().enumerate() {
        assert_eq!(v.plan_index, i);
        assert!(v.rejected.is_none(), "pose {i}: {:?}", v.rejected);
        assert_eq!(v.tags, 36, "pose {i}: every tag of the 6x6 grid used");
        assert!(v.reprojection_rms_px.unwrap() < 0.5);
        assert!(r.folder.root().join(&v.frame).is_file());
    }
    assert_eq!(moving(&r.events), vec![0, 1, 2, 3]);
    assert_eq!(
        recorded(&r.events),
        (0..POSES).map(|i| (i, None, false)).collect::<Vec<_>>()
    );
}

#[test]
fn a_protective_stop_mid_plan_stops_cleanly_and_keeps_the_samples_so_far() {
    let mut script = vec![Expect::SetInterrupt];
    script.extend((0..2).flat_map(visit));
    script.push(Expect::MoveJoints(
        joints(2),
        Err(RobotError::ProtectiveStop),
    ));
    // The driver stops the arm and touches nothing else.
    script.push(Expect::stop());
    let r = run(script, (0..2).map(|i| Grab::Frame(frame(i))).collect());
    match r.result {
        Err(SessionError::Robot {
            plan_index: 2,
            recorded: 2,
            ref folder,
            source: RobotError::ProtectiveStop,
        }) => assert_eq!(folder, r.folder.root()),
        ref other => panic!("expected a robot stop at pose 2 with 2 recorded, got {other:?}"),
    }
    let message = r.result.unwrap_err().to_string();
    assert!(
        message.contains("plan pose 2") && message.contains("--resume"),
        "{message}"
    );
    let samples = samples(&r.folder);
    assert_eq!(samples.len(), 2);
    assert_sample(&samples[0], 0);
    assert_sample(&samples[1], 1);
    let visits = r.folder.read_visits().unwrap();
    assert_eq!(
        visits.iter().map(|v| v.plan_index).collect::<Vec<_>>(),
        vec![0, 1]
    );
    assert!(!r.folder.root().join("poses/002.yaml").exists());
}

#[test]
fn a_camera_error_stops_the_arm_and_keeps_the_samples_so_far() {
    let mut script = vec![Expect::SetInterrupt];
    script.extend(visit(0));
    // The move to pose 1 arrives, the grab fails: no flange pose is read, the arm is stopped.
    script.push(Expect::move_to(joints(1)));
    script.push(Expect::stop());
    let r = run(
        script,
        vec![
            Grab::Frame(frame(0)),
            Grab::Fail(CameraError::Timeout(Duration::from_secs(2))),
        ],
    );
    match &r.result {
        Err(SessionError::Camera {
            plan_index: 1,
            recorded: 1,
            source: CameraError::Timeout(t),
            ..
        }) => assert_eq!(*t, Duration::from_secs(2)),
        other => panic!("expected a camera failure at pose 1 with 1 recorded, got {other:?}"),
    }
    let samples = samples(&r.folder);
    assert_eq!(samples.len(), 1);
    assert_sample(&samples[0], 0);
    assert_eq!(r.folder.read_visits().unwrap().len(), 1);
}

#[test]
fn a_pose_where_the_board_is_not_seen_is_retried_once_then_rejected_with_its_reason() {
    let mut script = vec![Expect::SetInterrupt];
    script.extend((0..POSES).flat_map(visit));
    // Second pass: only pose 1 again.
    script.extend(visit(1));
    let grabs = vec![
        Grab::Frame(frame(0)),
        Grab::Frame(empty_frame()),
        Grab::Frame(frame(2)),
        Grab::Frame(frame(3)),
        Grab::Frame(empty_frame()),
    ];
    let r = run(script, grabs);
    let outcome = r.result.unwrap();
    assert_eq!(outcome.accepted, vec![0, 2, 3]);
    assert_eq!(outcome.visited_now, POSES + 1);
    assert_eq!(outcome.skipped.len(), 1);
    let (index, reason) = &outcome.skipped[0];
    assert_eq!(*index, 1);
    assert!(reason.contains("no tag of the board"), "{reason}");

    // The record of pose 1 says why; it has no board pose and is not a sample.
    let visits = r.folder.read_visits().unwrap();
    let pose1 = visits.iter().find(|v| v.plan_index == 1).unwrap();
    assert_eq!(pose1.rejected.as_deref(), Some(reason.as_str()));
    assert!(pose1.camera_from_target.is_none());
    assert_eq!(pose1.tags, 0);
    let ids: Vec<String> = samples(&r.folder).into_iter().map(|s| s.0).collect();
    assert_eq!(ids, vec!["pose-000", "pose-002", "pose-003"]);

    // Events: pose 1 rejected with a retry, then rejected for good after the others.
    assert_eq!(moving(&r.events), vec![0, 1, 2, 3, 1]);
    let rec = recorded(&r.events);
    assert_eq!(rec.len(), POSES + 1);
    assert_eq!(rec[1], (1, Some(reason.clone()), true));
    assert_eq!(rec[4], (1, Some(reason.clone()), false));
}

#[test]
fn a_board_missed_once_is_accepted_on_the_retry() {
    let mut script = vec![Expect::SetInterrupt];
    script.extend((0..POSES).flat_map(visit));
    script.extend(visit(2));
    let grabs = vec![
        Grab::Frame(frame(0)),
        Grab::Frame(frame(1)),
        Grab::Frame(empty_frame()),
        Grab::Frame(frame(3)),
        Grab::Frame(frame(2)),
    ];
    let r = run(script, grabs);
    let outcome = r.result.unwrap();
    assert_eq!(outcome.accepted, vec![0, 1, 2, 3]);
    assert!(outcome.skipped.is_empty());
    let samples = samples(&r.folder);
    assert_eq!(samples.len(), POSES);
    for (i, sample) in samples.iter().enumerate() {
        assert_sample(sample, i);
    }
}

#[test]
fn an_interrupted_move_ends_the_run_as_interrupted_and_keeps_the_samples() {
    let mut script = vec![Expect::SetInterrupt];
    script.extend(visit(0));
    script.push(Expect::MoveJoints(joints(1), Err(RobotError::Interrupted)));
    script.push(Expect::stop());
    let r = run(script, vec![Grab::Frame(frame(0))]);
    match &r.result {
        Err(SessionError::Interrupted {
            plan_index: 1,
            recorded: 1,
            ..
        }) => {}
        other => panic!("expected an interruption at pose 1 with 1 recorded, got {other:?}"),
    }
    assert_eq!(samples(&r.folder).len(), 1);
}

#[test]
fn a_stop_request_before_the_next_pose_stops_without_moving() {
    // The stop flag is set while the arm is at pose 0 (as Ctrl-C would): the driver reads the
    // flange pose, then stops the arm instead of moving to pose 1.
    let dir = tempfile::tempdir().unwrap();
    let folder = SessionFolder::create(&dir.path().join("session")).unwrap();
    let stop = Arc::new(AtomicBool::new(false));
    let mut robot = ScriptedRobot::new(vec![
        Expect::SetInterrupt,
        Expect::move_to(joints(0)),
        Expect::pose(base_from_flange(0)),
        Expect::stop(),
    ]);
    let mut camera = ScriptedCamera::new(camera_model(), vec![Grab::Frame(frame(0))]);
    let flag = stop.clone();
    let result = run_session(
        session_setup(folder.clone(), stop.clone()),
        &mut robot,
        &mut [&mut camera],
        &mut |e| {
            if let SessionEvent::Moving { plan_index: 0, .. } = e {
                flag.store(true, Ordering::SeqCst);
            }
        },
    );
    assert!(
        robot
            .interrupt_flag()
            .is_some_and(|f| Arc::ptr_eq(&f, &stop)),
        "the driver hands the run's stop flag to the robot"
    );
    drop(robot);
    drop(camera);
    match result {
        Err(SessionError::Interrupted {
            plan_index: 1,
            recorded: 1,
            ..
        }) => {}
        other => panic!("expected an interruption before pose 1 with 1 recorded, got {other:?}"),
    }
    assert_eq!(samples(&folder).len(), 1);
}

#[test]
fn a_resumed_run_visits_only_the_poses_without_a_sample() {
    // First run: protective stop on the way to pose 2.
    let dir = tempfile::tempdir().unwrap();
    let root = dir.path().join("session");
    let folder = SessionFolder::create(&root).unwrap();
    let mut script = vec![Expect::SetInterrupt];
    script.extend((0..2).flat_map(visit));
    script.push(Expect::MoveJoints(
        joints(2),
        Err(RobotError::ProtectiveStop),
    ));
    script.push(Expect::stop());
    let mut robot = ScriptedRobot::new(script);
    let mut camera = ScriptedCamera::new(
        camera_model(),
        vec![Grab::Frame(frame(0)), Grab::Frame(frame(1))],
    );
    let first = run_session(
        session_setup(folder.clone(), Arc::new(AtomicBool::new(false))),
        &mut robot,
        &mut [&mut camera],
        &mut |_| {},
    );
    drop(robot);
    drop(camera);
    assert!(
        matches!(first, Err(SessionError::Robot { .. })),
        "{first:?}"
    );

    // Resume: poses 2 and 3 only, in order.
    let mut script = vec![Expect::SetInterrupt];
    script.extend((2..POSES).flat_map(visit));
    let mut robot = ScriptedRobot::new(script);
    let mut camera = ScriptedCamera::new(
        camera_model(),
        vec![Grab::Frame(frame(2)), Grab::Frame(frame(3))],
    );
    let outcome = run_session(
        session_setup(folder.clone(), Arc::new(AtomicBool::new(false))),
        &mut robot,
        &mut [&mut camera],
        &mut |_| {},
    )
    .unwrap();
    drop(robot);
    drop(camera);
    assert_eq!(outcome.accepted, vec![0, 1, 2, 3]);
    assert_eq!(outcome.visited_now, 2);
    let samples = samples(&folder);
    assert_eq!(samples.len(), POSES);
    for (i, sample) in samples.iter().enumerate() {
        assert_sample(sample, i);
    }
}

#[test]
fn a_move_that_would_leave_the_workspace_is_not_sent() {
    use handeye_plan::check::MoveCheck;
    use handeye_robot::kinematics::UrModel;
    use handeye_robot::WorkspaceBox;

    // Every move is checked from the joints the arm reports before it is sent: with a workspace
    // box far from every pose the first move is refused, the arm is stopped, nothing is recorded.
    let dir = tempfile::tempdir().unwrap();
    let folder = SessionFolder::create(&dir.path().join("session")).unwrap();
    let mut setup = session_setup(folder.clone(), Arc::new(AtomicBool::new(false)));
    setup.move_check = Some(MoveCheck::with_model(
        UrModel::ur5e(),
        WorkspaceBox {
            min: Vector3::new(5.0, 5.0, 5.0),
            max: Vector3::new(6.0, 6.0, 6.0),
        },
    ));
    let mut robot = ScriptedRobot::new(vec![
        Expect::SetInterrupt,
        Expect::Joints(Ok(joints(0))),
        Expect::stop(),
    ]);
    let mut camera = ScriptedCamera::new(camera_model(), Vec::new());
    let result = run_session(setup, &mut robot, &mut [&mut camera], &mut |_| {});
    drop(robot);
    drop(camera);
    match result {
        Err(SessionError::UnsafeMove {
            plan_index: 0,
            recorded: 0,
            problem,
            ..
        }) => assert!(problem.contains("leaves the workspace box"), "{problem}"),
        other => panic!("expected the first move refused, got {other:?}"),
    }
    assert!(nothing_recorded(&folder));
}

/// #40: a retry whose path from where the arm stands would leave the workspace box is not
/// sent; the pose keeps its first (rejected) record, is named as skipped with the reason, and
/// the run ends with the samples it has instead of an error that asks for a resume.
#[test]
fn a_retry_that_cannot_be_reached_is_skipped_and_the_run_ends_with_its_samples() {
    use handeye_plan::check::MoveCheck;
    use handeye_robot::kinematics::UrModel;
    use handeye_robot::WorkspaceBox;

    let arm = UrModel::ur5e();
    // The box holds every flange position on the plan's own joint paths (0 → 1 → 2 → 3), with
    // 5 cm to spare; the arm then reports itself swung 120° about its base, from where the way
    // back to pose 1 sweeps out of it.
    let (mut min, mut max) = (
        Vector3::repeat(f64::INFINITY),
        Vector3::repeat(f64::NEG_INFINITY),
    );
    for i in 0..POSES - 1 {
        for step in 0..=20 {
            let f = step as f64 / 20.0;
            let q = Joints::from_fn(6, |j| joints(i)[j] * (1.0 - f) + joints(i + 1)[j] * f);
            let p = arm.forward(&q).translation.vector;
            min = min.inf(&p);
            max = max.sup(&p);
        }
    }
    let margin = Vector3::repeat(0.05);
    let workspace = WorkspaceBox {
        min: min - margin,
        max: max + margin,
    };
    let mut swung = joints(3);
    swung[0] += 120f64.to_radians();
    let dir = tempfile::tempdir().unwrap();
    let folder = SessionFolder::create(&dir.path().join("session")).unwrap();
    let mut setup = session_setup(folder.clone(), Arc::new(AtomicBool::new(false)));
    setup.move_check = Some(MoveCheck::with_model(arm, workspace));
    let mut script = vec![Expect::SetInterrupt];
    for i in 0..POSES {
        let from = if i == 0 { joints(0) } else { joints(i - 1) };
        script.push(Expect::Joints(Ok(from)));
        script.extend(visit(i));
    }
    // The second pass: the arm says where it stands, and the retry of pose 1 is not sent.
    script.push(Expect::Joints(Ok(swung)));
    let mut robot = ScriptedRobot::new(script).with_limits(MotionLimits::default());
    let grabs = vec![
        Grab::Frame(frame(0)),
        Grab::Frame(empty_frame()),
        Grab::Frame(frame(2)),
        Grab::Frame(frame(3)),
    ];
    let mut camera = ScriptedCamera::new(camera_model(), grabs);
    let result = run_session(setup, &mut robot, &mut [&mut camera], &mut |_| {});
    drop(robot);
    drop(camera);
    let outcome = result.expect("the run ends with its samples");
    assert_eq!(outcome.accepted, vec![0, 2, 3]);
    assert_eq!(outcome.skipped.len(), 1, "{:?}", outcome.skipped);
    let (index, reason) = &outcome.skipped[0];
    assert_eq!(*index, 1);
    assert!(
        reason.starts_with("not visited again") && reason.contains("workspace box"),
        "{reason}"
    );
    // Pose 1 keeps its one (rejected) record.
    let visits = folder.read_visits().unwrap();
    assert_eq!(visits.iter().filter(|v| v.plan_index == 1).count(), 1);
}

fn nothing_recorded(folder: &SessionFolder) -> bool {
    folder.read_visits().unwrap().is_empty() && !folder.samples_path().exists()
}

// The fakes themselves are strict: a wrong argument, a call out of order, or calls not made
// fail the test.

#[test]
#[should_panic(expected = "ScriptedRobot: call #1 was move_joints")]
fn the_scripted_robot_refuses_a_move_to_other_joints() {
    use handeye_robot::Robot;
    let mut robot = ScriptedRobot::new(vec![Expect::move_to(joints(1))]);
    let _ = robot.move_joints(&joints(2), &MotionLimits::default());
}

#[test]
#[should_panic(expected = "ScriptedRobot: call #2 was stop(), expected base_from_flange()")]
fn the_scripted_robot_refuses_calls_out_of_order() {
    use handeye_robot::Robot;
    let mut robot = ScriptedRobot::new(vec![
        Expect::move_to(joints(0)),
        Expect::pose(base_from_flange(0)),
        Expect::stop(),
    ]);
    let _ = robot.move_joints(&joints(0), &MotionLimits::default());
    let _ = robot.stop();
}

#[test]
#[should_panic(expected = "1 expected calls not made")]
fn the_scripted_robot_fails_when_an_expected_call_is_not_made() {
    use handeye_robot::Robot;
    let mut robot = ScriptedRobot::new(vec![Expect::move_to(joints(0)), Expect::stop()]);
    let _ = robot.move_joints(&joints(0), &MotionLimits::default());
    drop(robot);
}

#[test]
#[should_panic(expected = "ScriptedCamera: unexpected grab #2")]
fn the_scripted_camera_refuses_an_unexpected_grab() {
    use handeye_camera::Camera;
    let mut camera = ScriptedCamera::new(camera_model(), vec![Grab::Frame(empty_frame())]);
    let _ = camera.grab(std::time::Instant::now());
    let _ = camera.grab(std::time::Instant::now());
}

/// A plan that grows one pose at a time (adaptive, hand-guided) on the run's one pose loop: a
/// pose no camera accepts is dropped and its index given to the next pose, whose first miss
/// then ends it (the dropped pose's rejected record counts as its first try, as on a resume);
/// the rejected records are kept aside, and the manifest holds only the pose that was kept.
#[test]
fn a_growing_plan_gives_a_dropped_poses_index_to_the_next_which_gets_one_try() {
    use handeye_core::setup::PosePair;
    use handeye_session::{run_adaptive_session, PlanSource};
    struct Scripted(Vec<usize>);
    impl PlanSource for Scripted {
        fn next_pose(&mut self, _: &[Vec<PosePair>]) -> Option<(Pose, Joints)> {
            (!self.0.is_empty()).then(|| {
                let i = self.0.remove(0);
                (base_from_flange(i), joints(i))
            })
        }
        fn visited(&mut self, _: &[Pose]) {}
    }
    let dir = tempfile::tempdir().unwrap();
    let folder = SessionFolder::create(&dir.path().join("session")).unwrap();
    // Pose 0 missed twice (a retry), pose 1 missed once at the same index, pose 2 seen there.
    let mut script = vec![Expect::SetInterrupt];
    script.extend(visit(0));
    script.extend(visit(0));
    script.push(Expect::SetInterrupt);
    script.extend(visit(1));
    script.push(Expect::SetInterrupt);
    script.extend(visit(2));
    let mut robot = ScriptedRobot::new(script).with_limits(MotionLimits::default());
    let grabs = vec![
        Grab::Frame(empty_frame()),
        Grab::Frame(empty_frame()),
        Grab::Frame(empty_frame()),
        Grab::Frame(frame(2)),
    ];
    let mut camera = ScriptedCamera::new(camera_model(), grabs);
    let mut events = Vec::new();
    let outcome = run_adaptive_session(
        session_setup(folder.clone(), Arc::new(AtomicBool::new(false))),
        dir.path().join("cell.yaml"),
        &mut Scripted(vec![0, 1, 2]),
        &mut robot,
        &mut [&mut camera],
        &mut |e| events.push(e),
    )
    .unwrap();
    drop(robot);
    drop(camera);
    assert_eq!(outcome.accepted, vec![0]);
    assert_eq!(moving(&events), vec![0, 0, 0, 0]);
    let retries: Vec<(bool, bool)> = recorded(&events)
        .into_iter()
        .map(|(_, rejected, will_retry)| (rejected.is_some(), will_retry))
        .collect();
    assert_eq!(
        retries,
        vec![(true, true), (true, false), (true, false), (false, false)]
    );
    let manifest = folder.read_manifest().unwrap();
    assert_eq!(manifest.plan.len(), 1);
    let (mm, _) = pose_error_mm_deg(&manifest.plan[0].base_from_flange, &base_from_flange(2));
    assert!(mm < 1e-9, "the manifest's pose is {mm} mm from pose 2's");
    assert_eq!(folder.read_rejected_visits().unwrap().len(), 2);
    let kept = samples(&folder);
    assert_eq!(kept.len(), 1);
    let (mm, _) = pose_error_mm_deg(&kept[0].1, &base_from_flange(2));
    assert!(
        mm < 1e-9,
        "the sample's robot pose is {mm} mm from pose 2's"
    );
}
