//! The calibration target: the board of any kind (`target`: aprilgrid, ChArUco or chessboard,
//! and its detector), the aprilgrid specification (`board`), the AprilTag family tables it is
//! printed from (`family`), tag detection on a dedicated thread (`detect`), ChArUco boards
//! (`charuco`), plain chessboards (`chessboard`), sub-pixel refinement of every board's corners
//! to the saddle point of the image (`xcorner`: Kalibr's corner squares, chessboard and ChArUco
//! corners), a frame's sharpness (`sharpness`), printable boards (`print`) and the
//! board pose `T_camera_target` by PnP with lens distortion (`pnp`).
//!
//! Frames: `target` is the board frame, x to the right and y up as printed, z out of the
//! printed face; its origin is the outer bottom-left corner of tag 0's black square (aprilgrid),
//! the bottom-left outer corner of the squares (ChArUco) or the bottom-left inner corner
//! (chessboard). `camera` is the optical frame. Units: metres in the target frame, pixels
//! (OpenCV convention: centres at integers) in images. Depends on `geometry`, `camera_model`
//! and `setup` (the recorded corner); never on robots, sessions or the CLI. ChArUco marker
//! decoding and chessboard grid labelling come from the `calib-targets-*` crates.

pub mod annotate;
pub mod board;
pub mod charuco;
pub mod chessboard;
pub mod detect;
pub mod draw;
pub mod family;
// The AprilTag C library's bindings: the crate's one module with `unsafe`.
#[allow(unsafe_code)]
mod ffi;
pub mod pnp;
pub mod print;
mod regrid;
pub mod sharpness;
pub mod shrink;
pub mod target;
pub mod xcorner;

use std::path::{Path, PathBuf};

pub use board::{Board, BoardExtent, BoardTag};
pub use detect::{BoardDetection, DetectorOptions, RejectedTag, TagDetector, TagObservation};
pub use family::TagFamily;
pub use pnp::{estimate_board_pose, reproject, BoardPose};
pub use target::{Target, TargetDetector};

use handeye_core::camera_model::CameraModelError;

/// Everything that can go wrong between a board file, an image and `T_camera_target`.
#[derive(Debug, thiserror::Error)]
pub enum TargetError {
    /// A file could not be read or written.
    #[error("{path}: cannot read")]
    Io {
        /// The file.
        path: PathBuf,
        /// The I/O failure.
        #[source]
        source: std::io::Error,
    },
    /// The board YAML does not parse (syntax, unknown key, wrong type).
    // The serde error is the problem itself (no further cause), so it is in the message and
    // not also a `#[source]`: `{:#}` chains would print it twice.
    #[error("board file {path}: at `{key}`: {}", handeye_core::yaml_file::plain_parser_message(.problem))]
    BoardYaml {
        /// The file.
        path: PathBuf,
        /// The YAML path where parsing failed.
        key: String,
        /// The parser's error (in the message, so not a `#[source]`).
        problem: serde_yaml_ng::Error,
    },
    /// A board value is out of range.
    #[error("board file {path}: `{key}` must be {expected}, found {found}")]
    BadBoard {
        /// The file (or `<inline>`).
        path: PathBuf,
        /// The key.
        key: String,
        /// What was expected.
        expected: String,
        /// What was found.
        found: String,
    },
    /// An image file could not be read or decoded.
    #[error("image {path}: cannot read or decode")]
    Image {
        /// The file.
        path: PathBuf,
        /// The decoder's error.
        #[source]
        source: image::ImageError,
    },
    /// The memory a detector needs is not there (a limit such as `ulimit -v`).
    #[error(transparent)]
    Memory(#[from] handeye_core::memory::NotEnoughMemory),
    /// The AprilTag detector could not be created.
    #[error("AprilTag detector: {reason}")]
    Detector {
        /// Why.
        reason: String,
    },
    /// The image is too small for the AprilTag detector at its decimation: the C code would
    /// read outside its buffers.
    #[error(
        "image {width}x{height} px is too small for the AprilTag detector at decimation \
         {decimation}: each side must be at least {min_side_px} px"
    )]
    ImageTooSmall {
        /// Image width, px.
        width: u32,
        /// Image height, px.
        height: u32,
        /// The detector's decimation.
        decimation: f32,
        /// Smallest accepted side at this decimation, px.
        min_side_px: u32,
    },
    /// The detector thread is gone (it panicked or was shut down).
    #[error("AprilTag detector thread stopped unexpectedly")]
    DetectorStopped,
    /// The image size disagrees with the intrinsics.
    #[error(
        "image is {image_width}x{image_height} px but the intrinsics are for \
         {camera_width}x{camera_height} px"
    )]
    ImageSizeMismatch {
        /// Image width, px.
        image_width: u32,
        /// Image height, px.
        image_height: u32,
        /// Intrinsics width, px.
        camera_width: u32,
        /// Intrinsics height, px.
        camera_height: u32,
    },
    /// No tag of the board was found in the image.
    #[error("no tag of the board found in the image ({rejected} detections rejected)")]
    NoTagsFound {
        /// How many detections were rejected (wrong id, duplicate, hamming).
        rejected: usize,
    },
    /// A ChArUco board or chessboard was not found (or not completely enough to be labelled).
    #[error("{board} not found in the image: {reason}")]
    BoardNotFound {
        /// The board, in a few words.
        board: String,
        /// What the detector saw.
        reason: String,
    },
    /// Too few usable corners for a pose.
    #[error("board pose needs at least {required} corners, only {actual} usable")]
    NotEnoughCorners {
        /// Minimum.
        required: usize,
        /// Available.
        actual: usize,
    },
    /// The pose estimate failed numerically.
    #[error("board pose estimation failed: {reason}")]
    PoseFailed {
        /// Why.
        reason: &'static str,
    },
    /// The intrinsics file is unusable.
    #[error(transparent)]
    Camera(#[from] CameraModelError),
}

impl TargetError {
    /// Turns a board builder's `(key, expected, found)` into [`TargetError::BadBoard`] naming
    /// the board's source `path` (a file, or `<print>`).
    pub(crate) fn bad_board(path: &Path) -> impl Fn((String, String, String)) -> TargetError + '_ {
        move |(key, expected, found)| TargetError::BadBoard {
            path: path.to_path_buf(),
            key,
            expected,
            found,
        }
    }
}
