//! A recorded cell: the recorded robot (`robot: {backend: recorded}`) replaying measured flange
//! poses, with the image-folder camera (`camera: {backend: files}`) serving the frame taken at
//! each. The plan is the recorded poses in file order; frame `i` (natural file-name order) goes
//! with pose `i`. Nothing is checked for reach or joint limits: a real arm already visited these
//! poses. Only the rotation diversity the solver needs is checked before running.

use handeye_camera::files::{FilesCamera, FrameSelector};
use handeye_config::{CameraConfig, CellConfig, RobotConfig};
use handeye_core::camera_model::CameraModel;
use handeye_core::geometry::Pose;
use handeye_plan::check::{board_margin, board_points, PlanReport, PoseCheck};
use handeye_plan::{Plan, Waypoint};
use handeye_robot::recorded::{load_recorded_poses, plan_joints, RecordedRobot};
use handeye_robot::{Joints, MotionLimits, Robot, RobotError, RobotStatus};
use handeye_solve::check_rotation_diversity;
use handeye_vision::Target;

use super::CellError;

/// The plan of a recorded cell and its report (distances and image margins under the nominal
/// transforms, for information only).
pub fn plan(
    config: &CellConfig,
    camera: &CameraModel,
    board: &Target,
) -> Result<(Plan, PlanReport), CellError> {
    let RobotConfig::Recorded(handeye_config::RecordedRobot { poses, .. }) = &config.robot else {
        return Err(CellError::Backend(
            "a recorded plan needs `robot: {backend: recorded}`".into(),
        ));
    };
    let recorded = load_recorded_poses(poses).map_err(|e| CellError::Backend(e.to_string()))?;
    let points = board_points(board);
    let checks = recorded
        .iter()
        .enumerate()
        .map(|(index, base_from_flange)| {
            let camera_from_target = config.camera().nominal.camera_from_target(base_from_flange);
            PoseCheck {
                index,
                base_from_flange: *base_from_flange,
                joints: Some(plan_joints(index)),
                distance_m: camera_from_target.translation.vector.norm(),
                image_margin_px: board_margin(camera, &camera_from_target, &points),
                move_time_s: 0.0,
                problems: Vec::new(),
            }
        })
        .collect();
    let plan_problems = match check_rotation_diversity(&recorded) {
        Ok(()) => Vec::new(),
        Err(e) => vec![format!("recorded poses {}: {e}", poses.display())],
    };
    Ok((
        Plan {
            waypoints: recorded.into_iter().map(Waypoint::FlangePose).collect(),
        },
        PlanReport {
            poses: checks,
            plan_problems,
            notes: Vec::new(),
            intrinsics: None,
            given_order_move_time_s: None,
        },
    ))
}

/// A recorded cell without intrinsics (they are estimated from the recorded corners after the
/// run): a lens of the first frame's size (focal length = the larger side, centred, no
/// distortion), used only for the plan report's information-only margins and the folder camera's
/// frame-size check.
pub fn provisional_model(config: &CellConfig) -> Result<CameraModel, CellError> {
    let CameraConfig::Files(handeye_config::FilesCamera { folder }) = &config.camera().backend
    else {
        return Err(CellError::Backend(
            "a recorded cell needs `camera: {backend: files}`".into(),
        ));
    };
    let frames = handeye_camera::files::list_frames(folder)
        .map_err(|e| CellError::Backend(e.to_string()))?;
    let first = frames.first().ok_or_else(|| {
        CellError::Backend(format!("{}: no frames in the folder", folder.display()))
    })?;
    let (width, height) = image::image_dimensions(first)
        .map_err(|e| CellError::Backend(format!("{}: {e}", first.display())))?;
    let focal = f64::from(width.max(height));
    Ok(CameraModel {
        width,
        height,
        fx: focal,
        fy: focal,
        cx: (f64::from(width) - 1.0) / 2.0,
        cy: (f64::from(height) - 1.0) / 2.0,
        distortion: handeye_core::camera_model::Distortion::None,
    })
}

/// Opens the recorded arm of `config` (`robot: {backend: recorded}`): it serves the validated
/// plan's poses (the recorded ones, in file order) and names each pose it moves to on the
/// selector its folder cameras serve frames by ([`open_camera`]).
pub fn arm(
    config: &CellConfig,
    plan: &[(Pose, Joints)],
) -> Result<(Box<dyn Robot>, FrameSelector), CellError> {
    let RobotConfig::Recorded(_) = &config.robot else {
        return Err(CellError::Backend(
            "a recorded cell needs `robot: {backend: recorded}` and `camera: {backend: files}`"
                .into(),
        ));
    };
    let selector = FrameSelector::default();
    let robot = SelectingRobot {
        robot: RecordedRobot::new(plan.iter().map(|(pose, _)| *pose).collect()),
        selector: selector.clone(),
    };
    Ok((Box::new(robot), selector))
}

/// Opens the image-folder camera of `config`, serving the frame of the pose `selector` names;
/// the folder must hold a frame for each of `poses` poses.
pub fn open_camera(
    config: &CellConfig,
    selector: &FrameSelector,
    poses: usize,
    camera_model: CameraModel,
) -> Result<Box<dyn handeye_camera::Camera>, CellError> {
    let CameraConfig::Files(handeye_config::FilesCamera { folder }) = &config.camera().backend
    else {
        return Err(CellError::Backend(
            "recorded poses need `camera: {backend: files}`".into(),
        ));
    };
    let camera = FilesCamera::open(folder, camera_model)
        .map_err(|e| CellError::Backend(e.to_string()))?
        .with_selector(selector.clone());
    camera
        .require_frames(poses)
        .map_err(|e| CellError::Backend(e.to_string()))?;
    Ok(Box::new(camera))
}

/// The recorded robot, telling the folder camera which pose it is at after every move.
struct SelectingRobot {
    robot: RecordedRobot,
    selector: FrameSelector,
}

impl SelectingRobot {
    fn sync(&self) {
        if let Some(i) = self.robot.current() {
            self.selector.select(i);
        }
    }
}

impl Robot for SelectingRobot {
    fn base_from_flange(&mut self) -> Result<Pose, RobotError> {
        self.robot.base_from_flange()
    }
    fn joint_positions(&mut self) -> Result<Joints, RobotError> {
        self.robot.joint_positions()
    }
    fn move_linear(&mut self, pose: &Pose, limits: &MotionLimits) -> Result<(), RobotError> {
        self.robot.move_linear(pose, limits)?;
        self.sync();
        Ok(())
    }
    fn move_joints(&mut self, joints: &Joints, limits: &MotionLimits) -> Result<(), RobotError> {
        self.robot.move_joints(joints, limits)?;
        self.sync();
        Ok(())
    }
    fn stop(&mut self) -> Result<(), RobotError> {
        self.robot.stop()
    }
    fn status(&mut self) -> Result<RobotStatus, RobotError> {
        self.robot.status()
    }
}
