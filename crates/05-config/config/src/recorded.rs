//! The config of a recorded cell: frames imported from elsewhere (a ROS 2 bag, a ViSP folder)
//! replayed as a session, with a `recorded` robot serving the measured flange poses and a
//! `files` camera serving the images. Written by the importers, read back like any cell config.

use std::collections::BTreeMap;
use std::path::PathBuf;

use handeye_core::geometry::{Pose, PoseYaml};
use handeye_core::setup::{RobotFrames, Setup};

use super::{
    CameraConfig, ConfigFile, DetectorConfig, LimitsConfig, PlanConfig, RobotConfig, SessionConfig,
    SolverConfig, WorkspaceConfig,
};

/// Where a recorded cell's files are (relative paths are read from the config's folder).
#[derive(Debug, Clone)]
pub struct RecordedFiles {
    /// The board file.
    pub target: PathBuf,
    /// The intrinsics file; `None`: estimated from the frames.
    pub intrinsics: Option<PathBuf>,
    /// The recorded flange poses (`handeye_robot::recorded` form).
    pub poses: PathBuf,
    /// The folder of images, one per pose in natural order.
    pub images: PathBuf,
    /// The frames the recorded poses are in.
    pub frames: RobotFrames,
}

/// The config of a recorded cell that replays imported frames: the flange poses
/// `base_from_flange` (as in `files.poses`) with the images of a folder camera. `nominal`
/// (camera mount, target mount) only feeds the plan report; the workspace box, which a recorded
/// robot does not use, spans the recorded flange positions ± 0.5 m; nothing moves, so nothing
/// settles.
pub fn recorded_cell(
    setup: Setup,
    files: RecordedFiles,
    (camera_mount, target_mount): (Pose, Pose),
    base_from_flange: &[Pose],
    decimate: f32,
) -> ConfigFile {
    let (mut lo, mut hi) = ([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]);
    for p in base_from_flange {
        let t = p.translation.vector;
        for k in 0..3 {
            lo[k] = lo[k].min(t[k] - 0.5);
            hi[k] = hi[k].max(t[k] + 0.5);
        }
    }
    let (camera_key, target_key) = setup.unknown_names();
    ConfigFile {
        setup: Some(setup),
        flange_target: None,
        cameras: None,
        target: files.target,
        intrinsics: files.intrinsics,
        robot: RobotConfig::Recorded(super::RecordedRobot {
            poses: files.poses,
            repeatability_mm: None,
            repeatability_deg: None,
            frames: Some(files.frames),
        }),
        camera: Some(CameraConfig::Files(super::FilesCamera {
            folder: files.images,
        })),
        nominal: BTreeMap::from([
            (camera_key.to_string(), PoseYaml::from_pose(&camera_mount)),
            (target_key.to_string(), PoseYaml::from_pose(&target_mount)),
        ]),
        simulation: None,
        plan: PlanConfig::default(),
        limits: LimitsConfig::default(),
        workspace: WorkspaceConfig { min: lo, max: hi },
        detector: DetectorConfig {
            decimate,
            ..DetectorConfig::default()
        },
        solver: SolverConfig::default(),
        session: SessionConfig {
            settle_s: 0.0,
            ..SessionConfig::default()
        },
        verdict: Default::default(),
    }
}
