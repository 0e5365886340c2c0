//! ChArUco boards as OpenCV defines them (`cv2.aruco.CharucoBoard`, the board MoveIt
//! Calibration and most OpenCV users print): the board file keys (OpenCV's constructor names),
//! the corner geometry in the target frame, the printed reflectance (chessboard squares and
//! ArUco markers, for the simulated camera), and detection: markers decoded and chessboard
//! corners labelled by the `calib-targets-charuco` crate (its dictionaries are OpenCV's bit
//! tables; partial views are labelled by the markers the view shows), then refined to sub-pixel precision by the saddle fit of [`super::xcorner`].
//!
//! Geometry: `squaresX x squaresY` squares of `squareLength`, the top-left square black
//! (OpenCV ≥ 4.6), a marker of `markerLength` centred in every white square, marker ids
//! row-major over the white squares from the top-left. Chessboard corner ids are OpenCV's:
//! row-major from the top-left inner corner, `(squaresX - 1)` per row. Target frame: origin at
//! the bottom-left outer corner of the squares, x to the right, y up, z out of the printed
//! face; corner `k` (column `c = k mod (squaresX - 1)`, row `r` from the top) sits at
//! `((c + 1)·squareLength, (squaresY - 1 - r)·squareLength, 0)`. Units: metres. Depends on
//! `vision::xcorner` and the `calib-targets-charuco` crate.

use image::GrayImage;
use nalgebra::{Point2, Point3};

use calib_targets_charuco::{
    builtins::BUILTIN_DICTIONARY_NAMES, resolve_dictionary, CharucoBoardSpec, CharucoDetector,
    CharucoParams, Dictionary,
};

use super::TargetError;
use rayon::prelude::*;

use super::xcorner;
use handeye_core::geometry::homography::homography;

/// The crate's ChESS strength floor for grid corners (its ChArUco default is 33): 20 keeps
/// the corners of a board seen at 0.8 m under 35° of tilt.
const MIN_CORNER_STRENGTH: f32 = 20.0;

/// Dictionaries a board file may name (OpenCV's names).
pub fn dictionary_names() -> Vec<&'static str> {
    BUILTIN_DICTIONARY_NAMES
        .iter()
        .copied()
        .filter(|n| n.starts_with("DICT_") && !n.contains("APRILTAG") && !n.contains("MIP"))
        .collect()
}

/// A ChArUco board.
#[derive(Debug, Clone)]
pub struct Charuco {
    squares_x: u32,
    squares_y: u32,
    square_length: f64,
    marker_length: f64,
    dictionary: Dictionary,
    /// Marker id of each square, row-major from the top-left (`None`: black square).
    marker_at: Vec<Option<u32>>,
}

impl PartialEq for Charuco {
    fn eq(&self, other: &Self) -> bool {
        (
            self.squares_x,
            self.squares_y,
            self.square_length,
            self.marker_length,
            self.dictionary.name(),
        ) == (
            other.squares_x,
            other.squares_y,
            other.square_length,
            other.marker_length,
            other.dictionary.name(),
        )
    }
}

/// Board file keys of a ChArUco board (OpenCV's constructor names).
#[derive(Debug, Clone, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct CharucoFile {
    #[allow(dead_code)]
    target_type: String,
    #[serde(rename = "squaresX")]
    squares_x: u32,
    #[serde(rename = "squaresY")]
    squares_y: u32,
    #[serde(rename = "squareLength")]
    square_length: f64,
    #[serde(rename = "markerLength")]
    marker_length: f64,
    dictionary: String,
    #[serde(rename = "legacyPattern", default)]
    legacy_pattern: bool,
}

impl CharucoFile {
    pub(crate) fn build(&self) -> Result<Charuco, (String, String, String)> {
        Charuco::new(
            self.squares_x,
            self.squares_y,
            self.square_length,
            self.marker_length,
            &self.dictionary,
            self.legacy_pattern,
        )
    }
}

impl Charuco {
    /// Builds and validates a board. Errors are `(key, expected, found)`.
    pub fn new(
        squares_x: u32,
        squares_y: u32,
        square_length: f64,
        marker_length: f64,
        dictionary: &str,
        legacy_pattern: bool,
    ) -> Result<Self, (String, String, String)> {
        let err = |k: &str, e: String, f: String| Err((k.to_string(), e, f));
        if !(2..=100).contains(&squares_x) || !(2..=100).contains(&squares_y) {
            return err(
                "squaresX x squaresY",
                "2 to 100 squares each way".into(),
                format!("{squares_x}x{squares_y}"),
            );
        }
        if !(square_length.is_finite() && square_length > 0.0 && square_length < 1.0) {
            return err(
                "squareLength",
                "a square edge in metres, in (0, 1)".into(),
                square_length.to_string(),
            );
        }
        if !(marker_length.is_finite() && marker_length > 0.0 && marker_length < square_length) {
            return err(
                "markerLength",
                format!("a marker edge in metres, in (0, squareLength = {square_length})"),
                marker_length.to_string(),
            );
        }
        let known = dictionary_names();
        let Some(dict) = known
            .contains(&dictionary)
            .then(|| resolve_dictionary(dictionary))
            .flatten()
        else {
            return err(
                "dictionary",
                format!("one of OpenCV's names: {}", known.join(", ")),
                dictionary.to_string(),
            );
        };
        if legacy_pattern && squares_y.is_multiple_of(2) {
            return err(
                "legacyPattern",
                "false for a board with an even squaresY: OpenCV's legacy pattern (before 4.6) \
                 then starts with a white square, which this detector does not read — print \
                 the board with OpenCV ≥ 4.6 (legacyPattern is the same for an odd squaresY)"
                    .into(),
                "true".into(),
            );
        }
        let mut marker_at = Vec::with_capacity((squares_x * squares_y) as usize);
        let mut next = 0u32;
        for j in 0..squares_y {
            for i in 0..squares_x {
                if (i + j) % 2 == 1 {
                    marker_at.push(Some(next));
                    next += 1;
                } else {
                    marker_at.push(None);
                }
            }
        }
        if next as usize > dict.codes().len() {
            return err(
                "dictionary",
                format!(
                    "a dictionary with at least {next} markers for {squares_x}x{squares_y} squares"
                ),
                format!("{dictionary} ({} markers)", dict.codes().len()),
            );
        }
        Ok(Charuco {
            squares_x,
            squares_y,
            square_length,
            marker_length,
            dictionary: dict,
            marker_at,
        })
    }

    /// Squares along x.
    pub fn squares_x(&self) -> u32 {
        self.squares_x
    }

    /// Squares along y.
    pub fn squares_y(&self) -> u32 {
        self.squares_y
    }

    /// Square edge, m.
    pub fn square_length(&self) -> f64 {
        self.square_length
    }

    /// Marker edge, m.
    pub fn marker_length(&self) -> f64 {
        self.marker_length
    }

    /// The white gap between a chessboard corner and the nearest marker, as a share of the
    /// square's side: a corner's refinement window and X-junction ring stay inside it.
    fn gap_ratio(&self) -> f64 {
        (self.square_length - self.marker_length) / (2.0 * self.square_length)
    }

    /// Cells across a marker: its bits plus the one-cell black border.
    pub fn marker_cells(&self) -> u32 {
        self.dictionary.marker_size() as u32 + 2
    }

    /// The dictionary's OpenCV name.
    pub fn dictionary_name(&self) -> &'static str {
        self.dictionary.name()
    }

    /// Number of chessboard (inner) corners.
    pub fn corner_count(&self) -> u32 {
        (self.squares_x - 1) * (self.squares_y - 1)
    }

    /// Chessboard corner `id` (OpenCV's numbering) in the target frame (m).
    pub fn corner(&self, id: u32) -> Option<Point3<f64>> {
        if id >= self.corner_count() {
            return None;
        }
        let per_row = self.squares_x - 1;
        let (c, r) = (id % per_row, id / per_row);
        Some(Point3::new(
            (c + 1) as f64 * self.square_length,
            (self.squares_y - 1 - r) as f64 * self.square_length,
            0.0,
        ))
    }

    /// The squares' rectangle (m).
    pub fn squares_extent(&self) -> (Point2<f64>, Point2<f64>) {
        (
            Point2::origin(),
            Point2::new(
                self.squares_x as f64 * self.square_length,
                self.squares_y as f64 * self.square_length,
            ),
        )
    }

    /// Printed colour at a point inside [`Self::squares_extent`]: `false` black.
    pub fn square_is_white(&self, x: f64, y: f64) -> bool {
        let s = self.square_length;
        let i = (x / s).floor().clamp(0.0, (self.squares_x - 1) as f64) as u32;
        let j_top = self.squares_y as i64 - 1 - (y / s).floor() as i64;
        let j_top = j_top.clamp(0, self.squares_y as i64 - 1) as u32;
        let Some(id) = self.marker_at[(j_top * self.squares_x + i) as usize] else {
            return false;
        };
        // Position inside the square from its top-left corner, y down.
        let lx = x - i as f64 * s;
        let ly = (self.squares_y - j_top) as f64 * s - y;
        let off = (s - self.marker_length) / 2.0;
        let n = self.dictionary.marker_size() as i64;
        let cells = n + 2; // one-cell black border, as OpenCV's default
        let cell = self.marker_length / cells as f64;
        let cx = ((lx - off) / cell).floor() as i64;
        let cy = ((ly - off) / cell).floor() as i64;
        if cx < 0 || cy < 0 || cx >= cells || cy >= cells {
            return true;
        }
        if cx == 0 || cy == 0 || cx == cells - 1 || cy == cells - 1 {
            return false;
        }
        let code = self.dictionary.codes()[id as usize];
        let bit = (code >> ((cy - 1) * n + (cx - 1))) & 1;
        bit == 0
    }

    /// The detector for this board (built once per camera: it holds the crate's tables).
    pub fn detector(&self) -> Result<CharucoCornerDetector, TargetError> {
        let spec = CharucoBoardSpec::new(
            self.squares_y,
            self.squares_x,
            self.square_length as f32,
            (self.marker_length / self.square_length) as f32,
            self.dictionary,
        );
        let mut params = CharucoParams::for_board(spec);
        params.chessboard.min_corner_strength = MIN_CORNER_STRENGTH;
        params.chess = super::chessboard::corner_search();
        let detector = CharucoDetector::new(params).map_err(|e| TargetError::Detector {
            reason: format!("ChArUco board: {e}"),
        })?;
        Ok(CharucoCornerDetector {
            board: self.clone(),
            detector,
        })
    }

    /// `charuco 9x6 squares, 0.035 m, markers 0.026 m, DICT_5X5_100`.
    pub fn describe(&self) -> String {
        format!(
            "charuco {}x{} squares of {} m, markers {} m, {}",
            self.squares_x,
            self.squares_y,
            self.square_length,
            self.marker_length,
            self.dictionary.name()
        )
    }
}

/// A ChArUco detector for one board.
pub struct CharucoCornerDetector {
    board: Charuco,
    detector: CharucoDetector,
}

impl std::fmt::Debug for CharucoCornerDetector {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("CharucoCornerDetector")
            .field("board", &self.board.describe())
            .finish()
    }
}

impl CharucoCornerDetector {
    /// Finds the board's chessboard corners in `image`: `(id, pixel)` by id.
    pub fn detect(&self, image: &GrayImage) -> Result<Vec<(u32, Point2<f64>)>, TargetError> {
        let view = calib_targets_charuco::GrayImageView {
            width: image.width() as usize,
            height: image.height() as usize,
            data: image.as_raw(),
        };
        let detection = self
            .detector
            .detect(&view)
            .map_err(|e| TargetError::BoardNotFound {
                board: self.board.describe(),
                reason: e.to_string(),
            })?;
        // Every labelled corner is kept: the crate labels the chessboard grid as a whole and
        // aligns it to the board by the decoded markers, so a corner needs the grid around it,
        // not its own two markers decoded (requiring both, as OpenCV does, kept 41 % of the
        // visible corners on OpenCV-rendered frames; the ids were right either way).
        let mut corners: Vec<(u32, Point2<f64>)> = detection
            .corners
            .iter()
            .filter(|c| c.id < self.board.corner_count())
            .map(|c| (c.id, Point2::new(c.position.x as f64, c.position.y as f64)))
            .collect();
        corners.sort_by_key(|(id, _)| *id);
        corners.dedup_by_key(|(id, _)| *id);
        if corners.is_empty() {
            return Err(TargetError::BoardNotFound {
                board: self.board.describe(),
                reason: "no chessboard corner labelled".into(),
            });
        }
        // The grid grows by up to two squares a pass.
        for _ in 0..3 {
            if !self.complete(image, &mut corners) {
                break;
            }
        }
        // The window must stay inside the white gap between the corner and the markers: a
        // marker's border is an edge that does not pass through the corner.
        let gap = self.board.gap_ratio();
        let by_id: std::collections::HashMap<u32, Point2<f64>> = corners.iter().copied().collect();
        let per_row = self.board.squares_x - 1;
        // Each corner on its own: in parallel, on the pool the corner search ran on.
        corners.par_iter_mut().for_each(|(id, pixel)| {
            let neighbours = [
                id.checked_sub(1).filter(|_| *id % per_row != 0),
                Some(*id + 1).filter(|n| n % per_row != 0),
                id.checked_sub(per_row),
                Some(*id + per_row),
            ];
            let step = |a: Option<u32>, b: Option<u32>| -> Option<nalgebra::Vector2<f64>> {
                let towards = |n: Option<u32>| n.and_then(|n| by_id.get(&n));
                match (towards(b), towards(a)) {
                    (Some(p), _) => Some(p - *pixel),
                    (None, Some(p)) => Some(*pixel - p),
                    _ => None,
                }
            };
            // Pixel steps to the next corner along the row and down the column.
            let (Some(along), Some(down)) = (
                step(neighbours[0], neighbours[1]),
                step(neighbours[2], neighbours[3]),
            ) else {
                return;
            };
            let square_px = along.norm().min(down.norm());
            if let Some(refined) = xcorner::refine_grid_corner(image, *pixel, square_px, gap) {
                *pixel = refined;
            }
        });
        Ok(corners)
    }
}

impl CharucoCornerDetector {
    /// Adds corners the grid detector missed: each board corner without a pixel is predicted
    /// from a homography of its nearest labelled corners (local, so lens distortion does not
    /// matter), refined, and kept when the refinement settles on an X-corner near the
    /// prediction.
    fn complete(&self, image: &GrayImage, corners: &mut Vec<(u32, Point2<f64>)>) -> bool {
        if corners.len() < 6 {
            return false;
        }
        let s = self.board.square_length;
        let gap = self.board.gap_ratio();
        let plane = |id: u32| -> Option<Point2<f64>> {
            let p = self.board.corner(id)?;
            Some(Point2::new(p.x / s, p.y / s))
        };
        let known: std::collections::HashSet<u32> = corners.iter().map(|(id, _)| *id).collect();
        let labelled: Vec<(Point2<f64>, Point2<f64>)> = corners
            .iter()
            .filter_map(|(id, px)| Some((plane(*id)?, *px)))
            .collect();
        let mut added = Vec::new();
        for id in 0..self.board.corner_count() {
            if known.contains(&id) {
                continue;
            }
            let Some(b) = plane(id) else { continue };
            let mut nearest: Vec<&(Point2<f64>, Point2<f64>)> = labelled.iter().collect();
            nearest.sort_by(|x, y| (x.0 - b).norm().total_cmp(&(y.0 - b).norm()));
            nearest.truncate(8);
            // Only next to the labelled grid: at most two squares away.
            if nearest.first().is_none_or(|n| (n.0 - b).norm() > 2.01) {
                continue;
            }
            let plane_points: Vec<(f64, f64)> = nearest.iter().map(|(b, _)| (b.x, b.y)).collect();
            let pixels: Vec<Point2<f64>> = nearest.iter().map(|(_, px)| *px).collect();
            let Some(h) = homography(&plane_points, &pixels) else {
                continue;
            };
            let project = |p: Point2<f64>| -> Option<Point2<f64>> {
                let q = h * nalgebra::Vector3::new(p.x, p.y, 1.0);
                (q.z.abs() > 1e-12).then(|| Point2::new(q.x / q.z, q.y / q.z))
            };
            let (Some(predicted), Some(right), Some(up)) = (
                project(b),
                project(b + nalgebra::Vector2::new(1.0, 0.0)),
                project(b + nalgebra::Vector2::new(0.0, 1.0)),
            ) else {
                continue;
            };
            let (along, down) = (right - predicted, up - predicted);
            let square_px = along.norm().min(down.norm());
            if square_px < 8.0 {
                continue;
            }
            if let Some(found) = xcorner::refine_grid_corner(image, predicted, square_px, gap) {
                if (found - predicted).norm() < 0.1 * square_px
                    && xcorner::is_x_junction(
                        image,
                        found,
                        X_CORNER_RING * gap * square_px,
                        X_CORNER_CONTRAST,
                    )
                {
                    added.push((id, found));
                }
            }
        }
        let grew = !added.is_empty();
        corners.extend(added);
        corners.sort_by_key(|(id, _)| *id);
        grew
    }
}

/// Radius of the ring on which a completed corner must look like an X-junction, in units of
/// the white gap between a corner and the markers (times the square's pixel size): 0.85 of the
/// gap keeps every ring sample inside the four squares' corner regions, clear of the markers.
const X_CORNER_RING: f64 = 0.85;
/// Smallest grey-level difference between the light and dark squares around a completed corner.
const X_CORNER_CONTRAST: f64 = 20.0;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_unknown_dictionary_lists_the_accepted_names() {
        let (key, expected, found) =
            Charuco::new(5, 7, 0.04, 0.03, "DICT_5X5_99", false).unwrap_err();
        assert_eq!(
            (key.as_str(), found.as_str()),
            ("dictionary", "DICT_5X5_99")
        );
        for name in [
            "DICT_4X4_50",
            "DICT_4X4_1000",
            "DICT_5X5_100",
            "DICT_6X6_250",
            "DICT_ARUCO_ORIGINAL",
        ] {
            assert!(expected.contains(name), "{expected}");
        }
    }

    #[test]
    fn corners_follow_opencv_numbering_in_a_y_up_frame() {
        let board = Charuco::new(5, 7, 0.04, 0.03, "DICT_4X4_50", false).unwrap();
        assert_eq!(board.corner_count(), 24);
        // Corner 0: right of the top-left square, below it.
        let p = board.corner(0).unwrap();
        assert!((p - Point3::new(0.04, 0.24, 0.0)).norm() < 1e-12);
        let p = board.corner(23).unwrap();
        assert!((p - Point3::new(0.16, 0.04, 0.0)).norm() < 1e-12);
        // Top-left square black; the one right of it white paper around marker 0.
        assert!(!board.square_is_white(0.02, 0.27));
        assert!(board.square_is_white(0.041, 0.279));
        // Marker 0's border ring.
        assert!(!board.square_is_white(0.046, 0.274));
    }
}
