//! The SVG writer: the printable board as an SVG document in millimetres, black cells as merged
//! rectangles, with the scale bar and the board's parameters under it.
//!
//! Depends on the page geometry of its parent ([`print`](super)) and `vision::target`.

use super::super::target::AsTarget;
use super::{black_rects, Page};

/// The printable board (any `target_type`) as an SVG document in millimetres (black cells as
/// merged rectangles).
pub fn board_svg(target: &(impl AsTarget + ?Sized)) -> String {
    let target = target.as_target();
    let page = Page::new(&target, None);
    let mm = |m: f64| m * 1000.0;
    let mut svg = format!(
        "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"{w:.3}mm\" height=\"{h:.3}mm\" \
         viewBox=\"0 0 {w:.4} {h:.4}\">\n<rect width=\"100%\" height=\"100%\" fill=\"white\"/>\n<g fill=\"black\">\n",
        w = mm(page.width),
        h = mm(page.height)
    );
    for [left, top, width, height] in black_rects(&target) {
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{Board, TagFamily};

    #[test]
    fn svg_has_millimetre_page_and_every_tag() {
        let board = Board::aprilgrid(2, 2, 0.04, 0.25, TagFamily::Tag36h11, 0, 2).unwrap();
        let svg = board_svg(&board);
        assert!(svg.contains("height=\"135.000mm\""), "{}", &svg[..200]);
        assert!(svg.contains("tagSize 0.04 m"));
        assert!(svg.matches("<rect").count() > 4 * 10);
        // Kalibr's corner squares: one rectangle each, 3x3 for a 2x2 grid, and each tag's four
        // outer-ring corner cells, which lie on a square, turn black too (4 x 4).
        let plain = board_svg(&board.clone().with_corner_squares(false).unwrap());
        assert_eq!(
            svg.matches("<rect").count() - plain.matches("<rect").count(),
            9 + 16
        );
        assert!(plain.contains("corner_squares false"));
    }
}
