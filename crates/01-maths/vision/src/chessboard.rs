//! Plain chessboards (Kalibr's `target_type: checkerboard`): the board file keys, the corner
//! geometry in the target frame, the printed reflectance, and detection in an image — corners
//! labelled by the `calib-targets-chessboard` grid detector, refined to sub-pixel precision by
//! the saddle fit of [`super::xcorner`], and oriented from the board's colour asymmetry.
//!
//! Geometry: `targetCols x targetRows` inner corners, `colSpacingMeters` apart along x and
//! `rowSpacingMeters` along y; the printed board has one more square than inner corners on each
//! side. Corner ids run row-major from the top-left inner corner as the board is printed
//! (OpenCV's order): id `r·cols + c` sits at `(c·colSpacing, (rows - 1 - r)·rowSpacing, 0)`,
//! so the target frame's origin is the bottom-left inner corner, x to the right, y up, z out
//! of the printed face. The outer square diagonally beyond corner 0 (the top-left square) is
//! black, as in OpenCV's pattern.
//!
//! Orientation: a chessboard seen by a camera can be the right way up or turned by 180°; the
//! colours at its four corners tell which only when the square counts are odd x even (an
//! inner-corner count `cols + rows` odd). A board with `cols + rows` even looks the same
//! turned, so it is refused when the board file is read. Units: metres. Depends on
//! `vision::xcorner` and the `calib-targets-chessboard` crate.

use image::GrayImage;
use nalgebra::{Point2, Point3};

use rayon::prelude::*;

use super::xcorner;
use super::TargetError;

/// A plain chessboard with a known orientation.
#[derive(Debug, Clone, PartialEq)]
pub struct Checkerboard {
    cols: u32,
    rows: u32,
    col_spacing: f64,
    row_spacing: f64,
}

/// Board file keys of a checkerboard (Kalibr's names).
#[derive(Debug, Clone, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct CheckerboardFile {
    #[allow(dead_code)]
    target_type: String,
    #[serde(rename = "targetCols")]
    target_cols: u32,
    #[serde(rename = "targetRows")]
    target_rows: u32,
    #[serde(rename = "rowSpacingMeters")]
    row_spacing: f64,
    #[serde(rename = "colSpacingMeters")]
    col_spacing: f64,
}

impl CheckerboardFile {
    pub(crate) fn build(&self) -> Result<Checkerboard, (String, String, String)> {
        Checkerboard::new(
            self.target_cols,
            self.target_rows,
            self.col_spacing,
            self.row_spacing,
        )
    }
}

impl Checkerboard {
    /// Builds and validates a board of `cols x rows` inner corners. Errors are
    /// `(key, expected, found)`.
    pub fn new(
        cols: u32,
        rows: u32,
        col_spacing: f64,
        row_spacing: f64,
    ) -> Result<Self, (String, String, String)> {
        if cols < 2 || rows < 2 || cols > 100 || rows > 100 {
            return Err((
                "targetCols x targetRows".into(),
                "2 to 100 inner corners each way".into(),
                format!("{cols}x{rows}"),
            ));
        }
        if (cols + rows).is_multiple_of(2) {
            return Err((
                "targetCols x targetRows".into(),
                format!(
                    "an odd sum, so the board can be oriented: {cols}x{rows} inner corners \
                     ({}x{} squares) look the same turned by 180°, so a camera cannot tell \
                     which corner is the first — print a board with an odd number of squares \
                     one way and an even number the other (e.g. 9x6 inner corners, 10x7 squares)",
                    cols + 1,
                    rows + 1
                ),
                format!("{cols}x{rows}"),
            ));
        }
        for (key, value) in [
            ("colSpacingMeters", col_spacing),
            ("rowSpacingMeters", row_spacing),
        ] {
            if !(value.is_finite() && value > 0.0 && value < 1.0) {
                return Err((
                    key.into(),
                    "a square edge in metres, in (0, 1)".into(),
                    value.to_string(),
                ));
            }
        }
        Ok(Checkerboard {
            cols,
            rows,
            col_spacing,
            row_spacing,
        })
    }

    /// Inner corners along x.
    pub fn cols(&self) -> u32 {
        self.cols
    }

    /// Inner corners along y.
    pub fn rows(&self) -> u32 {
        self.rows
    }

    /// Square edge along x, m.
    pub fn col_spacing(&self) -> f64 {
        self.col_spacing
    }

    /// Square edge along y, m.
    pub fn row_spacing(&self) -> f64 {
        self.row_spacing
    }

    /// Number of inner corners.
    pub fn corner_count(&self) -> u32 {
        self.cols * self.rows
    }

    /// Corner `id` in the target frame (m).
    pub fn corner(&self, id: u32) -> Option<Point3<f64>> {
        if id >= self.corner_count() {
            return None;
        }
        let (c, r) = (id % self.cols, id / self.cols);
        Some(Point3::new(
            c as f64 * self.col_spacing,
            (self.rows - 1 - r) as f64 * self.row_spacing,
            0.0,
        ))
    }

    /// The squares' rectangle (m): one square beyond the outer inner corners.
    pub fn squares_extent(&self) -> (Point2<f64>, Point2<f64>) {
        (
            Point2::new(-self.col_spacing, -self.row_spacing),
            Point2::new(
                self.cols as f64 * self.col_spacing,
                self.rows as f64 * self.row_spacing,
            ),
        )
    }

    /// Colour of the square at a point inside [`Self::squares_extent`]: `false` black.
    pub fn square_is_white(&self, x: f64, y: f64) -> bool {
        let i = ((x + self.col_spacing) / self.col_spacing).floor() as i64;
        let j_top = ((self.rows as f64 * self.row_spacing - y) / self.row_spacing).floor() as i64;
        (i + j_top).rem_euclid(2) == 1
    }

    /// Finds the board's corners in `image`: `(id, pixel)` by id. The whole board must be in
    /// view (a chessboard without markers cannot say which part of it a partial view shows).
    pub fn detect(&self, image: &GrayImage) -> Result<Vec<(u32, Point2<f64>)>, TargetError> {
        let not_found = |reason: String| TargetError::BoardNotFound {
            board: self.describe(),
            reason,
        };
        let view = calib_targets_chessboard::GrayImageView {
            width: image.width() as usize,
            height: image.height() as usize,
            data: image.as_raw(),
        };
        let frame = calib_targets_chessboard::detect_corner_frame(&view, &corner_search());
        let params = calib_targets_chessboard::ChessboardParams::default();
        let detector = calib_targets_chessboard::ChessboardDetector::new(params).map_err(|e| {
            TargetError::Detector {
                reason: e.to_string(),
            }
        })?;
        let Some(grid) = detector.detect(&frame.corners) else {
            return Err(not_found("no chessboard grid in the image".into()));
        };
        let expected = self.corner_count() as usize;
        if grid.corners.len() != expected {
            return Err(not_found(format!(
                "{} of the {expected} inner corners seen: the whole board must be in view",
                grid.corners.len()
            )));
        }
        let u0 = grid.corners.iter().map(|c| c.grid.u).min().unwrap_or(0);
        let v0 = grid.corners.iter().map(|c| c.grid.v).min().unwrap_or(0);
        let u_span = grid
            .corners
            .iter()
            .map(|c| c.grid.u - u0)
            .max()
            .unwrap_or(0) as u32
            + 1;
        let v_span = grid
            .corners
            .iter()
            .map(|c| c.grid.v - v0)
            .max()
            .unwrap_or(0) as u32
            + 1;
        let mut by_uv = vec![None; expected];
        for c in &grid.corners {
            let (u, v) = ((c.grid.u - u0) as u32, (c.grid.v - v0) as u32);
            if u < u_span && v < v_span {
                by_uv[(v * u_span + u) as usize] =
                    Some(Point2::new(c.position.x as f64, c.position.y as f64));
            }
        }
        // The grid as detected is the board turned by a multiple of 90° in the image; its
        // spans settle 0/180 against 90/270 (cols != rows always: cols + rows is odd).
        let transposed = if (u_span, v_span) == (self.cols, self.rows) {
            false
        } else if (u_span, v_span) == (self.rows, self.cols) {
            true
        } else {
            return Err(not_found(format!(
                "a {u_span}x{v_span} corner grid, not the board's {}x{}",
                self.cols, self.rows
            )));
        };
        // (c, r) -> detected (u, v) for the two candidate orientations.
        let lookup = |c: u32, r: u32, turned: bool| -> Option<Point2<f64>> {
            let (c, r) = if turned {
                (self.cols - 1 - c, self.rows - 1 - r)
            } else {
                (c, r)
            };
            let (u, v) = if transposed {
                (self.rows - 1 - r, c)
            } else {
                (c, r)
            };
            by_uv[(v * u_span + u) as usize]
        };
        // The outer square beyond corner 0 is black; beyond the last corner it is white.
        let darkness = |turned: bool| -> Option<f64> {
            let outer = |c0: u32, r0: u32, c1: u32, r1: u32| -> Option<f64> {
                let p0 = lookup(c0, r0, turned)?;
                let p1 = lookup(c1, r1, turned)?;
                let centre = p0 + (p0 - p1) * 0.5;
                mean_around(image, centre)
            };
            let first = outer(0, 0, 1, 1)?;
            let last = outer(self.cols - 1, self.rows - 1, self.cols - 2, self.rows - 2)?;
            Some(last - first)
        };
        let (straight, turned) = (darkness(false), darkness(true));
        let turned = match (straight, turned) {
            (Some(a), Some(b)) if a > b => false,
            (Some(_), Some(_)) => true,
            (Some(_), None) => false,
            (None, Some(_)) => true,
            (None, None) => {
                return Err(not_found(
                    "the board's outer squares are outside the image: it cannot be oriented".into(),
                ))
            }
        };
        let mut corners = Vec::with_capacity(expected);
        for id in 0..self.corner_count() {
            let (c, r) = (id % self.cols, id / self.cols);
            let pixel = lookup(c, r, turned).ok_or_else(|| not_found("grid hole".into()))?;
            corners.push((id, pixel));
        }
        let spacing = |a: Point2<f64>, b: Point2<f64>| (a - b).norm();
        let cell_px: Vec<f64> = corners
            .iter()
            .map(|(id, p)| {
                let (c, r) = (id % self.cols, id / self.cols);
                let neighbour = if c + 1 < self.cols { id + 1 } else { id - 1 };
                let below = if r + 1 < self.rows {
                    id + self.cols
                } else {
                    id - self.cols
                };
                spacing(*p, corners[neighbour as usize].1)
                    .min(spacing(*p, corners[below as usize].1))
            })
            .collect();
        // Each corner on its own: in parallel, on the pool the corner search ran on.
        corners
            .par_iter_mut()
            .zip(cell_px.par_iter())
            .for_each(|((_, pixel), &cell)| {
                // A chessboard's squares are plain up to the next corner: half a square clear.
                if let Some(refined) = xcorner::refine_grid_corner(image, *pixel, cell, 0.5) {
                    *pixel = refined;
                }
            });
        Ok(corners)
    }

    /// `checkerboard 9x6 inner corners, 0.0236 x 0.0236 m`.
    pub fn describe(&self) -> String {
        format!(
            "checkerboard {}x{} inner corners, {} x {} m squares",
            self.cols, self.rows, self.col_spacing, self.row_spacing
        )
    }
}

/// The ChESS corner search of the `calib-targets` crates (ChArUco and chessboards), coarse to
/// fine: the ChESS response — most of the detection time at full resolution — is computed on a
/// half-resolution copy, and each corner found there is located again in the full frame within
/// [`PYRAMID_REFINE_RADIUS`] px of the copy (2x that in the frame). The corners are refined to
/// sub-pixel precision by `vision::xcorner` afterwards either way. Two levels, not the crate's
/// three: at a quarter of the resolution the bench's ChArUco board (squares ~50 px across in
/// the 1280x720 frame) is no longer found.
pub(crate) fn corner_search() -> calib_targets_chessboard::DetectorConfig {
    let mut config = calib_targets_chessboard::default_chess_config();
    config.multiscale = chess_corners::MultiscaleConfig::pyramid(
        PYRAMID_LEVELS,
        PYRAMID_MIN_SIDE_PX,
        PYRAMID_REFINE_RADIUS,
    );
    config
}

/// Levels of the corner search's pyramid (full resolution and half).
const PYRAMID_LEVELS: u8 = 2;
/// The pyramid stops before a level whose shorter side would be under this, px (the crate's
/// default): a small image is searched at full resolution.
const PYRAMID_MIN_SIDE_PX: usize = 128;
/// Search radius around each coarse corner, coarse px (the crate's default).
const PYRAMID_REFINE_RADIUS: u32 = 3;

/// Mean grey level in a 5x5 window around `centre`, `None` outside the image.
pub(crate) fn mean_around(image: &GrayImage, centre: Point2<f64>) -> Option<f64> {
    let (x, y) = (centre.x.round() as i64, centre.y.round() as i64);
    let (w, h) = (image.width() as i64, image.height() as i64);
    if x < 2 || y < 2 || x + 2 >= w || y + 2 >= h {
        return None;
    }
    let mut sum = 0.0;
    for dy in -2..=2 {
        for dx in -2..=2 {
            sum += f64::from(image.get_pixel((x + dx) as u32, (y + dy) as u32)[0]);
        }
    }
    Some(sum / 25.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn corner_ids_run_row_major_from_the_top_left() {
        let board = Checkerboard::new(9, 6, 0.03, 0.02).unwrap();
        assert_eq!(board.corner(0).unwrap(), Point3::new(0.0, 0.1, 0.0));
        assert_eq!(board.corner(8).unwrap(), Point3::new(0.24, 0.1, 0.0));
        assert_eq!(board.corner(53).unwrap(), Point3::new(0.24, 0.0, 0.0));
        assert!(board.corner(54).is_none());
        // Top-left outer square black, top-right white (10 squares across).
        assert!(!board.square_is_white(-0.01, 0.11));
        assert!(board.square_is_white(0.25, 0.11));
        assert!(!board.square_is_white(-0.01, -0.01));
    }

    #[test]
    fn a_symmetric_board_is_refused_naming_the_fix() {
        let (key, expected, found) = Checkerboard::new(8, 6, 0.03, 0.03).unwrap_err();
        assert_eq!(key, "targetCols x targetRows");
        assert_eq!(found, "8x6");
        assert!(expected.contains("180°"), "{expected}");
        assert!(Checkerboard::new(7, 7, 0.03, 0.03).is_err());
    }
}
