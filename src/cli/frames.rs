//! The frame-id flags `export` and `publish` share, turned into [`FrameIds`] checked before
//! anything is read or written (the flag is named in the message).

use clap::Args;

use handeye_core::setup::RobotFrames;
use handeye_formats::{ExportError, FrameIds};

/// Frame ids of the exported or published transforms. They follow ROS naming: ASCII letters,
/// digits, `_` and `/` (no leading `/`, no part starting with a digit).
#[derive(Debug, Args)]
pub(super) struct FrameArgs {
    /// Frame id of the robot base. Default: the frame the result's robot poses were read in
    /// (its `robot_frames`; `base`, the UR controller's, for older results). Between the UR
    /// ROS driver's `base` and `base_link` (`base` turned 180° about z) the base-side
    /// transforms are turned to match.
    #[arg(long)]
    base_frame: Option<String>,
    /// Frame id of the flange. Default: the result's flange frame (`tool0` for older results).
    #[arg(long)]
    flange_frame: Option<String>,
    /// Frame id of the camera's optical frame (x right, y down, z forward).
    #[arg(long, default_value = "camera_optical_frame")]
    camera_frame: String,
    /// Frame id of the board.
    #[arg(long, default_value = "calibration_target")]
    target_frame: String,
}

impl FrameArgs {
    /// The ids, each checked (the error names its flag), for a result whose robot poses were
    /// read in `robot`'s frames.
    pub(super) fn ids(self, robot: &RobotFrames) -> anyhow::Result<FrameIds> {
        let ids = FrameIds {
            base: self.base_frame.unwrap_or_else(|| robot.base.clone()),
            flange: self.flange_frame.unwrap_or_else(|| robot.flange.clone()),
            camera: self.camera_frame,
            target: self.target_frame,
            poses_in: robot.base.clone(),
        };
        ids.validate().map_err(|e| {
            let flag = match &e {
                ExportError::FrameId { role, .. } => format!("--{role}-frame"),
                _ => "a frame flag".to_string(),
            };
            anyhow::Error::new(e).context(format!("{flag} is not a ROS frame id"))
        })?;
        Ok(ids)
    }
}
