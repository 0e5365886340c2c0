//! Printable ChArUco boards and chessboards at true scale: a PNG (resolution in its pHYs
//! chunk), an SVG in millimetres or a vector PDF, each with a 100 mm (or 50 mm) scale bar and
//! the board file's keys in a 25 mm strip under the board. Aprilgrids have their own writers
//! (`vision::print`); this module serves the other `target_type`s.
//!
//! Everything black is a rectangle of [`black_rects`] (squares, marker cells merged into runs),
//! sampled from [`Target::is_white_at`], the single source of truth the simulated camera also
//! renders. Units: metres, page coordinates from the top-left, y down. Depends on
//! `vision::{target, draw}`.

use image::{GrayImage, Luma};

use super::draw;
use super::target::Target;
use super::TargetError;

/// Height of the strip under the board, m.
const STRIP_M: f64 = 0.025;
/// PostScript points per metre.
const PT_PER_M: f64 = 72.0 / 0.0254;

/// The board's keys as one caption line.
fn caption(target: &Target) -> String {
    match target {
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
        Target::Aprilgrid(_) => target.describe(),
    }
}

/// Black rectangles `[left, top, width, height]` (m, from the sheet extent's top-left, y down):
/// the black squares, and each marker row's black cells merged into runs.
pub fn black_rects(target: &Target) -> Vec<[f64; 4]> {
    let e = target.extent();
    let mut rects = Vec::new();
    // Sample on the finest grid the board has: squares (chessboard) or marker cells (ChArUco),
    // offset so every cell boundary falls on a grid line.
    let (cell, origin_x, origin_y, nx, ny) = match target {
        Target::Checkerboard(c) => {
            let (min, max) = c.squares_extent();
            let (sx, sy) = (c.col_spacing(), c.row_spacing());
            for j in 0..=c.rows() {
                for i in 0..=c.cols() {
                    let (x, y) = (min.x + (i as f64 + 0.5) * sx, max.y - (j as f64 + 0.5) * sy);
                    if target.is_white_at(x, y) == Some(false) {
                        rects.push([
                            min.x + i as f64 * sx - e.min.x,
                            e.max.y - (max.y - j as f64 * sy),
                            sx,
                            sy,
                        ]);
                    }
                }
            }
            return rects;
        }
        Target::Charuco(c) => {
            let s = c.square_length();
            let squares = |i: u32, j: u32| (i as f64 * s, c.squares_y() as f64 * s - j as f64 * s);
            for j in 0..c.squares_y() {
                for i in 0..c.squares_x() {
                    let (x, top) = squares(i, j);
                    if target.is_white_at(x + 0.5 * s, top - 0.5 * s) == Some(false)
                        && target.is_white_at(x + 0.01 * s, top - 0.01 * s) == Some(false)
                    {
                        rects.push([x - e.min.x, e.max.y - top, s, s]);
                    }
                }
            }
            let cells = c.marker_cells();
            let cell = c.marker_length() / cells as f64;
            let off = (s - c.marker_length()) / 2.0;
            (cell, off, off, cells, cells)
        }
        Target::Aprilgrid(_) => return rects,
    };
    // ChArUco markers: each white square's marker, cell rows merged into runs.
    if let Target::Charuco(c) = target {
        let s = c.square_length();
        for j in 0..c.squares_y() {
            for i in 0..c.squares_x() {
                let (x0, top) = (i as f64 * s, c.squares_y() as f64 * s - j as f64 * s);
                // Only white squares carry a marker: their paper just inside the corner is white.
                if target.is_white_at(x0 + 0.01 * s, top - 0.01 * s) != Some(true) {
                    continue;
                }
                for r in 0..ny {
                    let y_centre = top - origin_y - (r as f64 + 0.5) * cell;
                    let black = |k: u32| {
                        target.is_white_at(x0 + origin_x + (k as f64 + 0.5) * cell, y_centre)
                            == Some(false)
                    };
                    let mut k = 0;
                    while k < nx {
                        if !black(k) {
                            k += 1;
                            continue;
                        }
                        let start = k;
                        while k < nx && black(k) {
                            k += 1;
                        }
                        rects.push([
                            x0 + origin_x + start as f64 * cell - e.min.x,
                            e.max.y - (top - origin_y - r as f64 * cell),
                            (k - start) as f64 * cell,
                            cell,
                        ]);
                    }
                }
            }
        }
    }
    rects
}

/// Page size (m), the board's width and height, and the scale bar length.
fn page(target: &Target) -> (f64, f64, f64, f64, f64) {
    let e = target.extent();
    let (bw, bh) = (e.max.x - e.min.x, e.max.y - e.min.y);
    let text_w = caption(target).len() as f64 * 0.0021 + 0.01;
    let scale_bar = if bw >= 0.12 { 0.1 } else { 0.05 };
    (bw.max(text_w), bh + STRIP_M, bw, bh, scale_bar)
}

/// The printable board as an SVG document in millimetres.
pub fn target_svg(target: &Target) -> String {
    let (w, h, bw, bh, bar) = page(target);
    let left = (w - bw) / 2.0;
    let mm = |m: f64| m * 1000.0;
    let mut svg = format!(
        "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"{w:.3}mm\" height=\"{h:.3}mm\" \
         viewBox=\"0 0 {w:.4} {h:.4}\">\n<rect width=\"100%\" height=\"100%\" fill=\"white\"/>\n<g fill=\"black\">\n",
        w = mm(w),
        h = mm(h)
    );
    for [x, y, rw, rh] in black_rects(target) {
        svg.push_str(&format!(
            "<rect x=\"{:.4}\" y=\"{:.4}\" width=\"{:.4}\" height=\"{:.4}\"/>\n",
            mm(left + x),
            mm(y),
            mm(rw),
            mm(rh)
        ));
    }
    let (bar_x, bar_y) = (mm(left + 0.005), mm(bh + 0.004));
    for k in (0..(bar / 0.01).round() as usize).step_by(2) {
        svg.push_str(&format!(
            "<rect x=\"{:.4}\" y=\"{bar_y:.4}\" width=\"10\" height=\"2\"/>\n",
            bar_x + 10.0 * k as f64
        ));
    }
    svg.push_str(&format!(
        "</g>\n<rect x=\"{bar_x:.4}\" y=\"{bar_y:.4}\" width=\"{:.4}\" height=\"2\" fill=\"none\" \
         stroke=\"black\" stroke-width=\"0.2\"/>\n\
         <text x=\"{:.4}\" y=\"{:.4}\" font-family=\"monospace\" font-size=\"3\">{} mm</text>\n\
         <text x=\"5\" y=\"{:.4}\" font-family=\"monospace\" font-size=\"3\">{}</text>\n</svg>\n",
        mm(bar),
        bar_x + mm(bar) + 3.0,
        bar_y + 2.0,
        mm(bar).round(),
        bar_y + 10.5,
        caption(target)
    ));
    svg
}

/// The printable board as a one-page vector PDF (the page is the board plus the strip).
pub fn target_pdf(target: &Target) -> Vec<u8> {
    use pdf_writer::{Content, Name, Str};
    let (w, h, bw, bh, bar) = page(target);
    let left = (w - bw) / 2.0;
    let pt = |m: f64| (m * PT_PER_M) as f32;
    let y_pt = |from_top: f64| pt(h - from_top);
    let mut content = Content::new();
    content.set_fill_gray(0.0);
    for [x, y, rw, rh] in black_rects(target) {
        content.rect(pt(left + x), y_pt(y + rh), pt(rw), pt(rh));
    }
    let (bar_x, bar_top, bar_h) = (left + 0.005, bh + 0.004, 0.002);
    for k in (0..(bar / 0.01).round() as usize).step_by(2) {
        content.rect(
            pt(bar_x + 0.01 * k as f64),
            y_pt(bar_top + bar_h),
            pt(0.01),
            pt(bar_h),
        );
    }
    content.fill_nonzero();
    content.set_stroke_gray(0.0);
    content.set_line_width(0.5);
    content.rect(pt(bar_x), y_pt(bar_top + bar_h), pt(bar), pt(bar_h));
    content.stroke();
    let font = Name(b"F1");
    for (x, baseline, text) in [
        (
            bar_x + bar + 0.003,
            bar_top + bar_h,
            format!("{} mm", (bar * 1000.0).round()),
        ),
        (0.005, bar_top + 0.0075, caption(target)),
        (
            0.005,
            bar_top + 0.0115,
            "print at actual size (100 %), not 'fit to page'".to_string(),
        ),
    ] {
        content.begin_text();
        content.set_font(font, 7.0);
        content.next_line(pt(x), y_pt(baseline));
        content.show(Str(text.as_bytes()));
        content.end_text();
    }
    let content = content.finish();
    super::print::one_page_pdf(content, font, pt(w), pt(h))
}

/// The printable board as a PNG at `dpi` (pixels per metre in its pHYs chunk).
pub fn target_png(target: &Target, dpi: f64) -> Result<Vec<u8>, TargetError> {
    if !(dpi.is_finite() && (72.0..=1200.0).contains(&dpi)) {
        return Err(TargetError::BadBoard {
            path: "<board.png>".into(),
            key: "dpi".into(),
            expected: "72 to 1200".into(),
            found: dpi.to_string(),
        });
    }
    let (w, h, bw, bh, bar) = page(target);
    let px_per_m = dpi / 0.0254;
    let px = |m: f64| (m * px_per_m).round() as i64;
    let mut image = GrayImage::from_pixel(px(w).max(1) as u32, px(h).max(1) as u32, Luma([255]));
    let left = (w - bw) / 2.0;
    for [x, y, rw, rh] in black_rects(target) {
        let (x0, y0) = (px(left + x), px(y));
        draw::fill_rect(
            &mut image,
            x0,
            y0,
            px(left + x + rw) - x0,
            px(y + rh) - y0,
            Luma([0]),
        );
    }
    let (bar_x, bar_top) = (left + 0.005, bh + 0.004);
    for k in (0..(bar / 0.01).round() as usize).step_by(2) {
        let x0 = px(bar_x + 0.01 * k as f64);
        draw::fill_rect(
            &mut image,
            x0,
            px(bar_top),
            px(bar_x + 0.01 * (k + 1) as f64) - x0,
            px(0.002),
            Luma([0]),
        );
    }
    let scale = ((0.0005 * px_per_m).round() as u32).max(1);
    draw::text(
        &mut image,
        px(0.005),
        px(bar_top + 0.005),
        scale,
        &format!(
            "{} mm scale bar - {}",
            (bar * 1000.0).round(),
            caption(target)
        ),
        Luma([0]),
    );
    draw::text(
        &mut image,
        px(0.005),
        px(bar_top + 0.011),
        scale,
        &format!("{dpi} dpi, print at 100 %"),
        Luma([0]),
    );
    super::print::encode_png(&image, px_per_m.round() as u32)
}
