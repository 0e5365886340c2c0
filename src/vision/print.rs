//! Printable boards at true scale: a PNG (with its resolution in the pHYs chunk, so printing at
//! 100 % keeps every cell's size), an SVG in millimetres or a vector PDF (through `pdf-writer`),
//! each with a scale bar and the board's parameters printed in the bottom margin. Measure the
//! scale bar after printing. [`fit_to_paper`] scales a board's tags to fill an A4, Letter or A3
//! sheet inside a printer's margin; the PDF then takes the sheet as its page.
//!
//! Page layout (metres): the board's sheet extent (tags plus white margin) on top, a 25 mm
//! strip below it for the scale bar and the parameters; the page is widened when the text is
//! wider than the board. Depends on `vision::board` and `vision::draw`.
//!
//! # Files
//!
//! This file holds the page geometry shared by the writers (`Page`, the black runs of a board);
//! `png.rs` the PNG writer, `svg.rs` the SVG writer, `pdf.rs` the PDF writer, and `paper.rs` the
//! sheets of paper and the fitting of a board to one ([`fit_to_paper`], [`fitted_board_yaml`]).
//! Their public items are re-exported here: callers use `vision::print::…` paths only.

use super::board::Board;
use super::draw;

mod paper;
mod pdf;
mod png;
mod svg;

pub use paper::{
    fit_to_paper, fitted_board_yaml, FittedBoard, Paper, Sheet, MARGIN_MM, MIN_FITTED_TAG_M,
};
pub use pdf::board_pdf;
pub(crate) use pdf::one_page_pdf;
pub use png::board_png;
pub(crate) use png::encode_png;
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
fn caption(board: &Board) -> String {
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

impl Page {
    fn new(board: &Board, dpi: Option<f64>) -> Self {
        let (board_width, board_height) = paper::extent_size(board);
        let mut caption = caption(board);
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
/// The board's black cells merged into horizontal runs, each `[left, top, width, height]` in
/// metres from the top-left corner of the board's sheet extent, y pointing down (page order).
/// Each cell's centre is sampled: the board's reflectance is the single source of truth. Kalibr's
/// corner squares, when printed, follow as one square each.
fn black_runs(board: &Board) -> Vec<[f64; 4]> {
    let extent = board.extent();
    let layout = board.layout();
    let n = layout.total_width as usize;
    let cell = board.cell_size();
    let margin = layout.margin_cells() as f64;
    let mut runs = Vec::new();
    for tag in board.tags() {
        let x0 = tag.corners_in_target[0].x - margin * cell;
        let top = tag.corners_in_target[0].y - margin * cell + n as f64 * cell;
        for r in 0..n {
            let y_centre = top - (r as f64 + 0.5) * cell;
            let black =
                |c: usize| board.is_white_at(x0 + (c as f64 + 0.5) * cell, y_centre) == Some(false);
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
                runs.push([
                    x0 + start as f64 * cell - extent.min.x,
                    extent.max.y - (top - r as f64 * cell),
                    (c - start) as f64 * cell,
                    cell,
                ]);
            }
        }
    }
    let g = board.corner_square_size();
    for origin in board.corner_square_origins() {
        runs.push([origin.x - extent.min.x, extent.max.y - (origin.y + g), g, g]);
    }
    runs
}
