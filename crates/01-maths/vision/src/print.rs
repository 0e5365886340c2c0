//! Printable boards at true scale, for every `target_type` (aprilgrid, ChArUco, chessboard): a
//! PNG (with its resolution in the pHYs chunk, so printing at 100 % keeps every cell's size), an
//! SVG in millimetres or a vector PDF (through `pdf-writer`), each with a scale bar and the
//! board's parameters printed in the bottom margin. Measure the scale bar after printing.
//! [`fit_to_paper`] scales any board (its tags or squares) to fill an A4, Letter or A3 sheet
//! inside a printer's margin; the PDF then takes the sheet as its page.
//!
//! Page layout (metres): the board's sheet extent (tags plus white margin) on top, a 25 mm
//! strip below it for the scale bar and the parameters; the page is widened when the text is
//! wider than the board. Everything black is sampled from [`Target::is_white_at`], the single
//! source of truth the simulated camera also renders. Depends on `vision::{board, target, draw}`.
//!
//! # Files
//!
//! This file holds the page geometry shared by the writers (`Page`, the black runs of a board);
//! `png.rs` the PNG writer, `svg.rs` the SVG writer, `pdf.rs` the PDF writer, and `paper.rs` the
//! sheets of paper and the fitting of a board to one ([`fit_to_paper`], [`resized_board_yaml`], [`scaled`]).
//! Their public items are re-exported here: callers use `vision::print::…` paths only.

use super::draw;
use super::target::Target;

mod paper;
mod pdf;
mod png;
mod svg;

pub use paper::{
    fit_to_paper, resized_board_yaml, scaled, size_keys, FittedBoard, Paper, Sheet, MARGIN_MM,
    MIN_FITTED_SIZE_M,
};
pub use pdf::board_pdf;
pub use png::board_png;
pub use svg::board_svg;

/// Height of the margin strip under the board, m.
const STRIP_M: f64 = 0.025;
/// Height of one font pixel, m (glyphs are 5 font pixels tall: 2.5 mm).
const FONT_PIXEL_M: f64 = 0.0005;

/// The page geometry shared by the PNG and SVG writers.
struct Page {
    width: f64,
    height: f64,
    board_left: f64,
    board_height: f64,
    scale_bar: f64,
    caption: String,
}

/// The board's keys as the one caption line every printed form carries.
fn caption(target: &Target) -> String {
    match target {
        Target::Aprilgrid(board) => {
            let mut caption = format!(
                "aprilgrid {}x{} {} tagSize {} m tagSpacing {} first_id {} border_bits {}",
                board.cols(),
                board.rows(),
                board.family().name(),
                board.tag_size(),
                board.tag_spacing(),
                board.first_id(),
                board.border_bits()
            );
            if !board.corner_squares() {
                caption.push_str(" corner_squares false");
            }
            caption
        }
        Target::Charuco(c) => format!(
            "charuco squaresX {} squaresY {} squareLength {} m markerLength {} m {}",
            c.squares_x(),
            c.squares_y(),
            c.square_length(),
            c.marker_length(),
            c.dictionary_name()
        ),
        Target::Checkerboard(c) => format!(
            "checkerboard targetCols {} targetRows {} (inner corners) colSpacingMeters {} rowSpacingMeters {}",
            c.cols(),
            c.rows(),
            c.col_spacing(),
            c.row_spacing()
        ),
    }
}

impl Page {
    fn new(target: &Target, dpi: Option<f64>) -> Self {
        let (board_width, board_height) = paper::extent_size(target);
        let mut caption = caption(target);
        if let Some(dpi) = dpi {
            caption.push_str(&format!(" - {dpi} dpi, print at 100 %"));
        }
        let text_width = draw::text_width(&caption, 1) as f64 * FONT_PIXEL_M + 0.01;
        let width = board_width.max(text_width);
        let scale_bar = if board_width >= 0.12 { 0.1 } else { 0.05 };
        Page {
            width,
            height: board_height + STRIP_M,
            board_left: (width - board_width) / 2.0,
            board_height,
            scale_bar,
            caption,
        }
    }
}

/// Everything black on the board as rectangles `[left, top, width, height]` in metres from the
/// top-left corner of its sheet extent, y pointing down (page order): cells of one row merged
/// into runs, squares (and Kalibr's corner squares) one rectangle each.
fn black_rects(target: &Target) -> Vec<[f64; 4]> {
    let e = target.extent();
    let mut rects = Vec::new();
    match target {
        Target::Aprilgrid(board) => {
            let layout = board.layout();
            let n = layout.total_width;
            let cell = board.cell_size();
            let margin = layout.margin_cells() as f64;
            for tag in board.tags() {
                let left = tag.corners_in_target[0].x - margin * cell;
                let top = tag.corners_in_target[0].y - margin * cell + n as f64 * cell;
                runs(target, (left, top), cell, n as u32, &mut rects);
            }
            let g = board.corner_square_size();
            for origin in board.corner_square_origins() {
                rects.push([origin.x - e.min.x, e.max.y - (origin.y + g), g, g]);
            }
        }
        Target::Charuco(c) => {
            let s = c.square_length();
            let (min, max) = c.squares_extent();
            let cells = c.marker_cells();
            let inset = (s - c.marker_length()) / 2.0;
            for (left, top) in grid((min.x, max.y), c.squares_x(), c.squares_y(), (s, s)) {
                match target.is_white_at(left + 0.01 * s, top - 0.01 * s) {
                    // A black square is black just inside its corner; a white one carries a
                    // marker (which may be black at the square's centre).
                    Some(false) => rects.push([left - e.min.x, e.max.y - top, s, s]),
                    Some(true) => {
                        let cell = c.marker_length() / cells as f64;
                        runs(target, (left + inset, top - inset), cell, cells, &mut rects);
                    }
                    None => {}
                }
            }
        }
        Target::Checkerboard(c) => {
            let (min, max) = c.squares_extent();
            let (sx, sy) = (c.col_spacing(), c.row_spacing());
            for (left, top) in grid((min.x, max.y), c.cols() + 1, c.rows() + 1, (sx, sy)) {
                if target.is_white_at(left + 0.5 * sx, top - 0.5 * sy) == Some(false) {
                    rects.push([left - e.min.x, e.max.y - top, sx, sy]);
                }
            }
        }
    }
    rects
}

/// The top-left corners `(x, y)` (target frame, m) of the `nx` x `ny` squares of size
/// `(sx, sy)` of a grid whose top-left corner is `top_left`, row by row from the top.
fn grid(
    (x0, y0): (f64, f64),
    nx: u32,
    ny: u32,
    (sx, sy): (f64, f64),
) -> impl Iterator<Item = (f64, f64)> {
    (0..ny).flat_map(move |j| (0..nx).map(move |i| (x0 + i as f64 * sx, y0 - j as f64 * sy)))
}

/// Appends the black cells of an `n` x `n` grid of `cell`-sized cells whose top-left corner is
/// `(left, top)` (target frame, m), each row's black cells merged into runs, in page order.
/// Each cell's centre is sampled: the board's reflectance is the single source of truth.
fn runs(target: &Target, (left, top): (f64, f64), cell: f64, n: u32, rects: &mut Vec<[f64; 4]>) {
    let e = target.extent();
    for r in 0..n {
        let y_centre = top - (r as f64 + 0.5) * cell;
        let black =
            |c: u32| target.is_white_at(left + (c as f64 + 0.5) * cell, y_centre) == Some(false);
        let mut c = 0;
        while c < n {
            if !black(c) {
                c += 1;
                continue;
            }
            let start = c;
            while c < n && black(c) {
                c += 1;
            }
            rects.push([
                left + start as f64 * cell - e.min.x,
                e.max.y - (top - r as f64 * cell),
                (c - start) as f64 * cell,
                cell,
            ]);
        }
    }
}
