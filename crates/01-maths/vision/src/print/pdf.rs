//! The PDF writer: the printable board as a one-page vector PDF (through `pdf-writer`), on its
//! own extent or centred on a sheet of paper, with the scale bar and the board's parameters in
//! Courier under it.
//!
//! Depends on the black rectangles of its parent ([`print`](super)), the sheets and fit check
//! of `print/paper.rs`, `vision::target` and `vision::TargetError`.

use super::super::target::AsTarget;
use super::super::TargetError;
use super::black_rects;
use super::paper::{extent_size, fits, Sheet, PDF_STRIP_M};

/// Caption font size on a PDF page, pt (Courier: every glyph 0.6 em wide).
const PDF_FONT_PT: f64 = 7.0;
/// PostScript points per metre.
const PT_PER_M: f64 = 72.0 / 0.0254;

/// The printable board (any `target_type`) as a one-page vector PDF. With `sheet` the page is that sheet, the board
/// centred in its printable area (refused if it does not fit: fit it with [`fit_to_paper`]);
/// without, the page is the board's extent plus the strip. Under the board: a 100 mm (or
/// 50 mm) scale bar to measure after printing, and the board's parameters in Courier, with the
/// reminder to print at actual size.
pub fn board_pdf(
    target: &(impl AsTarget + ?Sized),
    sheet: Option<&Sheet>,
) -> Result<Vec<u8>, TargetError> {
    use pdf_writer::{Content, Name, Str};

    let target = target.as_target();
    let (bw, bh) = extent_size(&target);
    let caption = super::caption(&target);
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
            if !fits(&target, s) || text_w > s.printable_m().0 + 1e-12 {
                return Err(TargetError::BadBoard {
                    path: "<print>".into(),
                    key: super::paper::size_keys(&target)[0].0.into(),
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
    for [x, y, w, h] in black_rects(&target) {
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

    Ok(one_page_pdf(content, font, pt(page_w), pt(page_h)))
}

/// A one-page PDF of `content` (drawn with the Courier font resource `font`) on a page of
/// `width_pt` x `height_pt` points: the document structure every printable board shares.
fn one_page_pdf(
    content: pdf_writer::Buf,
    font: pdf_writer::Name,
    width_pt: f32,
    height_pt: f32,
) -> Vec<u8> {
    use pdf_writer::{Name, Pdf, Rect, Ref};
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
            .media_box(Rect::new(0.0, 0.0, width_pt, height_pt))
            .contents(content_id);
        p.resources().fonts().pair(font, font_id);
    }
    pdf.type1_font(font_id).base_font(Name(b"Courier"));
    pdf.stream(content_id, &content);
    pdf.finish()
}
