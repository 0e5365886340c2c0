//! Cameras: the [`Camera`] contract and its error; the frame simulator that renders a board
//! through the intrinsic model (`render`); and the backends: the simulated camera (`sim`), the
//! image folder (`files`) and USB/UVC cameras (`uvc`, behind the `uvc` feature). The session
//! sees only the trait.
//!
//! Frames: `camera` is the optical frame (x right, y down, z forward, as OpenCV and ROS
//! `*_optical_frame`). Pixels follow OpenCV's convention for the whole project: pixel
//! centres sit at integer coordinates, pixel `(u, v)` covers `[u - 0.5, u + 0.5)`.
//! Units: metres for points, pixels for image coordinates. The intrinsic model lives on the
//! ground floor (`camera_model`). This module depends on the ground floor and `vision` (for
//! the board the renderer draws), never on robots or sessions.

pub mod decode;
pub mod files;
pub mod render;
pub mod sim;
#[cfg(feature = "uvc")]
pub mod uvc;

use std::time::Instant;

use image::GrayImage;

use handeye_core::camera_model::CameraModel;

/// One grabbed frame.
#[derive(Debug, Clone)]
pub struct Frame {
    /// The grey image.
    pub image: GrayImage,
    /// When the exposure happened (or the best the backend knows).
    pub captured_at: Instant,
    /// The frame's PNG file, when the frame is a recorded grey PNG (the image-folder camera): a
    /// session stores it as its frame file instead of encoding the same pixels again (or keeps
    /// it where it is, when it already is that file).
    pub png: Option<PngFile>,
}

/// A recorded grey PNG a frame was read from: where it is and its bytes as read.
#[derive(Debug, Clone, PartialEq)]
pub struct PngFile {
    /// The file.
    pub path: std::path::PathBuf,
    /// Its bytes.
    pub bytes: Vec<u8>,
}

/// Why a camera call failed.
#[derive(Debug, thiserror::Error)]
pub enum CameraError {
    /// The camera could not be opened.
    #[error("cannot open the camera: {0}")]
    Open(String),
    /// No frame newer than the requested instant arrived in time.
    #[error("no fresh frame within {0:?}")]
    Timeout(std::time::Duration),
    /// A frame source ran out (an image folder with fewer frames than plan poses).
    #[error("no more frames: {0}")]
    Exhausted(String),
    /// An image folder holds fewer frames than the plan has poses.
    #[error("the frame folder {} holds {frames} frames but the plan needs {poses} poses (frame i is plan pose i, in natural file-name order)", folder.display())]
    TooFewFrames {
        /// The folder.
        folder: std::path::PathBuf,
        /// Image files in it.
        frames: usize,
        /// Poses that need a frame.
        poses: usize,
    },
    /// A frame could not be read or decoded.
    #[error("cannot read frame {path}: {reason}")]
    Frame {
        /// Where the frame came from.
        path: String,
        /// What went wrong.
        reason: String,
    },
    /// The frame's memory could not be had (a limit such as `ulimit -v`): the cause to act on
    /// before resuming.
    #[error(transparent)]
    Memory(Box<handeye_core::memory::NotEnoughMemory>),
    /// Anything else the backend reports.
    #[error("camera backend error")]
    Backend(#[source] Box<dyn std::error::Error + Send + Sync>),
}

impl From<handeye_core::memory::NotEnoughMemory> for CameraError {
    fn from(error: handeye_core::memory::NotEnoughMemory) -> Self {
        CameraError::Memory(Box::new(error))
    }
}

/// A camera. `grab` blocks until a frame exposed no earlier than `not_before` is available, so a
/// frame buffered while the arm was still moving is never used.
pub trait Camera: Send {
    /// The next frame exposed at or after `not_before`.
    fn grab(&mut self, not_before: Instant) -> Result<Frame, CameraError>;
    /// The camera's intrinsics.
    fn model(&self) -> &CameraModel;
}
