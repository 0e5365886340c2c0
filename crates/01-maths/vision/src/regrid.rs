//! The second pass of the AprilTag detection of a grid: where the tags found say a missing tag
//! must be, look again at full resolution.
//!
//! The first pass searches the whole frame for quads at the configured decimation (half
//! resolution by default). A small tag (far board, low-resolution camera) or a blurred one then
//! spans too few pixels of the quad-search image to form a quad, although its bits can still be
//! read. Once some tags are found, the grid says where every other one is: for each missing tag,
//! a homography fitted to the corners of the nearest found tags (nearest on the grid, so lens
//! distortion, which is smooth, hardly bends it) predicts its four corners; the region around them
//! is cut from the pre-filtered frame, enlarged 2× when the tag is small, and searched at full
//! resolution. A tag found there counts only with the expected id and only where it was
//! predicted (its centre within a third of its side): a misread id or a tag of another board is
//! not taken.

use image::{imageops, GrayImage};
use nalgebra::{Point2, Vector3};

use super::board::Board;
use super::ffi::DetectorHandle;
use handeye_core::geometry::homography::homography;

/// Found tags (at least) before the grid is trusted to predict the missing ones.
const MIN_FOUND: usize = 4;
/// Found tags, nearest on the grid, that a prediction is fitted to.
const NEIGHBOURS: usize = 6;
/// Tags with a predicted side below this (px) are searched at twice the resolution.
const ENLARGE_BELOW_PX: f64 = 48.0;
/// Predicted tags with a side below this (px) are not searched: too small to decode.
const MIN_SIDE_PX: f64 = 8.0;

/// The grid of a board: each tag's id, cell and corners on the board plane (m).
#[derive(Debug, Clone)]
pub(crate) struct Grid {
    tags: Vec<GridTag>,
}

#[derive(Debug, Clone)]
struct GridTag {
    id: u32,
    col: i64,
    row: i64,
    plane: [(f64, f64); 4],
}

/// A tag the second pass found: its id and corners (project pixel convention, AprilTag order),
/// with the detector's own figures.
#[derive(Debug, Clone)]
pub(crate) struct Refound {
    pub(crate) id: u32,
    pub(crate) hamming: u32,
    pub(crate) decision_margin: f32,
    pub(crate) corners_px: [Point2<f64>; 4],
}

impl Grid {
    /// The grid of an aprilgrid board.
    pub(crate) fn of(board: &Board) -> Grid {
        Grid {
            tags: board
                .tags()
                .iter()
                .map(|t| GridTag {
                    id: t.id,
                    col: i64::from(t.col),
                    row: i64::from(t.row),
                    plane: t.corners_in_target.map(|p| (p.x, p.y)),
                })
                .collect(),
        }
    }

    /// Searches again, at full resolution, where the `found` tags (id, corners in project
    /// pixels) say a missing tag is. `searched` is the pre-filtered frame the first pass
    /// searched; `to_project` converts the C library's corner pixels to the project's.
    pub(crate) fn refind(
        &self,
        detector: &mut DetectorHandle,
        searched: &GrayImage,
        found: &[(u32, [Point2<f64>; 4])],
        to_project: impl Fn([[f64; 2]; 4]) -> [Point2<f64>; 4],
    ) -> Vec<Refound> {
        let known: Vec<(&GridTag, &[Point2<f64>; 4])> = found
            .iter()
            .filter_map(|(id, corners)| {
                self.tags.iter().find(|t| t.id == *id).map(|t| (t, corners))
            })
            .collect();
        if known.len() < MIN_FOUND || known.len() == self.tags.len() {
            return Vec::new();
        }
        let mut refound = Vec::new();
        for missing in self
            .tags
            .iter()
            .filter(|t| !known.iter().any(|(k, _)| k.id == t.id))
        {
            let Some(predicted) = predict(missing, &known) else {
                continue;
            };
            if let Some(tag) = search(detector, searched, missing.id, &predicted, &to_project) {
                refound.push(tag);
            }
        }
        refound
    }
}

/// The missing tag's corners (px) by a homography fitted to the nearest found tags on the grid.
fn predict(missing: &GridTag, known: &[(&GridTag, &[Point2<f64>; 4])]) -> Option<[Point2<f64>; 4]> {
    let mut nearest: Vec<&(&GridTag, &[Point2<f64>; 4])> = known.iter().collect();
    nearest.sort_by_key(|(t, _)| {
        let (dc, dr) = (t.col - missing.col, t.row - missing.row);
        (dc * dc + dr * dr, t.id)
    });
    nearest.truncate(NEIGHBOURS);
    let plane: Vec<(f64, f64)> = nearest.iter().flat_map(|(t, _)| t.plane).collect();
    let pixels: Vec<Point2<f64>> = nearest
        .iter()
        .flat_map(|(_, c)| c.iter().copied())
        .collect();
    let h = homography(&plane, &pixels)?;
    let mut corners = [Point2::origin(); 4];
    for (corner, (x, y)) in corners.iter_mut().zip(missing.plane) {
        let p = h * Vector3::new(x, y, 1.0);
        if p.z.abs() < 1e-12 {
            return None;
        }
        *corner = Point2::new(p.x / p.z, p.y / p.z);
    }
    corners
        .iter()
        .all(|c| c.x.is_finite() && c.y.is_finite())
        .then_some(corners)
}

/// Searches the region around `predicted` (px) for tag `id` at full resolution.
fn search(
    detector: &mut DetectorHandle,
    searched: &GrayImage,
    id: u32,
    predicted: &[Point2<f64>; 4],
    to_project: impl Fn([[f64; 2]; 4]) -> [Point2<f64>; 4],
) -> Option<Refound> {
    let side = (0..4)
        .map(|k| (predicted[(k + 1) % 4] - predicted[k]).norm())
        .sum::<f64>()
        / 4.0;
    let (w, h) = (f64::from(searched.width()), f64::from(searched.height()));
    // Only tags wholly in the frame (the quad search needs the whole black border).
    let inside = predicted
        .iter()
        .all(|c| c.x >= 1.0 && c.y >= 1.0 && c.x <= w - 2.0 && c.y <= h - 2.0);
    if !inside || side < MIN_SIDE_PX || !side.is_finite() {
        return None;
    }
    // The tag and a margin of half its side each way: the white gap around it is inside.
    let margin = 0.5 * side;
    let (min_x, max_x) = predicted.iter().fold((f64::MAX, f64::MIN), |(lo, hi), c| {
        (lo.min(c.x), hi.max(c.x))
    });
    let (min_y, max_y) = predicted.iter().fold((f64::MAX, f64::MIN), |(lo, hi), c| {
        (lo.min(c.y), hi.max(c.y))
    });
    let x0 = (min_x - margin).floor().max(0.0) as u32;
    let y0 = (min_y - margin).floor().max(0.0) as u32;
    let x1 = ((max_x + margin).ceil() as u32).min(searched.width());
    let y1 = ((max_y + margin).ceil() as u32).min(searched.height());
    if x1 <= x0 || y1 <= y0 {
        return None;
    }
    let crop = imageops::crop_imm(searched, x0, y0, x1 - x0, y1 - y0).to_image();
    let scale = if side < ENLARGE_BELOW_PX { 2u32 } else { 1 };
    let crop = if scale == 1 {
        crop
    } else {
        imageops::resize(
            &crop,
            crop.width() * scale,
            crop.height() * scale,
            imageops::FilterType::Triangle,
        )
    };
    // A crop too small for the C detector's tiles is simply not searched.
    let mut tags = detector.detect_at(&crop, 1.0).ok()?;
    if !tags.iter().any(|t| t.id == id) {
        // Blur, more than size, loses a small tag's bits: once more with the crop sharpened (an
        // unsharp mask about one source pixel wide). Measured: the shared photos 384 → 385 of
        // 390 tags, the blurred 640x480 renders 272 → 274 of 576, no tag in the wrong place.
        let sharpened = imageops::unsharpen(&crop, scale as f32, 3);
        tags = detector.detect_at(&sharpened, 1.0).ok()?;
    }
    let s = f64::from(scale);
    let predicted_centre = centre(predicted);
    tags.into_iter()
        .filter(|t| t.id == id)
        .map(|t| {
            // Crop pixel (project convention) p is the frame's (p + 0.5) / s − 0.5 + offset.
            let corners = to_project(t.corners).map(|p| {
                Point2::new(
                    (p.x + 0.5) / s - 0.5 + f64::from(x0),
                    (p.y + 0.5) / s - 0.5 + f64::from(y0),
                )
            });
            (t, corners)
        })
        .find(|(_, corners)| (centre(corners) - predicted_centre).norm() < side / 3.0)
        .map(|(t, corners_px)| Refound {
            id,
            hamming: t.hamming,
            decision_margin: t.decision_margin,
            corners_px,
        })
}

fn centre(corners: &[Point2<f64>; 4]) -> Point2<f64> {
    Point2::from(
        corners
            .iter()
            .fold(nalgebra::Vector2::zeros(), |s, c| s + c.coords)
            / 4.0,
    )
}
