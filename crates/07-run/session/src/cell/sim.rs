//! The simulated cell: a simulated arm and a simulated camera sharing one world, so the camera
//! renders from the arm's true pose while the arm reports a noisy one (computed through its
//! nominal model when the config gives the arm's own errors, `simulation.arm_errors`).

use std::cell::Cell;
use std::sync::atomic::AtomicBool;
use std::sync::{Arc, Mutex, MutexGuard};

use handeye_camera::render::RenderOptions;
use handeye_camera::sim::{SimCamera, TrueFlangePose};
use handeye_config::{CameraConfig, CellConfig, RobotConfig};
use handeye_core::camera_model::CameraModel;
use handeye_core::geometry::Pose;
use handeye_core::setup::CellTransforms;
use handeye_robot::kinematics::UrModel;
use handeye_robot::sim::{SimFaults, SimRobot, SimRobotOptions};
use handeye_robot::{Joints, MotionLimits, Robot, RobotError, RobotStatus};
use handeye_vision::Target;

use super::CellError;

/// An arm behind a mutex, shared between the session (which drives it) and a simulated camera
/// (which renders from its pose).
pub struct Shared<R: Robot + ?Sized>(Arc<Mutex<R>>);

impl<R: Robot + ?Sized> Clone for Shared<R> {
    fn clone(&self) -> Self {
        Shared(self.0.clone())
    }
}

impl<R: Robot> Shared<R> {
    /// Shares `robot`.
    pub fn new(robot: R) -> Self {
        Shared(Arc::new(Mutex::new(robot)))
    }
}

impl<R: Robot + ?Sized> Shared<R> {
    /// The arm, for as long as the guard lives; a move in progress holds it until the move ends.
    pub fn lock(&self) -> MutexGuard<'_, R> {
        // A panic while holding the lock cannot leave the arm half-moved: a move updates the
        // arm's state in one step when it ends (arrived or interrupted).
        self.0
            .lock()
            .unwrap_or_else(|poisoned| poisoned.into_inner())
    }
}

impl Shared<dyn Robot> {
    /// Shares `robot` as an arm of a type chosen at run time.
    pub fn new_dyn<R: Robot + 'static>(robot: R) -> Self {
        Shared(Arc::new(Mutex::new(robot)))
    }

    /// A flange pose for a simulated camera next to this arm: the pose the arm reports now, or
    /// the last one it reported if it cannot answer (identity before its first answer). A mock
    /// controller reports its exact pose.
    pub fn reported_flange(&self) -> TrueFlangePose {
        let robot = self.clone();
        let last = Cell::new(None);
        Box::new(move || {
            if let Ok(now) = robot.lock().base_from_flange() {
                last.set(Some(now));
            }
            last.get().unwrap_or_else(Pose::identity)
        })
    }
}

impl<R: Robot + ?Sized> Robot for Shared<R> {
    fn base_from_flange(&mut self) -> Result<Pose, RobotError> {
        self.lock().base_from_flange()
    }
    fn joint_positions(&mut self) -> Result<Joints, RobotError> {
        self.lock().joint_positions()
    }
    fn move_linear(
        &mut self,
        base_from_flange: &Pose,
        limits: &MotionLimits,
    ) -> Result<(), RobotError> {
        self.lock().move_linear(base_from_flange, limits)
    }
    fn move_joints(&mut self, joints: &Joints, limits: &MotionLimits) -> Result<(), RobotError> {
        self.lock().move_joints(joints, limits)
    }
    fn stop(&mut self) -> Result<(), RobotError> {
        self.lock().stop()
    }
    fn set_interrupt(&mut self, flag: Arc<AtomicBool>) {
        self.lock().set_interrupt(flag);
    }
    fn status(&mut self) -> Result<RobotStatus, RobotError> {
        self.lock().status()
    }
    fn set_freedrive(&mut self, on: bool) -> Result<(), RobotError> {
        self.lock().set_freedrive(on)
    }
    fn joint_speeds(&mut self) -> Result<Option<Joints>, RobotError> {
        self.lock().joint_speeds()
    }
}

/// Builds the simulated arm a config describes (its cameras follow its true flange pose:
/// [`camera`]).
pub fn arm(
    config: &CellConfig,
    arm: UrModel,
    start: Joints,
) -> Result<Shared<SimRobot>, CellError> {
    let RobotConfig::Sim(handeye_config::SimRobot {
        move_duration_s,
        repeatability_mm,
        repeatability_deg,
        protective_stop_after_moves,
        seed,
        move_at_limits,
        ringing_deg,
        ringing_hz,
        ringing_decay_s,
        ..
    }) = &config.robot
    else {
        return Err(CellError::Backend(
            "the simulated cell needs `robot: {backend: sim}`".into(),
        ));
    };
    let options = SimRobotOptions {
        move_duration: std::time::Duration::from_secs_f64(*move_duration_s),
        move_at_limits: *move_at_limits,
        ringing: (*ringing_deg > 0.0).then(|| handeye_robot::sim::Ringing {
            amplitude_rad: ringing_deg.to_radians(),
            frequency_hz: *ringing_hz,
            decay_s: *ringing_decay_s,
        }),
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
    // The arm's own errors (`simulation.arm_errors`): it reports through its nominal model.
    let robot = match &config.true_arm {
        Some(truth) => robot.with_true_arm(truth.clone()),
        None => robot,
    };
    Ok(Shared::new(robot))
}

/// The simulated camera a config describes, rendering with the flange pose `flange` gives.
pub fn camera(
    config: &CellConfig,
    truth: CellTransforms,
    flange: TrueFlangePose,
    camera_model: CameraModel,
    board: Target,
) -> Result<SimCamera, CellError> {
    let CameraConfig::Sim(handeye_config::SimCamera {
        noise_sigma,
        blur_sigma_px,
        seed,
        hide_board_in_grabs,
        ..
    }) = &config.camera().backend
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
