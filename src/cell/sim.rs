//! The simulated cell: a simulated arm and a simulated camera sharing one world, so the camera
//! renders from the arm's true pose while the arm reports a noisy one.

use std::sync::atomic::AtomicBool;
use std::sync::{Arc, Mutex, MutexGuard};

use crate::camera::model::CameraModel;
use crate::camera::render::RenderOptions;
use crate::camera::sim::{SimCamera, TrueFlangePose};
use crate::config::{CameraConfig, CellConfig, RobotConfig};
use crate::geometry::Pose;
use crate::plan::CellTransforms;
use crate::robot::kinematics::UrModel;
use crate::robot::sim::{SimFaults, SimRobot, SimRobotOptions};
use crate::robot::{Joints, MotionLimits, Robot, RobotError, RobotStatus};
use crate::target::Board;

use super::CellError;

/// A simulated arm shared with the simulated camera.
pub struct SharedSimRobot(Arc<Mutex<SimRobot>>);

impl SharedSimRobot {
    fn arm(&self) -> MutexGuard<'_, SimRobot> {
        // A panic while holding the lock cannot leave the arm half-moved: a move updates the
        // arm's state in one step when it ends (arrived or interrupted).
        self.0
            .lock()
            .unwrap_or_else(|poisoned| poisoned.into_inner())
    }
}

impl Robot for SharedSimRobot {
    fn base_from_flange(&mut self) -> Result<Pose, RobotError> {
        self.arm().base_from_flange()
    }
    fn joint_positions(&mut self) -> Result<Joints, RobotError> {
        self.arm().joint_positions()
    }
    fn move_linear(
        &mut self,
        base_from_flange: &Pose,
        limits: &MotionLimits,
    ) -> Result<(), RobotError> {
        self.arm().move_linear(base_from_flange, limits)
    }
    fn move_joints(&mut self, joints: &Joints, limits: &MotionLimits) -> Result<(), RobotError> {
        self.arm().move_joints(joints, limits)
    }
    fn stop(&mut self) -> Result<(), RobotError> {
        self.arm().stop()
    }
    fn set_interrupt(&mut self, flag: Arc<AtomicBool>) {
        self.arm().set_interrupt(flag);
    }
    fn status(&mut self) -> Result<RobotStatus, RobotError> {
        self.arm().status()
    }
}

/// Builds the simulated arm and camera a config describes.
pub fn open(
    config: &CellConfig,
    truth: CellTransforms,
    arm: UrModel,
    start: Joints,
    camera_model: CameraModel,
    board: Board,
) -> Result<(SharedSimRobot, SimCamera), CellError> {
    let RobotConfig::Sim {
        move_duration_s,
        repeatability_mm,
        repeatability_deg,
        protective_stop_after_moves,
        seed,
        ..
    } = &config.robot
    else {
        return Err(CellError::Backend(
            "the simulated cell needs `robot: {backend: sim}`".into(),
        ));
    };
    let options = SimRobotOptions {
        move_duration: std::time::Duration::from_secs_f64(*move_duration_s),
        repeatability_m: repeatability_mm * 1e-3,
        repeatability_rad: repeatability_deg.to_radians(),
        seed: *seed,
        faults: SimFaults {
            protective_stop_after_moves: *protective_stop_after_moves,
            ..SimFaults::default()
        },
    };
    let robot =
        SimRobot::new(arm, start, options).map_err(|e| CellError::Backend(e.to_string()))?;
    let shared = Arc::new(Mutex::new(robot));
    let camera_arm = shared.clone();
    let true_pose = Box::new(move || {
        camera_arm
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .true_base_from_flange()
    });
    Ok((
        SharedSimRobot(shared),
        camera(config, truth, true_pose, camera_model, board)?,
    ))
}

/// The simulated camera a config describes, rendering with the flange pose `flange` gives.
pub fn camera(
    config: &CellConfig,
    truth: CellTransforms,
    flange: TrueFlangePose,
    camera_model: CameraModel,
    board: Board,
) -> Result<SimCamera, CellError> {
    let CameraConfig::Sim {
        noise_sigma,
        blur_sigma_px,
        seed,
        hide_board_in_grabs,
        ..
    } = &config.camera
    else {
        return Err(CellError::Backend(
            "expected `camera: {backend: sim}`".into(),
        ));
    };
    let render = RenderOptions {
        noise_sigma: *noise_sigma,
        blur_sigma_px: *blur_sigma_px,
        ..RenderOptions::default()
    };
    Ok(SimCamera::new(
        camera_model,
        board,
        truth,
        flange,
        render,
        *seed,
        hide_board_in_grabs.iter().copied().collect(),
    ))
}

/// Any arm shared with a simulated camera that renders from the pose the arm last reported
/// (a mock controller reports its exact pose).
#[derive(Clone)]
pub struct SharedRobot {
    robot: Arc<Mutex<Box<dyn Robot>>>,
    last: Arc<Mutex<Option<Pose>>>,
}

impl SharedRobot {
    /// Shares `robot`.
    pub fn new(robot: Box<dyn Robot>) -> Self {
        SharedRobot {
            robot: Arc::new(Mutex::new(robot)),
            last: Arc::new(Mutex::new(None)),
        }
    }

    fn robot(&self) -> MutexGuard<'_, Box<dyn Robot>> {
        self.robot
            .lock()
            .unwrap_or_else(|poisoned| poisoned.into_inner())
    }

    /// The flange pose the arm reports now, or the last one it reported if it cannot answer.
    pub fn last_base_from_flange(&self) -> Pose {
        let now = self.robot().base_from_flange().ok();
        let mut last = self.last.lock().unwrap_or_else(|p| p.into_inner());
        if now.is_some() {
            *last = now;
        }
        last.unwrap_or_else(Pose::identity)
    }
}

impl Robot for SharedRobot {
    fn base_from_flange(&mut self) -> Result<Pose, RobotError> {
        self.robot().base_from_flange()
    }
    fn joint_positions(&mut self) -> Result<Joints, RobotError> {
        self.robot().joint_positions()
    }
    fn move_linear(
        &mut self,
        base_from_flange: &Pose,
        limits: &MotionLimits,
    ) -> Result<(), RobotError> {
        self.robot().move_linear(base_from_flange, limits)
    }
    fn move_joints(&mut self, joints: &Joints, limits: &MotionLimits) -> Result<(), RobotError> {
        self.robot().move_joints(joints, limits)
    }
    fn stop(&mut self) -> Result<(), RobotError> {
        self.robot().stop()
    }
    fn set_interrupt(&mut self, flag: Arc<AtomicBool>) {
        self.robot().set_interrupt(flag);
    }
    fn status(&mut self) -> Result<RobotStatus, RobotError> {
        self.robot().status()
    }
}
