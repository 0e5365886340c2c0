//! The board specification: a Kalibr-compatible AprilTag grid read from YAML, its geometry in
//! the target frame, and the printed reflectance the renderer samples.
//!
//! Board frame (`target`): origin at the outer bottom-left corner of tag 0's black (border)
//! square; x along a row of tags, y up, z out of the printed face (right-handed). Tag `k`
//! (id `first_id + k`) sits at column `k % tagCols`, row `k / tagCols`, its border square's
//! bottom-left corner at `(col, row) · pitch`, `pitch = tagSize · (1 + tagSpacing)`. Tags are
//! printed upright (the tag image's top row towards +y). Corner order follows the AprilTag
//! library: bottom-left, bottom-right, top-right, top-left (counter-clockwise seen from +z).
//! Kalibr's corner squares (key `corner_squares`, default `true` like `kalibr_create_target_pdf`)
//! fill the gap at every tag corner, so each tag corner is an X-junction.
//! Units: metres. Depends on `vision::family` only.

use std::path::{Path, PathBuf};

use nalgebra::{Point2, Point3};
use serde::Deserialize;

use super::family::{FamilyLayout, TagFamily};
use super::target::read_board_file;
use super::TargetError;

/// The board YAML: Kalibr's aprilgrid keys plus ours; anything else is refused.
#[derive(Debug, Clone, Deserialize)]
#[serde(
    deny_unknown_fields,
    expecting = "a board mapping (Kalibr aprilgrid keys: target_type, tagCols, tagRows, tagSize, tagSpacing)"
)]
struct BoardFile {
    target_type: String,
    #[serde(rename = "tagCols")]
    tag_cols: u32,
    #[serde(rename = "tagRows")]
    tag_rows: u32,
    #[serde(rename = "tagSize")]
    tag_size: f64,
    #[serde(rename = "tagSpacing")]
    tag_spacing: f64,
    #[serde(default)]
    family: TagFamily,
    #[serde(default)]
    first_id: u32,
    /// Kalibr prints 2-cell borders and its files carry no border key, so 2 is the default.
    #[serde(default = "kalibr_border_bits")]
    border_bits: u32,
    /// Kalibr's PDF draws a black square of side `tagSpacing·tagSize` at every tag corner and
    /// its files carry no key for it, so the squares are there unless a file says `false`.
    #[serde(default)]
    corner_squares: Option<bool>,
}

fn kalibr_border_bits() -> u32 {
    2
}

/// One tag of the board.
#[derive(Debug, Clone, PartialEq)]
pub struct BoardTag {
    /// The tag id.
    pub id: u32,
    /// Column (along x), from 0.
    pub col: u32,
    /// Row (along y), from 0.
    pub row: u32,
    /// Border-square corners in the target frame (m), AprilTag order: bottom-left,
    /// bottom-right, top-right, top-left.
    pub corners_in_target: [Point3<f64>; 4],
}

/// The rectangle of the printed sheet in the target frame (m), z = 0.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BoardExtent {
    /// Bottom-left corner.
    pub min: Point2<f64>,
    /// Top-right corner.
    pub max: Point2<f64>,
}

/// An AprilTag grid board (a single tag is a 1x1 grid).
#[derive(Debug, Clone)]
pub struct Board {
    cols: u32,
    rows: u32,
    tag_size: f64,
    tag_spacing: f64,
    family: TagFamily,
    first_id: u32,
    border_bits: u32,
    layout: FamilyLayout,
    corner_squares: bool,
    tags: Vec<BoardTag>,
    bitmaps: Vec<Vec<bool>>,
    extent: BoardExtent,
}

/// Smallest plausible `tagSize`, m (a 2 mm tag is already hard to print and detect).
pub const MIN_TAG_SIZE_M: f64 = 0.002;
/// Largest plausible `tagSize`, m.
pub const MAX_TAG_SIZE_M: f64 = 1.0;

/// A `tagSize` out of range as found, with the unit it was likely written in.
fn tag_size_found(v: f64) -> String {
    let likely = |unit: &str, factor: f64| {
        let metres = v / factor;
        (MIN_TAG_SIZE_M..=MAX_TAG_SIZE_M)
            .contains(&metres)
            .then(|| format!("{v} (that looks like {unit}: tagSize: {metres} in metres)"))
    };
    if !v.is_finite() || v <= MAX_TAG_SIZE_M {
        return v.to_string();
    }
    // Centimetres first: a 1–100 cm tag is far more common than a 1–100 mm one written as such.
    if v <= 100.0 {
        likely("centimetres", 100.0)
    } else {
        likely("millimetres", 1000.0)
    }
    .unwrap_or_else(|| v.to_string())
}

impl Board {
    /// Reads a board YAML file.
    pub fn load(path: &Path) -> Result<Self, TargetError> {
        Self::from_yaml_str(&read_board_file(path)?, path)
    }

    /// Parses board YAML text; `path` names the source in errors.
    pub fn from_yaml_str(text: &str, path: &Path) -> Result<Self, TargetError> {
        let deserializer = serde_yaml_ng::Deserializer::from_str(text);
        let file: BoardFile = serde_path_to_error::deserialize(deserializer).map_err(|error| {
            TargetError::BoardYaml {
                path: path.to_path_buf(),
                key: error.path().to_string(),
                problem: error.into_inner(),
            }
        })?;
        if file.target_type != "aprilgrid" {
            return Err(bad(path, "target_type", "`aprilgrid`", &file.target_type));
        }
        Self::aprilgrid(
            file.tag_cols,
            file.tag_rows,
            file.tag_size,
            file.tag_spacing,
            file.family,
            file.first_id,
            file.border_bits,
        )
        .and_then(|board| match file.corner_squares {
            Some(on) => board.with_corner_squares(on),
            None => Ok(board),
        })
        .map_err(|error| match error {
            TargetError::BadBoard {
                key,
                expected,
                found,
                ..
            } => TargetError::BadBoard {
                path: path.to_path_buf(),
                key,
                expected,
                found,
            },
            other => other,
        })
    }

    /// Builds and validates a grid: `tag_size` (m) is the border square's edge, `tag_spacing`
    /// the gap between tags as a fraction of `tag_size`. Printed as Kalibr prints it: with the
    /// corner squares (see [`Board::with_corner_squares`]), except for a reversed-border family,
    /// whose data ring they would cover.
    pub fn aprilgrid(
        cols: u32,
        rows: u32,
        tag_size: f64,
        tag_spacing: f64,
        family: TagFamily,
        first_id: u32,
        border_bits: u32,
    ) -> Result<Self, TargetError> {
        let inline = Path::new("<inline>");
        if cols == 0 || rows == 0 {
            return Err(bad(
                inline,
                "tagCols x tagRows",
                "at least one tag (a single tag is 1x1)",
                &format!("{cols}x{rows}"),
            ));
        }
        if !(tag_size.is_finite() && (MIN_TAG_SIZE_M..=MAX_TAG_SIZE_M).contains(&tag_size)) {
            return Err(bad(
                inline,
                "tagSize",
                &format!(
                    "the edge of a tag's black square in metres, {MIN_TAG_SIZE_M}–{MAX_TAG_SIZE_M} m"
                ),
                &tag_size_found(tag_size),
            ));
        }
        let layout = family.layout(border_bits).ok_or_else(|| {
            bad(
                inline,
                "border_bits",
                if family == TagFamily::Tag36h11 {
                    "1 or 2"
                } else {
                    "1 (reversed-border family)"
                },
                &border_bits.to_string(),
            )
        })?;
        let cell = tag_size / layout.width_at_border as f64;
        // Neighbouring tags' outer rings may share the white gap of a normal family; a
        // reversed family carries data in its outer ring, which must not overlap.
        let margin = layout.margin_cells() as f64;
        let needed_cells = if layout.reversed_border {
            2.0 * margin + 1.0
        } else {
            margin
        };
        if !(tag_spacing.is_finite()
            && tag_spacing * layout.width_at_border as f64 >= needed_cells - 1e-9)
        {
            return Err(bad(
                inline,
                "tagSpacing",
                &format!(
                    "a ratio ≥ {:.3} ({needed_cells} cells of {} between tags)",
                    needed_cells / layout.width_at_border as f64,
                    family.name()
                ),
                &tag_spacing.to_string(),
            ));
        }
        let count = cols as u64 * rows as u64;
        if first_id as u64 + count > layout.codes.len() as u64 {
            return Err(bad(
                inline,
                "first_id + tagCols·tagRows",
                &format!("≤ {} ({} ids)", layout.codes.len(), family.name()),
                &(first_id as u64 + count).to_string(),
            ));
        }
        let pitch = tag_size * (1.0 + tag_spacing);
        let mut tags = Vec::with_capacity(count as usize);
        let mut bitmaps = Vec::with_capacity(count as usize);
        for k in 0..count as u32 {
            let (col, row) = (k % cols, k / cols);
            let (x0, y0) = (col as f64 * pitch, row as f64 * pitch);
            let s = tag_size;
            tags.push(BoardTag {
                id: first_id + k,
                col,
                row,
                corners_in_target: [
                    Point3::new(x0, y0, 0.0),
                    Point3::new(x0 + s, y0, 0.0),
                    Point3::new(x0 + s, y0 + s, 0.0),
                    Point3::new(x0, y0 + s, 0.0),
                ],
            });
            bitmaps.push(
                layout
                    .bitmap((first_id + k) as usize)
                    .expect("id checked above"),
            );
        }
        // White paper around the grid: at least the gap, and at least one ring beyond the tags'
        // outer cells, so the outermost tags have a clean surround.
        let paper = (tag_spacing * tag_size).max((margin + 1.0) * cell);
        let extent = BoardExtent {
            min: Point2::new(-paper, -paper),
            max: Point2::new(
                (cols - 1) as f64 * pitch + tag_size + paper,
                (rows - 1) as f64 * pitch + tag_size + paper,
            ),
        };
        Ok(Board {
            cols,
            rows,
            tag_size,
            tag_spacing,
            family,
            first_id,
            border_bits,
            corner_squares: !layout.reversed_border,
            layout,
            tags,
            bitmaps,
            extent,
        })
    }

    /// The same board with (`true`) or without Kalibr's corner squares: black squares of side
    /// `tagSpacing·tagSize` in the gaps at every tag corner (the outer corners of the grid
    /// too), touching the tags' black squares corner to corner so neighbouring tags meet in
    /// X-junctions, as `kalibr_create_target_pdf` draws them. Refused for a reversed-border
    /// family (the squares would cover its outer data ring).
    pub fn with_corner_squares(mut self, on: bool) -> Result<Self, TargetError> {
        if on && self.layout.reversed_border {
            return Err(bad(
                Path::new("<inline>"),
                "corner_squares",
                &format!(
                    "false for {} (its data ring lies where the squares go)",
                    self.family.name()
                ),
                "true",
            ));
        }
        self.corner_squares = on;
        Ok(self)
    }

    /// Whether Kalibr's corner squares are printed (see [`Board::with_corner_squares`]).
    pub fn corner_squares(&self) -> bool {
        self.corner_squares
    }

    /// Edge of a corner square, m (`tagSpacing·tagSize`, the gap between tags).
    pub fn corner_square_size(&self) -> f64 {
        self.tag_spacing * self.tag_size
    }

    /// The corner squares' bottom-left corners in the target frame (m), row by row from the
    /// bottom: `(tagCols + 1)·(tagRows + 1)` of them, or none when they are not printed.
    /// Each square spans `[x, x + corner_square_size()) x [y, y + corner_square_size())`.
    pub fn corner_square_origins(&self) -> Vec<Point2<f64>> {
        if !self.corner_squares {
            return Vec::new();
        }
        let (pitch, g) = (self.pitch(), self.corner_square_size());
        (0..=self.rows)
            .flat_map(|r| {
                (0..=self.cols)
                    .map(move |c| Point2::new(c as f64 * pitch - g, r as f64 * pitch - g))
            })
            .collect()
    }

    /// Whether the point (target frame, m) lies on a corner square.
    fn on_corner_square(&self, x: f64, y: f64) -> bool {
        if !self.corner_squares {
            return false;
        }
        let (pitch, g) = (self.pitch(), self.corner_square_size());
        // Square (c, r) spans [c·pitch - g, c·pitch) along x, c in 0..=cols; likewise y.
        let inside = |v: f64, count: u32| {
            let k = ((v + g) / pitch).floor();
            k >= 0.0 && k <= count as f64 && v + g - k * pitch < g
        };
        inside(x, self.cols) && inside(y, self.rows)
    }

    /// Border-square corners of tag `id` in the target frame (m), AprilTag order.
    pub fn tag_corners_in_target(&self, id: u32) -> Option<[Point3<f64>; 4]> {
        self.tag(id).map(|t| t.corners_in_target)
    }

    /// The tag with this id, if it is on the board.
    pub fn tag(&self, id: u32) -> Option<&BoardTag> {
        let index = id.checked_sub(self.first_id)? as usize;
        self.tags.get(index)
    }

    /// All tags, by id.
    pub fn tags(&self) -> &[BoardTag] {
        &self.tags
    }

    /// The printed sheet's rectangle (m).
    pub fn extent(&self) -> BoardExtent {
        self.extent
    }

    /// Columns of tags.
    pub fn cols(&self) -> u32 {
        self.cols
    }

    /// Rows of tags.
    pub fn rows(&self) -> u32 {
        self.rows
    }

    /// Edge of a tag's border square, m.
    pub fn tag_size(&self) -> f64 {
        self.tag_size
    }

    /// Gap between tags as a fraction of `tag_size`.
    pub fn tag_spacing(&self) -> f64 {
        self.tag_spacing
    }

    /// Centre-to-centre distance of neighbouring tags, m.
    pub fn pitch(&self) -> f64 {
        self.tag_size * (1.0 + self.tag_spacing)
    }

    /// The tag family.
    pub fn family(&self) -> TagFamily {
        self.family
    }

    /// The first id (tag at column 0, row 0).
    pub fn first_id(&self) -> u32 {
        self.first_id
    }

    /// Width of the black border in cells (1 standard, 2 Kalibr).
    pub fn border_bits(&self) -> u32 {
        self.border_bits
    }

    /// The family layout with this board's border.
    pub fn layout(&self) -> &FamilyLayout {
        &self.layout
    }

    /// Edge of one tag cell, m.
    pub fn cell_size(&self) -> f64 {
        self.tag_size / self.layout.width_at_border as f64
    }

    /// Printed reflectance at a point of the board plane (target frame, m): `Some(true)` white
    /// paper or white cell, `Some(false)` black (a tag's black cell or a corner square), `None`
    /// off the sheet.
    pub fn is_white_at(&self, x: f64, y: f64) -> Option<bool> {
        let e = &self.extent;
        if !(x >= e.min.x && x < e.max.x && y >= e.min.y && y < e.max.y) {
            return None;
        }
        if self.on_corner_square(x, y) {
            return Some(false);
        }
        let pitch = self.pitch();
        let cell = self.cell_size();
        let margin = self.layout.margin_cells();
        let n = self.layout.total_width;
        // The nearest tag whose outer cells could contain the point: tags occupy
        // [col·pitch - margin·cell, col·pitch + tag_size + margin·cell).
        let col = ((x + margin as f64 * cell) / pitch).floor();
        let row = ((y + margin as f64 * cell) / pitch).floor();
        if col < 0.0 || row < 0.0 || col >= self.cols as f64 || row >= self.rows as f64 {
            return Some(true);
        }
        let i = ((x - col * pitch) / cell).floor() as i64 + margin as i64;
        let j_up = ((y - row * pitch) / cell).floor() as i64 + margin as i64;
        if i < 0 || j_up < 0 || i >= n as i64 || j_up >= n as i64 {
            return Some(true);
        }
        // Bitmap rows run from the top of the printed tag (+y) downwards.
        let r = (n as i64 - 1 - j_up) as usize;
        let index = (row as u32 * self.cols + col as u32) as usize;
        Some(self.bitmaps[index][r * n as usize + i as usize])
    }
}

fn bad(path: &Path, key: &str, expected: &str, found: &str) -> TargetError {
    TargetError::BadBoard {
        path: PathBuf::from(path),
        key: key.to_string(),
        expected: expected.to_string(),
        found: found.to_string(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const KALIBR: &str =
        "target_type: 'aprilgrid'\ntagCols: 6\ntagRows: 6\ntagSize: 0.088\ntagSpacing: 0.3\n";

    #[test]
    fn kalibr_file_loads_with_two_cell_border_and_kalibr_layout() {
        let board = Board::from_yaml_str(KALIBR, Path::new("k.yaml")).unwrap();
        assert_eq!(board.tags().len(), 36);
        assert_eq!(board.border_bits(), 2);
        let pitch = 0.088 * 1.3;
        // Tag 7 is column 1, row 1: ids run along +x, then up.
        let c = board.tag_corners_in_target(7).unwrap();
        assert!((c[0] - Point3::new(pitch, pitch, 0.0)).norm() < 1e-12);
        assert!((c[2] - Point3::new(pitch + 0.088, pitch + 0.088, 0.0)).norm() < 1e-12);
        assert!(board.tag_corners_in_target(36).is_none());
    }

    #[test]
    fn unknown_keys_zero_tags_and_bad_values_are_refused_with_the_key() {
        let path = Path::new("b.yaml");
        let error = Board::from_yaml_str(&format!("{KALIBR}colour: red\n"), path).unwrap_err();
        assert!(error.to_string().contains("colour"), "{error}");
        let error =
            Board::from_yaml_str(&KALIBR.replace("tagCols: 6", "tagCols: 0"), path).unwrap_err();
        assert!(error.to_string().contains("at least one tag"), "{error}");
        let error = Board::from_yaml_str(&KALIBR.replace("0.088", "-0.088"), path).unwrap_err();
        assert!(error.to_string().contains("tagSize"), "{error}");
        // Issue #30: a tag size in centimetres or millimetres is named as such.
        for (size, expected) in [
            ("4", "`tagSize` must be the edge of a tag's black square in metres, 0.002–1 m, found 4 (that looks like centimetres: tagSize: 0.04 in metres)"),
            ("40", "found 40 (that looks like centimetres: tagSize: 0.4 in metres)"),
            ("88", "found 88 (that looks like centimetres: tagSize: 0.88 in metres)"),
            ("400", "found 400 (that looks like millimetres: tagSize: 0.4 in metres)"),
            ("0.001", "found 0.001"),
        ] {
            let text = format!(
                "target_type: 'aprilgrid'\ntagCols: 6\ntagRows: 6\ntagSize: {size}\ntagSpacing: 0.3\n"
            );
            let error = Board::from_yaml_str(&text, Path::new("board.yaml")).unwrap_err();
            let message = error.to_string();
            assert!(message.starts_with("board file board.yaml: "), "{message}");
            assert!(message.contains(expected), "{message}");
        }
        let error = Board::from_yaml_str(&format!("{KALIBR}family: tag16h5\n"), path).unwrap_err();
        assert!(error.to_string().contains("family"), "{error}");
        let error = Board::from_yaml_str(&format!("{KALIBR}first_id: 560\n"), path).unwrap_err();
        assert!(error.to_string().contains("first_id"), "{error}");
    }

    #[test]
    fn kalibr_files_have_corner_squares_unless_the_key_says_no() {
        let path = Path::new("k.yaml");
        let board = Board::from_yaml_str(KALIBR, path).unwrap();
        assert!(board.corner_squares());
        assert_eq!(board.corner_square_origins().len(), 49);
        let off = Board::from_yaml_str(&format!("{KALIBR}corner_squares: false\n"), path).unwrap();
        assert!(!off.corner_squares());
        assert!(off.corner_square_origins().is_empty());
        let error = Board::from_yaml_str(
            &format!(
                "{}family: tagStandard41h12\nborder_bits: 1\ncorner_squares: true\n",
                KALIBR.replace("0.3", "1.0")
            ),
            path,
        )
        .unwrap_err();
        assert!(error.to_string().contains("corner_squares"), "{error}");
        assert!(error.to_string().contains("k.yaml"), "{error}");
    }

    #[test]
    fn corner_squares_fill_the_gap_at_every_tag_corner_and_nowhere_else() {
        // tag 0.08 m, gap 0.02 m, pitch 0.1 m.
        let board = Board::aprilgrid(2, 2, 0.08, 0.25, TagFamily::Tag36h11, 0, 2).unwrap();
        let plain = board.clone().with_corner_squares(false).unwrap();
        // Between the four tags: x, y in [0.08, 0.1).
        assert_eq!(board.is_white_at(0.09, 0.09), Some(false));
        assert_eq!(plain.is_white_at(0.09, 0.09), Some(true));
        // Outer corners of the grid: below-left of tag 0 and above-right of tag 3.
        assert_eq!(board.is_white_at(-0.019, -0.001), Some(false));
        assert_eq!(board.is_white_at(0.199, 0.181), Some(false));
        // The gap beside a tag edge (not at a corner) stays white.
        assert_eq!(board.is_white_at(0.09, 0.04), Some(true));
        assert_eq!(board.is_white_at(-0.01, 0.04), Some(true));
        // Tag cells are the same with and without the squares.
        for k in 0..400 {
            let (x, y) = (
                (k % 20) as f64 * 0.004 + 0.002,
                (k / 20) as f64 * 0.004 + 0.002,
            );
            assert_eq!(
                board.is_white_at(x, y),
                plain.is_white_at(x, y),
                "({x}, {y})"
            );
        }
    }

    #[test]
    fn reflectance_shows_black_border_and_white_gap() {
        let board = Board::aprilgrid(2, 2, 0.08, 0.25, TagFamily::Tag36h11, 0, 1).unwrap();
        let cell = 0.01;
        // Inside tag 0's border ring (first cell inside the black square).
        assert_eq!(board.is_white_at(0.5 * cell, 4.0 * cell), Some(false));
        // In the gap between tags 0 and 1.
        assert_eq!(board.is_white_at(0.09, 0.04), Some(true));
        // Off the sheet.
        assert_eq!(board.is_white_at(-1.0, 0.0), None);
    }
}
