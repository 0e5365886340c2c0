//! The calibration target of a cell, whichever kind of board it is: a Kalibr aprilgrid
//! ([`Board`]), an OpenCV ChArUco board ([`Charuco`]) or a plain chessboard
//! ([`Checkerboard`]), chosen by the board file's `target_type` (`aprilgrid | charuco |
//! checkerboard`). Everything that needs a board's 3D points, its printed reflectance or its
//! detector goes through [`Target`] and [`TargetDetector`].
//!
//! Corner identity (the recorded `[id, sub, u, v]`, see `setup::CornerObservation`): for an
//! aprilgrid `id` is the tag and `sub` its corner 0..=3; for ChArUco and chessboards `id` is
//! the inner-corner index (OpenCV's ChArUco ids; row-major from the top-left for chessboards)
//! and `sub` is 0. Depends on `vision::{board, charuco, chessboard, detect}` and `setup`.

use std::path::{Path, PathBuf};

use image::GrayImage;
use nalgebra::{Point2, Point3};

use super::board::{Board, BoardExtent};
use super::charuco::{Charuco, CharucoCornerDetector, CharucoFile};
use super::chessboard::{Checkerboard, CheckerboardFile};
use super::detect::{BoardDetection, DetectorOptions, TagDetector};
use super::TargetError;
use handeye_core::setup::CornerObservation;
use handeye_core::yaml_file::{name_symlink_loop, MAX_TEXT_BYTES};

/// A calibration target.
#[derive(Debug, Clone)]
pub enum Target {
    /// A Kalibr aprilgrid (or a single AprilTag).
    Aprilgrid(Board),
    /// An OpenCV ChArUco board.
    Charuco(Charuco),
    /// A plain chessboard.
    Checkerboard(Checkerboard),
}

/// Anything that is a target or holds one: a [`Target`], or an aprilgrid [`Board`] (wrapped
/// on the fly), so functions taking a target also take the aprilgrid type.
pub trait AsTarget {
    /// The target.
    fn as_target(&self) -> std::borrow::Cow<'_, Target>;
}

impl AsTarget for Target {
    fn as_target(&self) -> std::borrow::Cow<'_, Target> {
        std::borrow::Cow::Borrowed(self)
    }
}

impl AsTarget for Board {
    fn as_target(&self) -> std::borrow::Cow<'_, Target> {
        std::borrow::Cow::Owned(Target::Aprilgrid(self.clone()))
    }
}

/// Only `target_type`, to pick the parser.
#[derive(serde::Deserialize)]
struct Kind {
    target_type: Option<String>,
}

/// Accepted `target_type` values.
pub const TARGET_TYPES: &str = "`aprilgrid`, `charuco` or `checkerboard`";

impl From<Board> for Target {
    fn from(board: Board) -> Self {
        Target::Aprilgrid(board)
    }
}

/// A board file's text, with the path (and a symbolic link loop in it) named in the error; a
/// file larger than any text file handeye reads ([`MAX_TEXT_BYTES`]) is refused, not read.
pub(crate) fn read_board_file(path: &Path) -> Result<String, TargetError> {
    use std::io::Read;
    let io = |source: std::io::Error| TargetError::Io {
        path: path.to_path_buf(),
        source: name_symlink_loop(path, source),
    };
    let mut text = String::new();
    std::fs::File::open(path)
        .map_err(io)?
        .take(MAX_TEXT_BYTES + 1)
        .read_to_string(&mut text)
        .map_err(io)?;
    if text.len() as u64 > MAX_TEXT_BYTES {
        return Err(io(std::io::Error::other(format!(
            "larger than {} MiB: not a board file",
            MAX_TEXT_BYTES >> 20
        ))));
    }
    Ok(text)
}

impl Target {
    /// Reads a board YAML file.
    pub fn load(path: &Path) -> Result<Self, TargetError> {
        Self::from_yaml_str(&read_board_file(path)?, path)
    }

    /// Parses board YAML text; `path` names the source in errors.
    pub fn from_yaml_str(text: &str, path: &Path) -> Result<Self, TargetError> {
        let kind: Kind = serde_yaml_ng::from_str(text).unwrap_or(Kind { target_type: None });
        let bad = TargetError::bad_board(path);
        match kind.target_type.as_deref() {
            Some("charuco") => Ok(Target::Charuco(
                parse::<CharucoFile>(text, path)?.build().map_err(bad)?,
            )),
            Some("checkerboard") => Ok(Target::Checkerboard(
                parse::<CheckerboardFile>(text, path)?
                    .build()
                    .map_err(bad)?,
            )),
            Some("aprilgrid") | None => Board::from_yaml_str(text, path).map(Target::Aprilgrid),
            Some(other) => Err(bad((
                "target_type".into(),
                TARGET_TYPES.into(),
                other.into(),
            ))),
        }
    }

    /// The aprilgrid, when the target is one.
    pub fn aprilgrid(&self) -> Option<&Board> {
        match self {
            Target::Aprilgrid(board) => Some(board),
            _ => None,
        }
    }

    /// The board's kind and size in a few words (for messages).
    pub fn describe(&self) -> String {
        match self {
            Target::Aprilgrid(b) => format!(
                "aprilgrid {}x{} {} tagSize {} m",
                b.cols(),
                b.rows(),
                b.family().name(),
                b.tag_size()
            ),
            Target::Charuco(c) => c.describe(),
            Target::Checkerboard(c) => c.describe(),
        }
    }

    /// The point `(id, sub)` in the target frame (m), `None` when the board has no such point.
    pub fn point(&self, id: u32, sub: u8) -> Option<Point3<f64>> {
        match self {
            Target::Aprilgrid(b) => b
                .tag_corners_in_target(id)
                .and_then(|c| c.get(sub as usize).copied()),
            Target::Charuco(c) => (sub == 0).then(|| c.corner(id)).flatten(),
            Target::Checkerboard(c) => (sub == 0).then(|| c.corner(id)).flatten(),
        }
    }

    /// The 3D point of a recorded corner observation.
    pub fn observation_point(&self, corner: &CornerObservation) -> Option<Point3<f64>> {
        self.point(corner.tag_id, corner.corner)
    }

    /// Every point of the board as `(id, sub, point)`.
    pub fn points(&self) -> Vec<(u32, u8, Point3<f64>)> {
        match self {
            Target::Aprilgrid(b) => b
                .tags()
                .iter()
                .flat_map(|t| (0u8..).zip(t.corners_in_target).map(|(s, p)| (t.id, s, p)))
                .collect(),
            Target::Charuco(c) => (0..c.corner_count())
                .filter_map(|id| Some((id, 0, c.corner(id)?)))
                .collect(),
            Target::Checkerboard(c) => (0..c.corner_count())
                .filter_map(|id| Some((id, 0, c.corner(id)?)))
                .collect(),
        }
    }

    /// The printed sheet's rectangle (m): the squares plus a white margin of half a square.
    pub fn extent(&self) -> BoardExtent {
        match self {
            Target::Aprilgrid(b) => b.extent(),
            Target::Charuco(c) => margin(c.squares_extent(), c.square_length() / 2.0),
            Target::Checkerboard(c) => margin(
                c.squares_extent(),
                c.col_spacing().min(c.row_spacing()) / 2.0,
            ),
        }
    }

    /// Printed reflectance at a point of the board plane (target frame, m): `Some(true)`
    /// white, `Some(false)` black, `None` off the sheet.
    pub fn is_white_at(&self, x: f64, y: f64) -> Option<bool> {
        let inside = |(min, max): (Point2<f64>, Point2<f64>)| {
            x >= min.x && x < max.x && y >= min.y && y < max.y
        };
        let e = self.extent();
        if !(x >= e.min.x && x < e.max.x && y >= e.min.y && y < e.max.y) {
            return None;
        }
        match self {
            Target::Aprilgrid(b) => b.is_white_at(x, y),
            Target::Charuco(c) => Some(!inside(c.squares_extent()) || c.square_is_white(x, y)),
            Target::Checkerboard(c) => Some(!inside(c.squares_extent()) || c.square_is_white(x, y)),
        }
    }

    /// `(point in target, pixel)` pairs of a detection's corners on this board.
    pub fn correspondences(&self, detection: &BoardDetection) -> Vec<(Point3<f64>, Point2<f64>)> {
        detection
            .observations()
            .iter()
            .filter_map(|o| Some((self.observation_point(o)?, o.pixel)))
            .collect()
    }
}

fn margin((min, max): (Point2<f64>, Point2<f64>), m: f64) -> BoardExtent {
    BoardExtent {
        min: Point2::new(min.x - m, min.y - m),
        max: Point2::new(max.x + m, max.y + m),
    }
}

fn parse<T: serde::de::DeserializeOwned>(text: &str, path: &Path) -> Result<T, TargetError> {
    let deserializer = serde_yaml_ng::Deserializer::from_str(text);
    serde_path_to_error::deserialize(deserializer).map_err(|error| TargetError::BoardYaml {
        path: PathBuf::from(path),
        key: error.path().to_string(),
        problem: error.into_inner(),
    })
}

/// Bytes per pixel the ChArUco and chessboard corner search holds at most (see
/// [`TargetDetector::memory_needed`]).
const CORNER_SEARCH_BYTES_PER_PIXEL: u64 = 32;

/// The detector of a target: the AprilTag detector thread for aprilgrids, the chessboard
/// corner detector for ChArUco boards and chessboards. `Send + Sync`.
#[derive(Debug)]
pub enum TargetDetector {
    /// AprilTags.
    Tags(Box<TagDetector>),
    /// ChArUco corners.
    Charuco(Box<CharucoCornerDetector>),
    /// Chessboard corners.
    Checkerboard(Checkerboard),
}

impl TargetDetector {
    /// Starts the detector for `target` (`options` apply to the AprilTag detector).
    pub fn spawn(
        target: &(impl AsTarget + ?Sized),
        options: DetectorOptions,
    ) -> Result<Self, TargetError> {
        Ok(match &*target.as_target() {
            Target::Aprilgrid(board) => {
                TargetDetector::Tags(Box::new(TagDetector::spawn(board, options)?))
            }
            Target::Charuco(board) => TargetDetector::Charuco(Box::new(board.detector()?)),
            Target::Checkerboard(board) => TargetDetector::Checkerboard(board.clone()),
        })
    }

    /// The memory one detector of `target` needs at most to detect a `width`x`height` frame,
    /// with the thread it runs on, bytes: what a check against the process's memory limits
    /// ([`handeye_core::memory`]) counts per detector thread.
    pub fn memory_needed(
        target: &(impl AsTarget + ?Sized),
        options: &DetectorOptions,
        width: u32,
        height: u32,
    ) -> u64 {
        match &*target.as_target() {
            Target::Aprilgrid(board) => {
                super::detect::tag_detector_bytes(board, options, width, height)
            }
            // The ChESS corner search's image pyramid and response maps (32-bit floats, a few
            // of them per pixel) on the worker's own thread.
            Target::Charuco(_) | Target::Checkerboard(_) => {
                CORNER_SEARCH_BYTES_PER_PIXEL * u64::from(width) * u64::from(height)
                    + super::detect::THREAD_STACK_BYTES
            }
        }
    }

    /// Detects the board in a grey image.
    pub fn detect(&self, image: &GrayImage) -> Result<BoardDetection, TargetError> {
        let points = match self {
            TargetDetector::Tags(detector) => return detector.detect(image),
            TargetDetector::Charuco(detector) => detector.detect(image)?,
            TargetDetector::Checkerboard(board) => board.detect(image)?,
        };
        Ok(BoardDetection {
            tags: Vec::new(),
            rejected: Vec::new(),
            points,
            image_width: image.width(),
            image_height: image.height(),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn target_type_picks_the_board_and_unknown_types_are_refused() {
        let p = Path::new("t.yaml");
        let charuco = "target_type: charuco\nsquaresX: 5\nsquaresY: 7\nsquareLength: 0.04\n\
                       markerLength: 0.03\ndictionary: DICT_4X4_50\n";
        assert!(matches!(
            Target::from_yaml_str(charuco, p).unwrap(),
            Target::Charuco(_)
        ));
        let chess = "target_type: checkerboard\ntargetCols: 9\ntargetRows: 6\n\
                     rowSpacingMeters: 0.0236\ncolSpacingMeters: 0.0236\n";
        assert!(matches!(
            Target::from_yaml_str(chess, p).unwrap(),
            Target::Checkerboard(_)
        ));
        let error = Target::from_yaml_str("target_type: circles\n", p).unwrap_err();
        assert!(error.to_string().contains("aprilgrid"), "{error}");
        let error =
            Target::from_yaml_str(&charuco.replace("DICT_4X4_50", "DICT_9X9_1"), p).unwrap_err();
        assert!(error.to_string().contains("DICT_ARUCO_ORIGINAL"), "{error}");
        let error = Target::from_yaml_str(&format!("{chess}extra: 1\n"), p).unwrap_err();
        assert!(error.to_string().contains("extra"), "{error}");
    }
}
