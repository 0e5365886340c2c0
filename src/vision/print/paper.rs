//! Sheets of paper and fitting a board to one: [`Paper`], [`Sheet`], [`fit_to_paper`] (the
//! largest tag size whose board and caption strip fit the printable area) and
//! [`fitted_board_yaml`] (the board file rewritten with the fitted size).
//!
//! Depends on `vision::board` (the board and its YAML reader) and `vision::TargetError`.

use super::super::board::Board;
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
/// The smallest tag a fitted board may get, m: below 5 mm a 300 dpi printer draws a cell of a
/// 36h11 tag (10 cells across with Kalibr's border) with fewer than 6 dots.
pub const MIN_FITTED_TAG_M: f64 = 0.005;
/// Fitted tag sizes are rounded down to this step, m (0.1 mm), so the number entered in the
/// board file is short and the board still fits.
const TAG_STEP_M: f64 = 1e-4;
/// Height of the strip under the board on a PDF page (scale bar and two caption lines), m.
pub(super) const PDF_STRIP_M: f64 = 0.02;

/// A board scaled to fill a sheet's printable area.
#[derive(Debug, Clone)]
pub struct FittedBoard {
    /// The board at its fitted tag size (everything else as the original).
    pub board: Board,
    /// The sheet and orientation it was fitted to.
    pub sheet: Sheet,
}

/// The same grid as `board` with tag size `tag_size` (m).
fn resized(board: &Board, tag_size: f64) -> Result<Board, TargetError> {
    Board::aprilgrid(
        board.cols(),
        board.rows(),
        tag_size,
        board.tag_spacing(),
        board.family(),
        board.first_id(),
        board.border_bits(),
    )?
    .with_corner_squares(board.corner_squares())
}

/// The board's sheet extent (tags plus white margin), width and height, m.
pub(super) fn extent_size(board: &Board) -> (f64, f64) {
    let e = board.extent();
    (e.max.x - e.min.x, e.max.y - e.min.y)
}

/// Whether `board` with the PDF strip under it fits the printable area of `sheet`.
pub(super) fn fits(board: &Board, sheet: &Sheet) -> bool {
    let (w, h) = extent_size(board);
    let (pw, ph) = sheet.printable_m();
    w <= pw + 1e-12 && h + PDF_STRIP_M <= ph + 1e-12
}

/// Scales `board` (its tag size; the grid, spacing and family stay) to the largest size, in
/// steps of 0.1 mm, whose sheet extent plus the caption strip fits the printable area of
/// `paper` with `margin_m` on every side, in whichever orientation gives the larger tags
/// (portrait on a tie). Refused when the margin is outside [`MARGIN_MM`] or the tags would be
/// smaller than [`MIN_FITTED_TAG_M`].
pub fn fit_to_paper(
    board: &Board,
    paper: Paper,
    margin_m: f64,
) -> Result<FittedBoard, TargetError> {
    let margin_mm = margin_m * 1000.0;
    if !(margin_mm.is_finite() && margin_mm >= MARGIN_MM.0 && margin_mm <= MARGIN_MM.1) {
        return Err(TargetError::BadBoard {
            path: "<print>".into(),
            key: "margin-mm".into(),
            expected: format!("a margin in [{}, {}] mm", MARGIN_MM.0, MARGIN_MM.1),
            found: format!("{margin_mm} mm"),
        });
    }
    let (w0, h0) = extent_size(board);
    // The largest tag size (floored to the step) each orientation allows.
    let candidate = |landscape: bool| {
        let sheet = Sheet {
            paper,
            landscape,
            margin_m,
        };
        let (pw, ph) = sheet.printable_m();
        // The extent is linear in the tag size (the white margin is counted in cells).
        let scale = (pw / w0).min((ph - PDF_STRIP_M) / h0);
        let tag = (board.tag_size() * scale / TAG_STEP_M).floor() * TAG_STEP_M;
        (tag, sheet)
    };
    let (portrait, landscape) = (candidate(false), candidate(true));
    let (mut tag, sheet) = if landscape.0 > portrait.0 + TAG_STEP_M / 2.0 {
        landscape
    } else {
        portrait
    };
    // Round-off can put the floored size a hair over the edge: step down until it fits.
    while tag >= MIN_FITTED_TAG_M {
        // Whole tenths of a millimetre, written without binary noise (0.0426, not 0.042600000000000006).
        let clean = (tag * 1e4).round() / 1e4;
        let fitted = resized(board, clean)?;
        if fits(&fitted, &sheet) {
            return Ok(FittedBoard {
                board: fitted,
                sheet,
            });
        }
        tag -= TAG_STEP_M;
    }
    Err(TargetError::BadBoard {
        path: "<print>".into(),
        key: "paper".into(),
        expected: format!(
            "a sheet giving tags of at least {} mm (use larger paper, a smaller margin or fewer tags)",
            MIN_FITTED_TAG_M * 1000.0
        ),
        found: format!(
            "{}x{} tags on {}: {:.1} mm tags",
            board.cols(),
            board.rows(),
            sheet.describe(),
            tag.max(0.0) * 1000.0
        ),
    })
}

/// The board file `original` (its YAML text, from `path`) with `tagSize` set to the fitted
/// board's, every other line and comment kept; checked by reading it back. Refused when the
/// file has no `tagSize:` line of its own (a flow mapping, say): then enter the size by hand.
pub fn fitted_board_yaml(
    original: &str,
    path: &std::path::Path,
    fitted: &Board,
) -> Result<String, TargetError> {
    let mut replaced = 0;
    let text: Vec<String> = original
        .lines()
        .map(|line| {
            if line.starts_with("tagSize:") {
                replaced += 1;
                let comment = line.find(" #").map(|i| &line[i..]).unwrap_or("");
                format!("tagSize: {}{comment}", fitted.tag_size())
            } else {
                line.to_string()
            }
        })
        .collect();
    if replaced != 1 {
        return Err(TargetError::BadBoard {
            path: path.to_path_buf(),
            key: "tagSize".into(),
            expected: "exactly one top-level `tagSize:` line to rewrite".into(),
            found: format!("{replaced}"),
        });
    }
    let mut out = text.join("\n");
    out.push('\n');
    let back = Board::from_yaml_str(&out, path)?;
    if back.tag_size() != fitted.tag_size() || back.cols() != fitted.cols() {
        return Err(TargetError::BadBoard {
            path: path.to_path_buf(),
            key: "tagSize".into(),
            expected: format!("{} m after rewriting", fitted.tag_size()),
            found: format!("{} m", back.tag_size()),
        });
    }
    Ok(out)
}
