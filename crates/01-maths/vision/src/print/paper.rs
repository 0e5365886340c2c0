//! Sheets of paper and fitting a board to one: [`Paper`], [`Sheet`], [`fit_to_paper`] (the
//! largest board whose sheet extent and caption strip fit the printable area) and
//! [`resized_board_yaml`] (the board file rewritten with the fitted sizes).
//!
//! Depends on `vision::{board, charuco, chessboard, target}` (the boards and their YAML reader)
//! and `vision::TargetError`.

use super::super::board::Board;
use super::super::charuco::Charuco;
use super::super::chessboard::Checkerboard;
use super::super::target::{AsTarget, Target};
use super::super::TargetError;

/// A sheet of paper a board can be fitted to and printed on.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Paper {
    /// ISO A4, 210 × 297 mm.
    A4,
    /// US Letter, 8.5 × 11 in (215.9 × 279.4 mm).
    Letter,
    /// ISO A3, 297 × 420 mm.
    A3,
}

impl Paper {
    /// Width and height in portrait, m.
    pub fn portrait_m(self) -> (f64, f64) {
        match self {
            Paper::A4 => (0.210, 0.297),
            Paper::Letter => (0.2159, 0.2794),
            Paper::A3 => (0.297, 0.420),
        }
    }

    /// The name as a person writes it (`A4`, `Letter`, `A3`).
    pub fn name(self) -> &'static str {
        match self {
            Paper::A4 => "A4",
            Paper::Letter => "Letter",
            Paper::A3 => "A3",
        }
    }
}

/// A sheet in one orientation with the margin a printer leaves blank.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Sheet {
    /// The paper.
    pub paper: Paper,
    /// Long side horizontal.
    pub landscape: bool,
    /// Blank margin on every side, m.
    pub margin_m: f64,
}

impl Sheet {
    /// Width and height as placed, m.
    pub fn size_m(&self) -> (f64, f64) {
        let (w, h) = self.paper.portrait_m();
        if self.landscape {
            (h, w)
        } else {
            (w, h)
        }
    }

    /// Width and height of the printable area (inside the margins), m.
    pub fn printable_m(&self) -> (f64, f64) {
        let (w, h) = self.size_m();
        (w - 2.0 * self.margin_m, h - 2.0 * self.margin_m)
    }

    pub(super) fn describe(&self) -> String {
        format!(
            "{} {}, margin {} mm",
            self.paper.name(),
            if self.landscape {
                "landscape"
            } else {
                "portrait"
            },
            (self.margin_m * 1000.0 * 10.0).round() / 10.0
        )
    }
}

/// Accepted `--margin-mm`, mm: printers leave 3-6 mm blank; more than 50 mm wastes the sheet.
pub const MARGIN_MM: (f64, f64) = (0.0, 50.0);
/// The smallest tag (aprilgrid) or square (ChArUco, chessboard) a fitted board may get, m:
/// below 5 mm a 300 dpi printer draws a cell of a 36h11 tag (10 cells across with Kalibr's
/// border) with fewer than 6 dots.
pub const MIN_FITTED_SIZE_M: f64 = 0.005;
/// A fitted board's first size key is rounded down to whole steps of 1/this m (0.1 mm), so the
/// number entered in the board file is short and the board still fits.
const SIZE_STEPS_PER_M: f64 = 1e4;
/// The other size keys keep their ratio to the first, rounded to 1/this m (0.01 mm).
const RATIO_STEPS_PER_M: f64 = 1e5;

/// `v` rounded to whole steps of `1 / steps_per_m`, written without binary noise (0.0426, not
/// 0.042600000000000006: the division is by a whole number).
fn snap(v: f64, steps_per_m: f64) -> f64 {
    (v * steps_per_m).round() / steps_per_m
}
/// Height of the strip under the board on a PDF page (scale bar and two caption lines), m.
pub(super) const PDF_STRIP_M: f64 = 0.02;

/// A board scaled to fill a sheet's printable area.
#[derive(Debug, Clone)]
pub struct FittedBoard {
    /// The board at its fitted size (everything else as the original).
    pub board: Target,
    /// The sheet and orientation it was fitted to.
    pub sheet: Sheet,
}

/// The keys of a board file that set its size, with their values (m). The first is the one
/// fitting steps (`tagSize`, `squareLength`, `colSpacingMeters`); the others keep their ratio
/// to it.
pub fn size_keys(target: &Target) -> Vec<(&'static str, f64)> {
    match target {
        Target::Aprilgrid(b) => vec![("tagSize", b.tag_size())],
        Target::Charuco(c) => vec![
            ("squareLength", c.square_length()),
            ("markerLength", c.marker_length()),
        ],
        Target::Checkerboard(c) => vec![
            ("colSpacingMeters", c.col_spacing()),
            ("rowSpacingMeters", c.row_spacing()),
        ],
    }
}

/// The same board as `target` with the sizes of [`size_keys`] set to `sizes` (m).
fn resized(target: &Target, sizes: &[f64]) -> Result<Target, TargetError> {
    let bad = TargetError::bad_board(std::path::Path::new("<print>"));
    Ok(match target {
        Target::Aprilgrid(b) => Target::Aprilgrid(
            Board::aprilgrid(
                b.cols(),
                b.rows(),
                sizes[0],
                b.tag_spacing(),
                b.family(),
                b.first_id(),
                b.border_bits(),
            )?
            .with_corner_squares(b.corner_squares())?,
        ),
        // The legacy flag only changes boards this reader refuses, so `false` rebuilds the same.
        Target::Charuco(c) => Target::Charuco(
            Charuco::new(
                c.squares_x(),
                c.squares_y(),
                sizes[0],
                sizes[1],
                c.dictionary_name(),
                false,
            )
            .map_err(bad)?,
        ),
        Target::Checkerboard(c) => Target::Checkerboard(
            Checkerboard::new(c.cols(), c.rows(), sizes[0], sizes[1]).map_err(bad)?,
        ),
    })
}

/// The same board with every size of [`size_keys`] times `factor` (a board printed at another
/// scale than its file says).
pub fn scaled(target: &Target, factor: f64) -> Result<Target, TargetError> {
    let sizes: Vec<f64> = size_keys(target).iter().map(|(_, v)| v * factor).collect();
    resized(target, &sizes)
}

/// The board's sheet extent (squares or tags plus white margin), width and height, m.
pub(super) fn extent_size(target: &Target) -> (f64, f64) {
    let e = target.extent();
    (e.max.x - e.min.x, e.max.y - e.min.y)
}

/// Whether `board` with the PDF strip under it fits the printable area of `sheet`.
pub(super) fn fits(target: &Target, sheet: &Sheet) -> bool {
    let (w, h) = extent_size(target);
    let (pw, ph) = sheet.printable_m();
    w <= pw + 1e-12 && h + PDF_STRIP_M <= ph + 1e-12
}

/// Scales `target` (its [`size_keys`]; the grid, spacing ratios and family stay) to the largest
/// size, its first size key in steps of 0.1 mm, whose sheet extent plus the caption strip fits
/// the printable area of `paper` with `margin_m` on every side, in whichever orientation gives
/// the larger board (portrait on a tie). Refused when the margin is outside [`MARGIN_MM`] or the
/// tags (squares) would be smaller than [`MIN_FITTED_SIZE_M`].
pub fn fit_to_paper(
    target: &(impl AsTarget + ?Sized),
    paper: Paper,
    margin_m: f64,
) -> Result<FittedBoard, TargetError> {
    let target = target.as_target();
    let margin_mm = margin_m * 1000.0;
    if !(margin_mm.is_finite() && margin_mm >= MARGIN_MM.0 && margin_mm <= MARGIN_MM.1) {
        return Err(TargetError::BadBoard {
            path: "<print>".into(),
            key: "margin-mm".into(),
            expected: format!("a margin in [{}, {}] mm", MARGIN_MM.0, MARGIN_MM.1),
            found: format!("{margin_mm} mm"),
        });
    }
    let (w0, h0) = extent_size(&target);
    let sizes = size_keys(&target);
    let first = sizes[0].1;
    // The largest first size (floored to the step) each orientation allows.
    let candidate = |landscape: bool| {
        let sheet = Sheet {
            paper,
            landscape,
            margin_m,
        };
        let (pw, ph) = sheet.printable_m();
        // The extent is linear in the size (the white margin is counted in cells or squares).
        let scale = (pw / w0).min((ph - PDF_STRIP_M) / h0);
        let size = (first * scale * SIZE_STEPS_PER_M).floor() / SIZE_STEPS_PER_M;
        (size, sheet)
    };
    let (portrait, landscape) = (candidate(false), candidate(true));
    let step = 1.0 / SIZE_STEPS_PER_M;
    let (mut size, sheet) = if landscape.0 > portrait.0 + step / 2.0 {
        landscape
    } else {
        portrait
    };
    // Round-off can put the floored size a hair over the edge: step down until it fits.
    while size >= MIN_FITTED_SIZE_M {
        let clean = snap(size, SIZE_STEPS_PER_M);
        let scaled: Vec<f64> = std::iter::once(clean)
            .chain(
                sizes[1..]
                    .iter()
                    .map(|(_, v)| snap(v * clean / first, RATIO_STEPS_PER_M)),
            )
            .collect();
        let fitted = resized(&target, &scaled)?;
        if fits(&fitted, &sheet) {
            return Ok(FittedBoard {
                board: fitted,
                sheet,
            });
        }
        size -= step;
    }
    Err(TargetError::BadBoard {
        path: "<print>".into(),
        key: "paper".into(),
        expected: format!(
            "a sheet giving {} of at least {} mm (use larger paper, a smaller margin or a smaller grid)",
            sizes[0].0,
            MIN_FITTED_SIZE_M * 1000.0
        ),
        found: format!(
            "{} on {}: {} {:.1} mm",
            target.describe(),
            sheet.describe(),
            sizes[0].0,
            size.max(0.0) * 1000.0
        ),
    })
}

/// The board file `original` (its YAML text, from `path`) with its [`size_keys`] set to those of
/// `fitted` (the same board at another size), every other line and comment kept, under a first
/// line saying `how` the sizes were found; checked by reading it back. Refused when the file has
/// no line of its own for a size key (a flow mapping, say): then enter the sizes by hand.
pub fn resized_board_yaml(
    original: &str,
    path: &std::path::Path,
    fitted: &Target,
    how: &str,
) -> Result<String, TargetError> {
    let mut out = original.to_string();
    for (key, value) in size_keys(fitted) {
        let prefix = format!("{key}:");
        let mut replaced = 0;
        let text: Vec<String> = out
            .lines()
            .map(|line| {
                if line.starts_with(&prefix) {
                    replaced += 1;
                    let comment = line.find(" #").map(|i| &line[i..]).unwrap_or("");
                    format!("{key}: {value}{comment}")
                } else {
                    line.to_string()
                }
            })
            .collect();
        if replaced != 1 {
            return Err(TargetError::BadBoard {
                path: path.to_path_buf(),
                key: key.into(),
                expected: format!("exactly one top-level `{key}:` line to rewrite"),
                found: format!("{replaced}"),
            });
        }
        out = text.join("\n");
        out.push('\n');
    }
    let back = Target::from_yaml_str(&out, path)?;
    if size_keys(&back) != size_keys(fitted) || back.points().len() != fitted.points().len() {
        return Err(TargetError::BadBoard {
            path: path.to_path_buf(),
            key: size_keys(fitted)[0].0.into(),
            expected: format!("{:?} after rewriting", size_keys(fitted)),
            found: format!("{:?}", size_keys(&back)),
        });
    }
    // The original's comments may state its size ("0.29 m of tags"): the first line says which
    // size is this file's.
    let extent = fitted.extent();
    let header = format!(
        "# {how}: {} (a board of {:.0} x {:.0} mm). The comments below are those of {} and may give its size instead.\n",
        size_keys(fitted)
            .iter()
            .map(|(key, value)| format!("{key}: {value}"))
            .collect::<Vec<_>>()
            .join(", "),
        (extent.max.x - extent.min.x) * 1e3,
        (extent.max.y - extent.min.y) * 1e3,
        path.file_name().map_or_else(|| path.display().to_string(), |n| n.to_string_lossy().into_owned())
    );
    Ok(header + &out)
}
