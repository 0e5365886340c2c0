//! The frame-id flags `export` and `publish` share, turned into [`FrameIds`] checked before
//! anything is read or written (the flag is named in the message).

use clap::Args;

use handeye_formats::{ExportError, FrameIds};

/// Frame ids of the exported or published transforms. They follow ROS naming: ASCII letters,
/// digits, `_` and `/` (no leading `/`, no part starting with a digit).
#[derive(Debug, Args)]
pub(super) struct FrameArgs {
    /// Frame id of the robot base (the frame T_base_flange is reported in). `base_link` (the
    /// UR ROS driver's, `base` turned 180° about z) exports the base-side transform turned to
    /// match.
    #[arg(long, default_value = "base")]
    base_frame: String,
    /// Frame id of the flange.
    #[arg(long, default_value = "tool0")]
    flange_frame: String,
    /// Frame id of the camera's optical frame (x right, y down, z forward).
    #[arg(long, default_value = "camera_optical_frame")]
    camera_frame: String,
    /// Frame id of the board.
    #[arg(long, default_value = "calibration_target")]
    target_frame: String,
}

impl FrameArgs {
    /// The ids, each checked; the error names its flag.
    pub(super) fn ids(self) -> anyhow::Result<FrameIds> {
        let ids = FrameIds {
            base: self.base_frame,
            flange: self.flange_frame,
            camera: self.camera_frame,
            target: self.target_frame,
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
