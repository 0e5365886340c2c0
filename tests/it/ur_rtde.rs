//! The ur_rtde FFI backend against the mock UR controller (`mocks`), over loopback. Needs the
//! `ur-rtde` feature (and ur_rtde built by scripts/install-ur-rtde.sh). Each test runs under a
//! deadline so a broken mock or driver fails instead of hanging; each mock has its own loopback
//! address because ur_rtde's ports are fixed.
#![cfg(feature = "ur-rtde")]

use crate::util::within;
use std::f64::consts::PI;
use std::net::{IpAddr, Ipv4Addr};
use std::time::{Duration, Instant};

use handeye_core::geometry::{pose_from_rotvec, translation_distance, Pose};
use handeye_robot::ur::{UrRobot, UrRobotConfig};
use handeye_robot::{MotionLimits, Robot, RobotError, RobotStatus, WorkspaceBox};
use mocks::{MockFaults, MockUr, MockUrConfig};
use nalgebra::{UnitQuaternion, Vector3};

fn addr(last: u8) -> IpAddr {
    IpAddr::V4(Ipv4Addr::new(127, 0, 0, last))
}

fn start_mock(last: u8, tweak: impl FnOnce(&mut MockUrConfig)) -> MockUr {
    let mut config = MockUrConfig {
        address: addr(last),
        ..MockUrConfig::default()
    };
    tweak(&mut config);
    MockUr::start(config).expect("mock starts")
}

fn robot_config(mock: &MockUr) -> UrRobotConfig {
    UrRobotConfig {
        connect_timeout: Duration::from_secs(15),
        ..UrRobotConfig::new(mock.address().to_string())
    }
}

/// Fast moves so the tests stay short (the mock interpolates at these speeds).
fn fast() -> MotionLimits {
    MotionLimits {
        linear_speed: 0.5,
        linear_acceleration: 1.0,
        joint_speed: 2.0,
        joint_acceleration: 2.0,
    }
}

fn nudged(pose: &Pose, dx: f64, dz: f64, rotation: UnitQuaternion<f64>) -> Pose {
    let mut p = *pose;
    p.translation.vector += Vector3::new(dx, 0.0, dz);
    p.rotation = rotation * p.rotation;
    p
}

#[test]
fn connects_moves_and_reads_back_the_commanded_pose() {
    within(Duration::from_secs(60), || {
        let mock = start_mock(31, |_| {});
        let mut robot = UrRobot::connect(robot_config(&mock)).expect("connects");
        assert_eq!(robot.status().unwrap(), RobotStatus::Ready);
        let start = robot.base_from_flange().unwrap();
        assert!(translation_distance(&start, &mock.base_from_flange()) < 1e-9);

        let turn = UnitQuaternion::from_scaled_axis(Vector3::new(0.0, 0.0, 0.2));
        let target = nudged(&start, 0.03, -0.04, turn);
        let t0 = Instant::now();
        robot.move_linear(&target, &fast()).unwrap();
        // 5 cm at 0.5 m/s, or 0.2 rad at the mock's π/2 rad/s: ≥ 0.1 s of interpolated motion.
        assert!(t0.elapsed() >= Duration::from_millis(100));
        let reached = robot.base_from_flange().unwrap();
        assert!(
            translation_distance(&reached, &target) < 1e-6,
            "{reached:?}"
        );
        assert!(reached.rotation.angle_to(&target.rotation) < 1e-6);
        assert!(translation_distance(&mock.base_from_flange(), &target) < 1e-9);

        let mut q = robot.joint_positions().unwrap();
        q[0] += 0.1;
        q[5] -= 0.2;
        robot.move_joints(&q, &fast()).unwrap();
        let q_back = robot.joint_positions().unwrap();
        assert!(
            q_back.iter().zip(&q).all(|(a, b)| (a - b).abs() < 1e-9),
            "{q_back:?}"
        );
        assert_eq!(mock.moves_completed(), 2);
        robot.stop().unwrap();
        drop(robot);
        mock.shutdown();
    });
}

#[test]
fn tcp_offset_on_the_controller_still_gives_the_flange_pose() {
    within(Duration::from_secs(60), || {
        let offset = pose_from_rotvec(Vector3::new(0.01, -0.02, 0.18), Vector3::new(0.3, 0.0, 1.2));
        let mock = start_mock(32, |c| c.flange_from_tcp = offset);
        let mut robot = UrRobot::connect(robot_config(&mock)).expect("connects");
        let read = robot.flange_from_tcp();
        assert!(translation_distance(&read, &offset) < 1e-12);
        assert!(read.rotation.angle_to(&offset.rotation) < 1e-12);

        let flange = robot.base_from_flange().unwrap();
        let truth = mock.base_from_flange();
        assert!(translation_distance(&flange, &truth) < 1e-9);
        assert!(flange.rotation.angle_to(&truth.rotation) < 1e-9);

        // A flange target whose TCP rotation is within 1e-6 rad of 180° (rotvec sign ambiguity).
        let tcp_now = truth * offset;
        let axis = Vector3::new(0.6, 0.8, 0.0);
        let tcp_target_rot = UnitQuaternion::from_scaled_axis(axis * (PI - 1e-6));
        let mut tcp_target = tcp_now;
        tcp_target.rotation = tcp_target_rot;
        tcp_target.translation.vector += Vector3::new(0.0, 0.02, 0.0);
        let flange_target = tcp_target * offset.inverse();
        let slow_turns = MotionLimits {
            linear_speed: 1.0,
            ..fast()
        };
        robot.move_linear(&flange_target, &slow_turns).unwrap();
        let reached = robot.base_from_flange().unwrap();
        assert!(translation_distance(&reached, &flange_target) < 1e-6);
        assert!(reached.rotation.angle_to(&flange_target.rotation) < 1e-6);
        assert!(translation_distance(&mock.base_from_flange(), &flange_target) < 1e-9);
        drop(robot);
        mock.shutdown();
    });
}

#[test]
fn protective_stop_mid_move_is_reported_and_clearing_it_resumes() {
    within(Duration::from_secs(60), || {
        let mock = start_mock(33, |c| {
            c.faults = MockFaults {
                protective_stop_after_moves: Some(1),
                ..MockFaults::default()
            }
        });
        let mut robot = UrRobot::connect(robot_config(&mock)).expect("connects");
        let start = robot.base_from_flange().unwrap();
        let rot = UnitQuaternion::identity();
        robot
            .move_linear(&nudged(&start, 0.02, 0.0, rot), &fast())
            .unwrap();
        let err = robot
            .move_linear(&nudged(&start, 0.02, -0.05, rot), &fast())
            .unwrap_err();
        assert!(matches!(err, RobotError::ProtectiveStop), "{err}");
        assert_eq!(robot.status().unwrap(), RobotStatus::ProtectiveStop);
        // Refused while the stop is active, nothing sent.
        let started = mock.moves_started();
        assert!(matches!(
            robot.move_linear(&start, &fast()),
            Err(RobotError::ProtectiveStop)
        ));
        assert_eq!(mock.moves_started(), started);
        // A person clears it; the driver re-uploads the control script and carries on.
        mock.clear_stops();
        // The change reaches the client with the next data packages (2 ms apart).
        std::thread::sleep(Duration::from_millis(50));
        assert_eq!(robot.status().unwrap(), RobotStatus::Ready);
        robot.move_linear(&start, &fast()).unwrap();
        assert!(translation_distance(&robot.base_from_flange().unwrap(), &start) < 1e-6);
        assert!(mock.scripts_received() >= 2);
        drop(robot);
        mock.shutdown();
    });
}

/// Ctrl-C during a move: the driver tells the controller to stop (stopL) and the arm stands
/// part-way, instead of finishing the move first.
#[test]
fn an_interrupt_stops_the_arm_mid_move() {
    within(Duration::from_secs(60), || {
        let mock = start_mock(41, |_| {});
        let mut robot = UrRobot::connect(robot_config(&mock)).expect("connects");
        let flag = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
        robot.set_interrupt(flag.clone());
        let start = robot.base_from_flange().unwrap();
        // 20 cm at 0.1 m/s: about 2 s of motion.
        let slow = MotionLimits {
            linear_speed: 0.1,
            ..fast()
        };
        let target = nudged(&start, 0.0, 0.2, UnitQuaternion::identity());
        let setter = {
            let flag = flag.clone();
            std::thread::spawn(move || {
                std::thread::sleep(Duration::from_millis(500));
                flag.store(true, std::sync::atomic::Ordering::SeqCst);
            })
        };
        let t0 = Instant::now();
        let err = robot.move_linear(&target, &slow).unwrap_err();
        setter.join().unwrap();
        assert!(matches!(err, RobotError::Interrupted), "{err}");
        assert!(
            t0.elapsed() < Duration::from_millis(1500),
            "{:?}",
            t0.elapsed()
        );
        assert!(!mock.is_moving(), "the arm was stopped");
        let stopped = robot.base_from_flange().unwrap();
        let travelled = translation_distance(&stopped, &start);
        assert!(
            travelled > 0.01 && translation_distance(&stopped, &target) > 0.05,
            "stopped {travelled:.3} m from the start"
        );
        // While the flag is set nothing is sent.
        let started = mock.moves_started();
        assert!(matches!(
            robot.move_linear(&start, &fast()),
            Err(RobotError::Interrupted)
        ));
        assert_eq!(mock.moves_started(), started);
        drop(robot);
        mock.shutdown();
    });
}

#[test]
fn emergency_stop_is_reported() {
    within(Duration::from_secs(60), || {
        let mock = start_mock(34, |_| {});
        let mut robot = UrRobot::connect(robot_config(&mock)).expect("connects");
        let start = robot.base_from_flange().unwrap();
        mock.emergency_stop();
        let err = robot
            .move_linear(
                &nudged(&start, 0.0, 0.01, UnitQuaternion::identity()),
                &fast(),
            )
            .unwrap_err();
        assert!(matches!(err, RobotError::EmergencyStop), "{err}");
        assert_eq!(robot.status().unwrap(), RobotStatus::EmergencyStop);
        drop(robot);
        mock.shutdown();
    });
}

#[test]
fn stalled_move_times_out_and_stops_the_arm() {
    within(Duration::from_secs(60), || {
        let mock = start_mock(35, |c| {
            c.faults = MockFaults {
                stall_move: Some(0),
                ..MockFaults::default()
            }
        });
        let config = UrRobotConfig {
            move_timeout: Duration::from_millis(1500),
            ..robot_config(&mock)
        };
        let mut robot = UrRobot::connect(config).expect("connects");
        let start = robot.base_from_flange().unwrap();
        let t0 = Instant::now();
        let err = robot
            .move_linear(
                &nudged(&start, 0.0, 0.02, UnitQuaternion::identity()),
                &fast(),
            )
            .unwrap_err();
        assert!(matches!(err, RobotError::MoveTimeout(_)), "{err}");
        assert!(t0.elapsed() < Duration::from_secs(5));
        assert!(!mock.is_moving(), "the timed-out move was stopped");
        drop(robot);
        mock.shutdown();
    });
}

#[test]
fn dropped_connection_is_a_clean_error() {
    within(Duration::from_secs(60), || {
        let mock = start_mock(36, |c| {
            c.faults = MockFaults {
                drop_connection_after_moves: Some(1),
                ..MockFaults::default()
            }
        });
        let mut robot = UrRobot::connect(robot_config(&mock)).expect("connects");
        let start = robot.base_from_flange().unwrap();
        let rot = UnitQuaternion::identity();
        // The drop comes right as the first move completes, so the move itself (its read-back)
        // or the next call sees it.
        let t0 = Instant::now();
        let err = match robot.move_linear(&nudged(&start, 0.01, 0.0, rot), &fast()) {
            Err(e) => e,
            Ok(()) => robot
                .move_linear(&nudged(&start, 0.0, 0.0, rot), &fast())
                .and_then(|()| robot.base_from_flange().map(|_| ()))
                .unwrap_err(),
        };
        assert!(matches!(err, RobotError::ConnectionLost(_)), "{err}");
        assert!(t0.elapsed() < Duration::from_secs(10));
        assert_eq!(mock.moves_completed(), 1);
        // Later calls fail fast with the same kind of error.
        assert!(matches!(robot.status(), Err(RobotError::ConnectionLost(_))));
        drop(robot);
        mock.shutdown();
    });
}

#[test]
fn stopped_streaming_is_a_lost_connection() {
    within(Duration::from_secs(60), || {
        let mock = start_mock(37, |c| {
            c.faults = MockFaults {
                stop_streaming_after_moves: Some(1),
                ..MockFaults::default()
            }
        });
        let mut robot = UrRobot::connect(robot_config(&mock)).expect("connects");
        let start = robot.base_from_flange().unwrap();
        let rot = UnitQuaternion::identity();
        // The first move completes on the controller; streaming stops right then, so even its
        // read-back may already see the silence.
        let first = robot.move_linear(&nudged(&start, 0.01, 0.0, rot), &fast());
        let err = match first {
            Err(e) => e,
            Ok(()) => robot.base_from_flange().unwrap_err(),
        };
        assert!(
            matches!(err, RobotError::ConnectionLost(ref m) if m.contains("no state")),
            "{err}"
        );
        drop(robot);
        mock.shutdown();
    });
}

#[test]
fn target_outside_the_workspace_box_is_never_sent() {
    within(Duration::from_secs(60), || {
        let mock = start_mock(38, |_| {});
        let config = UrRobotConfig {
            workspace: Some(WorkspaceBox {
                min: Vector3::new(-1.0, -1.0, 0.2),
                max: Vector3::new(1.0, 1.0, 1.0),
            }),
            ..robot_config(&mock)
        };
        let mut robot = UrRobot::connect(config).expect("connects");
        let start = robot.base_from_flange().unwrap();
        let mut low = start;
        low.translation.z = 0.1;
        let err = robot.move_linear(&low, &fast()).unwrap_err();
        assert!(matches!(err, RobotError::OutsideWorkspace { .. }), "{err}");
        assert_eq!(mock.moves_started(), 0);
        drop(robot);
        mock.shutdown();
    });
}

#[test]
fn connecting_where_nothing_listens_fails_within_the_timeout() {
    within(Duration::from_secs(30), || {
        // Nothing is bound on 127.0.0.39.
        let config = UrRobotConfig {
            connect_timeout: Duration::from_secs(3),
            ..UrRobotConfig::new("127.0.0.39")
        };
        let t0 = Instant::now();
        let err = UrRobot::connect(config).unwrap_err();
        assert!(
            t0.elapsed() < Duration::from_millis(3500),
            "{:?}",
            t0.elapsed()
        );
        assert!(matches!(err, RobotError::Connect { .. }), "{err}");
        assert!(err.to_string().contains("127.0.0.39"), "{err}");
    });
}

#[test]
fn connecting_to_a_silent_controller_times_out() {
    within(Duration::from_secs(30), || {
        // A mock that accepts but never streams: ur_rtde alone would wait forever.
        let mock = start_mock(40, |c| {
            c.faults = MockFaults {
                stop_streaming_after_moves: Some(0),
                ..MockFaults::default()
            }
        });
        let config = UrRobotConfig {
            connect_timeout: Duration::from_secs(2),
            ..robot_config(&mock)
        };
        let t0 = Instant::now();
        let err = UrRobot::connect(config).unwrap_err();
        assert!(matches!(err, RobotError::Connect { .. }), "{err}");
        assert!(t0.elapsed() < Duration::from_millis(2500));
        mock.shutdown();
    });
}

#[test]
fn works_across_controller_versions() {
    // CB3 (125 Hz), a late e-Series (upper register set) and PolyScope X (no dashboard).
    for (last, version) in [(41u8, "3.15.0"), (42, "5.23.0"), (43, "10.11.0")] {
        within(Duration::from_secs(60), move || {
            let mock = start_mock(last, |c| c.controller_version = version.parse().unwrap());
            let mut robot = UrRobot::connect(robot_config(&mock)).expect(version);
            let start = robot.base_from_flange().unwrap();
            let target = nudged(&start, 0.0, 0.02, UnitQuaternion::identity());
            robot.move_linear(&target, &fast()).expect(version);
            let reached = robot.base_from_flange().unwrap();
            assert!(translation_distance(&reached, &target) < 1e-6, "{version}");
            drop(robot);
            mock.shutdown();
        });
    }
}
