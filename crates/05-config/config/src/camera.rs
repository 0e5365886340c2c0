//! The camera backends of a cell config (`camera: {backend: ...}`), each described once, as the
//! arms are (`robot.rs`): its section's keys (a struct) and what the rest of handeye asks of any
//! camera ([`CameraBackend`]): its name, whether it renders the simulated cell and with which
//! lens, the paths it names (read relative to the config), and its section's checks.
//! [`CameraConfig`] holds one of them and answers through [`CameraConfig::backend`].
//!
//! A new camera is its section struct and its `CameraBackend` impl (here, or in a module of its
//! own as `ros2.rs` is), a variant of [`CameraConfig`] and its line in the two dispatches below,
//! its `handeye_camera::Camera` in `crates/02-devices/camera`, and its opener in
//! `PreparedCell::open_camera_beside` (`crates/07-run/session/src/cell/mod.rs`).

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use super::schema::{CameraConfig, PixelFormatName};
use super::validate::{
    Validator, BLUR_SIGMA_PX, CAMERA_CONTROL, EXPOSURE_US, FPS, HIDDEN_GRAB, IMAGE_SIDE_PX,
    NOISE_SIGMA, STALE_FRAMES,
};
use super::ConfigError;

/// What handeye asks of a camera backend, whichever it is.
pub trait CameraBackend {
    /// Its `backend:` name (`sim`, `files`, `uvc`, `ros2`).
    fn name(&self) -> &'static str;
    /// It renders the simulated cell (the cell then needs its ground truth).
    fn simulated(&self) -> bool {
        false
    }
    /// The lens it renders with when it names its own (`camera.intrinsics` of a sim camera).
    fn own_lens(&self) -> Option<&Path> {
        None
    }
    /// Its paths made relative to the config's folder (`resolve`), as the config is read.
    fn resolve_paths(&mut self, _resolve: &dyn Fn(&Path) -> PathBuf) {}
    /// Its section's own checks (`camera.*`); `cell_intrinsics`: the cell gives `intrinsics`.
    fn check(&self, v: &Validator<'_>, cell_intrinsics: bool) -> Result<(), ConfigError>;
}

impl CameraConfig {
    /// The backend the config names.
    pub fn backend(&self) -> &dyn CameraBackend {
        match self {
            CameraConfig::Sim(sim) => sim,
            CameraConfig::Files(files) => files,
            CameraConfig::Uvc(uvc) => uvc,
            CameraConfig::Ros2(ros2) => ros2,
        }
    }

    /// The backend the config names, to change.
    pub fn backend_mut(&mut self) -> &mut dyn CameraBackend {
        match self {
            CameraConfig::Sim(sim) => sim,
            CameraConfig::Files(files) => files,
            CameraConfig::Uvc(uvc) => uvc,
            CameraConfig::Ros2(ros2) => ros2,
        }
    }
}

/// `camera: {backend: sim}`: frames rendered from the simulated cell's true chain.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SimCamera {
    /// Sensor noise, grey levels (1-sigma).
    #[serde(default = "default_noise")]
    pub noise_sigma: f64,
    /// Optical blur, pixels (1-sigma of a Gaussian), 0 = none.
    #[serde(default)]
    pub blur_sigma_px: f64,
    /// Render seed.
    #[serde(default)]
    pub seed: u64,
    /// Grab numbers (0-based) in which the board is hidden (fault injection for tests).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub hide_board_in_grabs: Vec<usize>,
    /// The simulated lens (camera_info YAML); defaults to the cell's `intrinsics`. Required
    /// when the cell has no `intrinsics` (they are then estimated from the run). Differing
    /// from the cell's `intrinsics`, it simulates a camera calibrated wrongly.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub intrinsics: Option<PathBuf>,
    /// The board the simulated camera sees (board file); defaults to the cell's `target`.
    /// Differing from it (another `tagSize`), it simulates a board printed at another scale.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub target: Option<PathBuf>,
}

impl CameraBackend for SimCamera {
    fn name(&self) -> &'static str {
        "sim"
    }

    fn simulated(&self) -> bool {
        true
    }

    fn own_lens(&self) -> Option<&Path> {
        self.intrinsics.as_deref()
    }

    fn resolve_paths(&mut self, resolve: &dyn Fn(&Path) -> PathBuf) {
        self.intrinsics = self.intrinsics.as_deref().map(resolve);
        self.target = self.target.as_deref().map(resolve);
    }

    fn check(&self, v: &Validator<'_>, cell_intrinsics: bool) -> Result<(), ConfigError> {
        v.number("camera.noise_sigma", self.noise_sigma, NOISE_SIGMA)?;
        v.number("camera.blur_sigma_px", self.blur_sigma_px, BLUR_SIGMA_PX)?;
        for (i, grab) in self.hide_board_in_grabs.iter().enumerate() {
            v.integer(
                &format!("camera.hide_board_in_grabs[{i}]"),
                *grab as i128,
                HIDDEN_GRAB,
            )?;
        }
        if !cell_intrinsics && self.intrinsics.is_none() {
            return Err(v.inconsistent(
                "camera.intrinsics",
                "the cell has no `intrinsics` (they will be estimated), so the sim camera needs its lens: `camera: {backend: sim, intrinsics: <camera_info.yaml>}`".into(),
            ));
        }
        Ok(())
    }
}

/// `camera: {backend: files}`: frames from an image folder, in plan order.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FilesCamera {
    /// The folder.
    pub folder: PathBuf,
}

impl CameraBackend for FilesCamera {
    fn name(&self) -> &'static str {
        "files"
    }

    fn resolve_paths(&mut self, resolve: &dyn Fn(&Path) -> PathBuf) {
        self.folder = resolve(&self.folder);
    }

    fn check(&self, _v: &Validator<'_>, _cell_intrinsics: bool) -> Result<(), ConfigError> {
        Ok(())
    }
}

/// `camera: {backend: uvc}`: a USB/UVC camera (needs the `uvc` build feature).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct UvcCamera {
    /// Camera index (`/dev/video<N>`) or (part of) its name.
    #[serde(default = "default_uvc_device")]
    pub device: String,
    /// Requested width, px.
    #[serde(default = "default_uvc_width")]
    pub width: u32,
    /// Requested height, px.
    #[serde(default = "default_uvc_height")]
    pub height: u32,
    /// Requested pixel format: `mjpeg`, `yuyv` or `gray`.
    #[serde(default)]
    pub pixel_format: PixelFormatName,
    /// Requested frame rate, frames/s.
    #[serde(default = "default_uvc_fps")]
    pub fps: u32,
    /// Fixed exposure, µs (auto exposure off).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub exposure_us: Option<u32>,
    /// Fixed gain, camera units (auto gain off).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub gain: Option<i64>,
    /// Fixed focus, camera units (autofocus is turned off whenever the camera allows).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub focus: Option<i64>,
    /// Frames dropped after the arm settles (the driver's queue depth).
    #[serde(default = "default_uvc_stale_frames")]
    pub stale_frames: usize,
}

impl CameraBackend for UvcCamera {
    fn name(&self) -> &'static str {
        "uvc"
    }

    fn check(&self, v: &Validator<'_>, _cell_intrinsics: bool) -> Result<(), ConfigError> {
        if self.device.trim().is_empty() {
            return Err(v.inconsistent(
                "camera.device",
                "expected a /dev/video index or (part of) the camera's name, found an empty string"
                    .into(),
            ));
        }
        v.integer("camera.width", i128::from(self.width), IMAGE_SIDE_PX)?;
        v.integer("camera.height", i128::from(self.height), IMAGE_SIDE_PX)?;
        v.integer("camera.fps", i128::from(self.fps), FPS)?;
        if let Some(us) = self.exposure_us {
            v.integer("camera.exposure_us", i128::from(us), EXPOSURE_US)?;
        }
        if let Some(gain) = self.gain {
            v.integer("camera.gain", i128::from(gain), CAMERA_CONTROL)?;
        }
        if let Some(focus) = self.focus {
            v.integer("camera.focus", i128::from(focus), CAMERA_CONTROL)?;
        }
        v.integer(
            "camera.stale_frames",
            self.stale_frames as i128,
            STALE_FRAMES,
        )?;
        Ok(())
    }
}

fn default_uvc_device() -> String {
    "0".into()
}
fn default_uvc_width() -> u32 {
    1280
}
fn default_uvc_height() -> u32 {
    720
}
fn default_uvc_fps() -> u32 {
    30
}
fn default_uvc_stale_frames() -> usize {
    4
}
fn default_noise() -> f64 {
    2.0
}
