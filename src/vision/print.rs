//! Printable boards at true scale: a PNG (with its resolution in the pHYs chunk, so printing at
//! 100 % keeps every cell's size), an SVG in millimetres or a vector PDF (through `pdf-writer`),
//! each with a scale bar and the board's parameters printed in the bottom margin. Measure the
//! scale bar after printing. [`fit_to_paper`] scales a board's tags to fill an A4, Letter or A3
//! sheet inside a printer's margin; the PDF then takes the sheet as its page.
//!
//! Page layout (metres): the board's sheet extent (tags plus white margin) on top, a 25 mm
//! strip below it for the scale bar and the parameters; the page is widened when the text is
//! wider than the board. Depends on `vision::board` and `vision::draw`.

use image::{GrayImage, ImageEncoder, Luma};

use super::board::Board;
use super::draw;
use super::TargetError;

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

impl Page {
    fn new(board: &Board, dpi: Option<f64>) -> Self {
        let extent = board.extent();
        let board_width = extent.max.x - extent.min.x;
        let board_height = extent.max.y - extent.min.y;
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

/// Renders the printable board as an 8-bit grey PNG at `dpi` (50-1200), encoded, with its
/// resolution stored so printers keep the true scale. `show_frame` overlays the board frame
/// for documentation (grey axes x and y from the origin, tag ids under the tags, and tag
/// 0's corner numbers); leave it off for a board to print.
pub fn board_png(board: &Board, dpi: f64, show_frame: bool) -> Result<Vec<u8>, TargetError> {
    if !(50.0..=1200.0).contains(&dpi) {
        return Err(TargetError::BadBoard {
            path: "<print>".into(),
            key: "dpi".to_string(),
            expected: "between 50 and 1200".to_string(),
            found: dpi.to_string(),
        });
    }
    let page = Page::new(board, Some(dpi));
    let px_per_m = dpi / 0.0254;
    let width = (page.width * px_per_m).ceil() as u32;
    let height = (page.height * px_per_m).ceil() as u32;
    // A 1 m board at 1200 dpi would need 2 GB: refuse instead of exhausting memory.
    const MAX_PIXELS: u64 = 400_000_000;
    if width as u64 * height as u64 > MAX_PIXELS {
        return Err(TargetError::BadBoard {
            path: "<print>".into(),
            key: "dpi".to_string(),
            expected: format!("a resolution giving at most {MAX_PIXELS} pixels for this board"),
            found: format!("{dpi} dpi ({width}x{height} px); use SVG for large boards"),
        });
    }
    let extent = board.extent();
    let mut image = GrayImage::from_pixel(width, height, Luma([255]));
    let board_rows = (page.board_height * px_per_m).round() as u32;
    for j in 0..board_rows.min(height) {
        let y = extent.max.y - (j as f64 + 0.5) / px_per_m;
        for i in 0..width {
            let x = extent.min.x + (i as f64 + 0.5) / px_per_m - page.board_left;
            if board.is_white_at(x, y) == Some(false) {
                image.put_pixel(i, j, Luma([0]));
            }
        }
    }
    // Scale bar: alternating 10 mm blocks with an outline, 2 mm tall.
    let to_px = |m: f64| (m * px_per_m).round() as i64;
    let bar_x = to_px(page.board_left + 0.005);
    let bar_y = to_px(page.board_height + 0.004);
    let bar_h = to_px(0.002);
    let blocks = (page.scale_bar / 0.01).round() as i64;
    for k in 0..blocks {
        let x0 = bar_x + to_px(k as f64 * 0.01);
        let x1 = bar_x + to_px((k + 1) as f64 * 0.01);
        if k % 2 == 0 {
            draw::fill_rect(&mut image, x0, bar_y, x1 - x0, bar_h, Luma([0]));
        }
    }
    let outline = 1.max(to_px(0.0002));
    let bar_w = to_px(page.scale_bar);
    draw::fill_rect(&mut image, bar_x, bar_y, bar_w, outline, Luma([0]));
    draw::fill_rect(
        &mut image,
        bar_x,
        bar_y + bar_h - outline,
        bar_w,
        outline,
        Luma([0]),
    );
    draw::fill_rect(
        &mut image,
        bar_x + bar_w - outline,
        bar_y,
        outline,
        bar_h,
        Luma([0]),
    );
    let scale = 1.max(to_px(FONT_PIXEL_M)) as u32;
    let label = format!("{} mm", (page.scale_bar * 1000.0).round());
    draw::text(
        &mut image,
        bar_x + bar_w + to_px(0.003),
        bar_y,
        scale,
        &label,
        Luma([0]),
    );
    draw::text(
        &mut image,
        to_px(0.005),
        bar_y + to_px(0.008),
        scale,
        &page.caption,
        Luma([0]),
    );
    if show_frame {
        draw_frame(&mut image, board, &page, px_per_m);
    }
    let mut encoded = Vec::new();
    image::codecs::png::PngEncoder::new(&mut encoded)
        .write_image(image.as_raw(), width, height, image::ExtendedColorType::L8)
        .map_err(|source| TargetError::Image {
            path: "<board.png>".into(),
            source,
        })?;
    Ok(with_png_resolution(encoded, px_per_m.round() as u32))
}

/// Overlays the board frame: x and y axes from the origin, ids, tag 0's corner order.
fn draw_frame(image: &mut GrayImage, board: &Board, page: &Page, px_per_m: f64) {
    let extent = board.extent();
    let pixel = |x: f64, y: f64| {
        nalgebra::Point2::new(
            (x - extent.min.x + page.board_left) * px_per_m - 0.5,
            (extent.max.y - y) * px_per_m - 0.5,
        )
    };
    let grey = Luma([128]);
    let thickness = (0.0008 * px_per_m).round().max(1.0) as u32;
    let scale = ((0.0004 * px_per_m).round() as u32).max(1);
    let length = board.pitch() * 0.8 + board.tag_size() * 0.2;
    let glyph = 5.0 * scale as f64;
    for (end, label) in [((length, 0.0), "X"), ((0.0, length), "Y")] {
        let tip = pixel(end.0, end.1);
        draw::line(image, pixel(0.0, 0.0), tip, thickness, grey);
        let (dx, dy) = if label == "X" {
            (glyph * 0.6, -glyph * 0.5)
        } else {
            (-glyph * 0.3, -glyph * 1.6)
        };
        draw::text(
            image,
            (tip.x + dx) as i64,
            (tip.y + dy) as i64,
            scale,
            label,
            grey,
        );
    }
    let gap = board.tag_spacing() * board.tag_size();
    for tag in board.tags() {
        let c = tag.corners_in_target[0];
        let at = pixel(c.x, c.y - gap * 0.25);
        draw::text(
            image,
            at.x as i64 + 2,
            at.y as i64,
            scale,
            &format!("ID {}", tag.id),
            grey,
        );
    }
    if let Some(tag) = board.tags().first() {
        let offset = gap * 0.35;
        let signs = [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)];
        for (k, (corner, (sx, sy))) in tag.corners_in_target.iter().zip(signs).enumerate() {
            let at = pixel(corner.x + sx * offset, corner.y + sy * offset);
            draw::text(
                image,
                (at.x - glyph * 0.3) as i64,
                (at.y - glyph * 0.5) as i64,
                scale,
                &k.to_string(),
                grey,
            );
        }
    }
}

/// Inserts a pHYs chunk (pixels per metre) right after the PNG header chunk.
fn with_png_resolution(png: Vec<u8>, px_per_m: u32) -> Vec<u8> {
    // 8-byte signature + IHDR (4 length + 4 type + 13 data + 4 CRC).
    const AFTER_IHDR: usize = 8 + 25;
    let mut chunk_body = b"pHYs".to_vec();
    chunk_body.extend_from_slice(&px_per_m.to_be_bytes());
    chunk_body.extend_from_slice(&px_per_m.to_be_bytes());
    chunk_body.push(1); // unit: metre
    let mut out = Vec::with_capacity(png.len() + 21);
    out.extend_from_slice(&png[..AFTER_IHDR]);
    out.extend_from_slice(&9u32.to_be_bytes());
    out.extend_from_slice(&chunk_body);
    out.extend_from_slice(&crc32(&chunk_body).to_be_bytes());
    out.extend_from_slice(&png[AFTER_IHDR..]);
    out
}

/// CRC-32 (IEEE, reflected, as PNG specifies), bitwise: a handful of bytes per file.
fn crc32(bytes: &[u8]) -> u32 {
    let mut crc = 0xFFFF_FFFFu32;
    for &byte in bytes {
        crc ^= byte as u32;
        for _ in 0..8 {
            crc = if crc & 1 != 0 {
                (crc >> 1) ^ 0xEDB8_8320
            } else {
                crc >> 1
            };
        }
    }
    !crc
}

/// The board's black cells merged into horizontal runs, each `[left, top, width, height]` in
/// metres from the top-left corner of the board's sheet extent, y pointing down (page order).
/// Each cell's centre is sampled: the board's reflectance is the single source of truth.
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
    runs
}

/// The printable board as an SVG document in millimetres (black cells as merged rectangles).
pub fn board_svg(board: &Board) -> String {
    let page = Page::new(board, None);
    let mm = |m: f64| m * 1000.0;
    let mut svg = format!(
        "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"{w:.3}mm\" height=\"{h:.3}mm\" \
         viewBox=\"0 0 {w:.4} {h:.4}\">\n<rect width=\"100%\" height=\"100%\" fill=\"white\"/>\n<g fill=\"black\">\n",
        w = mm(page.width),
        h = mm(page.height)
    );
    for [left, top, width, height] in black_runs(board) {
        svg.push_str(&format!(
            "<rect x=\"{:.4}\" y=\"{:.4}\" width=\"{:.4}\" height=\"{:.4}\"/>\n",
            mm(page.board_left + left),
            mm(top),
            mm(width),
            mm(height)
        ));
    }
    let bar_x = mm(page.board_left + 0.005);
    let bar_y = mm(page.board_height + 0.004);
    let blocks = (page.scale_bar / 0.01).round() as usize;
    for k in (0..blocks).step_by(2) {
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
        mm(page.scale_bar),
        bar_x + mm(page.scale_bar) + 3.0,
        bar_y + 2.0,
        mm(page.scale_bar).round(),
        bar_y + 10.5,
        page.caption
    ));
    svg
}

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

    fn describe(&self) -> String {
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
const PDF_STRIP_M: f64 = 0.02;
/// Caption font size on a PDF page, pt (Courier: every glyph 0.6 em wide).
const PDF_FONT_PT: f64 = 7.0;
/// PostScript points per metre.
const PT_PER_M: f64 = 72.0 / 0.0254;

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
    )
}

/// The board's sheet extent (tags plus white margin), width and height, m.
fn extent_size(board: &Board) -> (f64, f64) {
    let e = board.extent();
    (e.max.x - e.min.x, e.max.y - e.min.y)
}

/// Whether `board` with the PDF strip under it fits the printable area of `sheet`.
fn fits(board: &Board, sheet: &Sheet) -> bool {
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

/// The printable board as a one-page vector PDF. With `sheet` the page is that sheet, the board
/// centred in its printable area (refused if it does not fit: fit it with [`fit_to_paper`]);
/// without, the page is the board's extent plus the strip. Under the board: a 100 mm (or
/// 50 mm) scale bar to measure after printing, and the board's parameters in Courier, with the
/// reminder to print at actual size.
pub fn board_pdf(board: &Board, sheet: Option<&Sheet>) -> Result<Vec<u8>, TargetError> {
    use pdf_writer::{Content, Name, Pdf, Rect, Ref, Str};

    let (bw, bh) = extent_size(board);
    let caption = format!(
        "aprilgrid {}x{} {} tagSize {} m tagSpacing {} first_id {} border_bits {}",
        board.cols(),
        board.rows(),
        board.family().name(),
        board.tag_size(),
        board.tag_spacing(),
        board.first_id(),
        board.border_bits()
    );
    let note = match sheet {
        Some(s) => format!(
            "{}: print at actual size (100 %), not 'fit to page'",
            s.describe()
        ),
        None => "print at actual size (100 %), not 'fit to page'".to_string(),
    };
    let char_m = 0.6 * PDF_FONT_PT / PT_PER_M;
    let text_w = caption.len().max(note.len()) as f64 * char_m;
    // Page size and the board's top-left corner on it, m from the page's top-left.
    let (page_w, page_h, left, top) = match sheet {
        Some(s) => {
            if !fits(board, s) || text_w > s.printable_m().0 + 1e-12 {
                return Err(TargetError::BadBoard {
                    path: "<print>".into(),
                    key: "tagSize".into(),
                    expected: format!("a board that fits {} (fit it to the paper)", s.describe()),
                    found: format!("{:.0} x {:.0} mm", bw * 1000.0, bh * 1000.0),
                });
            }
            let (w, h) = s.size_m();
            let block_h = bh + PDF_STRIP_M;
            (w, h, (w - bw) / 2.0, (h - block_h) / 2.0)
        }
        None => {
            let w = bw.max(text_w + 0.01);
            (w, bh + PDF_STRIP_M, (w - bw) / 2.0, 0.0)
        }
    };
    // PDF user space: points, origin bottom-left, y up.
    let pt = |m: f64| (m * PT_PER_M) as f32;
    let y_pt = |from_top_m: f64| pt(page_h - from_top_m);

    let mut content = Content::new();
    content.set_fill_gray(0.0);
    for [x, y, w, h] in black_runs(board) {
        content.rect(pt(left + x), y_pt(top + y + h), pt(w), pt(h));
    }
    content.fill_nonzero();
    let scale_bar: f64 = if bw >= 0.12 { 0.1 } else { 0.05 };
    let (bar_x, bar_top, bar_h) = (left + 0.005, top + bh + 0.004, 0.002);
    let blocks = (scale_bar / 0.01).round() as usize;
    for k in (0..blocks).step_by(2) {
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
    content.rect(pt(bar_x), y_pt(bar_top + bar_h), pt(scale_bar), pt(bar_h));
    content.stroke();
    // Captions start with the board, or further left (centred) when wider than it.
    let text_x = left.min((page_w - text_w) / 2.0).max(0.0);
    let font = Name(b"F1");
    let lines = [
        (
            bar_x + scale_bar + 0.003,
            bar_top + bar_h,
            format!("{} mm", (scale_bar * 1000.0).round()),
        ),
        (text_x, bar_top + 0.0075, caption),
        (text_x, bar_top + 0.0115, note),
    ];
    for (x, baseline, text) in &lines {
        content.begin_text();
        content.set_font(font, PDF_FONT_PT as f32);
        content.next_line(pt(*x), y_pt(*baseline));
        content.show(Str(text.as_bytes()));
        content.end_text();
    }
    let content = content.finish();

    let (catalog, tree, page, font_id, content_id) = (
        Ref::new(1),
        Ref::new(2),
        Ref::new(3),
        Ref::new(4),
        Ref::new(5),
    );
    let mut pdf = Pdf::new();
    pdf.catalog(catalog).pages(tree);
    pdf.pages(tree).kids([page]).count(1);
    {
        let mut p = pdf.page(page);
        p.parent(tree)
            .media_box(Rect::new(0.0, 0.0, pt(page_w), pt(page_h)))
            .contents(content_id);
        p.resources().fonts().pair(font, font_id);
    }
    pdf.type1_font(font_id).base_font(Name(b"Courier"));
    pdf.stream(content_id, &content);
    Ok(pdf.finish())
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::vision::TagFamily;

    #[test]
    fn png_is_true_scale_and_carries_its_resolution() {
        let board = Board::aprilgrid(2, 2, 0.04, 0.25, TagFamily::Tag36h11, 0, 1).unwrap();
        let png = board_png(&board, 254.0, false).unwrap();
        // 254 dpi = 10 000 px/m: the pHYs chunk says so.
        let at = png.windows(4).position(|w| w == b"pHYs").unwrap();
        assert_eq!(&png[at + 4..at + 8], &10_000u32.to_be_bytes());
        let image = image::load_from_memory(&png).unwrap().into_luma8();
        // Sheet 0.09 m + 2 x 0.01 m margin wide = 1100 px; height adds the 25 mm strip.
        assert_eq!(image.height(), 1100 + 250);
        // Row 105 crosses the top border row of tags 2 and 3: two black runs of 0.04 m
        // (400 px) separated by the 0.01 m gap (100 px).
        let row: Vec<bool> = (0..image.width())
            .map(|x| image.get_pixel(x, 105)[0] == 0)
            .collect();
        let mut runs = Vec::new();
        let mut x = 0;
        while x < row.len() {
            let start = x;
            while x < row.len() && row[x] == row[start] {
                x += 1;
            }
            runs.push((row[start], x - start));
        }
        let black: Vec<usize> = runs.iter().filter(|r| r.0).map(|r| r.1).collect();
        assert_eq!(black, vec![400, 400], "{runs:?}");
        let gap = runs.iter().position(|r| r.0).unwrap() + 1;
        assert_eq!(runs[gap], (false, 100));
        assert_eq!(crc32(b"IEND"), 0xAE42_6082);
    }

    #[test]
    fn svg_has_millimetre_page_and_every_tag() {
        let board = Board::aprilgrid(2, 2, 0.04, 0.25, TagFamily::Tag36h11, 0, 2).unwrap();
        let svg = board_svg(&board);
        assert!(svg.contains("height=\"135.000mm\""), "{}", &svg[..200]);
        assert!(svg.contains("tagSize 0.04 m"));
        assert!(svg.matches("<rect").count() > 4 * 10);
    }
}
