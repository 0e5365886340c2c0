//! The PNG writer: the printable board as an 8-bit grey raster at a chosen resolution, its
//! pixels per metre stored in a pHYs chunk so printing at 100 % keeps the true scale, with an
//! optional overlay of the board frame for documentation.
//!
//! Depends on the page geometry of its parent ([`print`](super)), `vision::target`,
//! `vision::draw`, the `image` crate and (for the pHYs chunk) the `png` crate.

use image::{GrayImage, Luma};

use super::super::draw;
use super::super::target::{AsTarget, Target};
use super::super::TargetError;
use super::{Page, FONT_PIXEL_M};

/// Renders the printable board (any `target_type`) as an 8-bit grey PNG at `dpi` (50-1200),
/// encoded, with its resolution stored so printers keep the true scale. `show_frame` overlays
/// the board frame for documentation (grey axes x and y from the origin; an aprilgrid's tag ids
/// under the tags and tag 0's corner numbers; a ChArUco board's or chessboard's corner ids);
/// leave it off for a board to print.
pub fn board_png(
    target: &(impl AsTarget + ?Sized),
    dpi: f64,
    show_frame: bool,
) -> Result<Vec<u8>, TargetError> {
    let target = target.as_target();
    let target: &Target = &target;
    if !(50.0..=1200.0).contains(&dpi) {
        return Err(TargetError::BadBoard {
            path: "<print>".into(),
            key: "dpi".to_string(),
            expected: "between 50 and 1200".to_string(),
            found: dpi.to_string(),
        });
    }
    let mut page = Page::new(target, Some(dpi));
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
    // Centre the board in the raster on a whole pixel, so its edges stay on pixel boundaries
    // where the board's cells allow and its place follows from the image width alone.
    let board_px = super::paper::extent_size(target).0 * px_per_m;
    page.board_left = ((width as f64 - board_px) / 2.0).round() / px_per_m;
    let extent = target.extent();
    let mut image = GrayImage::from_pixel(width, height, Luma([255]));
    let board_rows = (page.board_height * px_per_m).round() as u32;
    for j in 0..board_rows.min(height) {
        let y = extent.max.y - (j as f64 + 0.5) / px_per_m;
        for i in 0..width {
            let x = extent.min.x + (i as f64 + 0.5) / px_per_m - page.board_left;
            if target.is_white_at(x, y) == Some(false) {
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
        draw_frame(&mut image, target, &page, px_per_m);
    }
    encode_png(&image, px_per_m.round() as u32)
}

/// Encodes a grey image as PNG with its pixels per metre in the pHYs chunk (the `image`
/// crate's encoder cannot write that chunk; the `png` crate it uses can).
/// A printable board image as PNG with its resolution (`px_per_m`) in the pHYs chunk, so a
/// printer or viewer knows its true size.
fn encode_png(image: &GrayImage, px_per_m: u32) -> Result<Vec<u8>, TargetError> {
    encode_png_with_size(image, px_per_m).map_err(|source| TargetError::Image {
        path: "<board.png>".into(),
        source: image::ImageError::Encoding(image::error::EncodingError::new(
            image::ImageFormat::Png.into(),
            source,
        )),
    })
}

fn encode_png_with_size(image: &GrayImage, px_per_m: u32) -> Result<Vec<u8>, png::EncodingError> {
    let mut encoded = Vec::new();
    let mut encoder = png::Encoder::new(&mut encoded, image.width(), image.height());
    encoder.set_color(png::ColorType::Grayscale);
    encoder.set_depth(png::BitDepth::Eight);
    encoder.set_pixel_dims(Some(png::PixelDimensions {
        xppu: px_per_m,
        yppu: px_per_m,
        unit: png::Unit::Meter,
    }));
    let mut writer = encoder.write_header()?;
    writer.write_image_data(image.as_raw())?;
    writer.finish()?;
    Ok(encoded)
}

/// Overlays the board frame: x and y axes from the origin, and the ids the recorded corners
/// carry (an aprilgrid's tag ids and tag 0's corner order; ChArUco and chessboard corner ids).
fn draw_frame(image: &mut GrayImage, target: &Target, page: &Page, px_per_m: f64) {
    let extent = target.extent();
    let pixel = |x: f64, y: f64| {
        nalgebra::Point2::new(
            (x - extent.min.x + page.board_left) * px_per_m - 0.5,
            (extent.max.y - y) * px_per_m - 0.5,
        )
    };
    let grey = Luma([128]);
    let thickness = (0.0008 * px_per_m).round().max(1.0) as u32;
    let scale = ((0.0004 * px_per_m).round() as u32).max(1);
    let glyph = 5.0 * scale as f64;
    // Labels stay readable on white paper and on black squares alike (Kalibr's corner squares
    // sit where tag 0's corner numbers go): dark grey over light pixels, light grey over dark.
    let label = |image: &mut GrayImage, at: nalgebra::Point2<f64>, text: &str| {
        let mut mask = GrayImage::new(draw::text_width(text, scale), 5 * scale);
        draw::text(&mut mask, 0, 0, scale, text, Luma([255]));
        let (x0, y0) = (at.x as i64, at.y as i64);
        for (mx, my, m) in mask.enumerate_pixels() {
            let (x, y) = (x0 + mx as i64, y0 + my as i64);
            if m[0] == 0
                || x < 0
                || y < 0
                || x >= image.width() as i64
                || y >= image.height() as i64
            {
                continue;
            }
            let under = image.get_pixel(x as u32, y as u32)[0];
            image.put_pixel(
                x as u32,
                y as u32,
                Luma([if under < 128 { 190 } else { 90 }]),
            );
        }
    };
    let length = match target {
        Target::Aprilgrid(board) => board.pitch() * 0.8 + board.tag_size() * 0.2,
        Target::Charuco(c) => c.square_length() * 1.5,
        Target::Checkerboard(c) => c.col_spacing().min(c.row_spacing()) * 1.5,
    };
    for (end, name) in [((length, 0.0), "X"), ((0.0, length), "Y")] {
        let tip = pixel(end.0, end.1);
        draw::line(image, pixel(0.0, 0.0), tip, thickness, grey);
        let (dx, dy) = if name == "X" {
            (glyph * 0.6, -glyph * 0.5)
        } else {
            (-glyph * 0.3, -glyph * 1.6)
        };
        label(image, nalgebra::Point2::new(tip.x + dx, tip.y + dy), name);
    }
    let Target::Aprilgrid(board) = target else {
        // ChArUco / chessboard: each corner's id just above and right of it.
        for (id, _, point) in target.points() {
            let at = pixel(point.x, point.y);
            label(
                image,
                nalgebra::Point2::new(at.x + glyph * 0.4, at.y - glyph * 1.4),
                &id.to_string(),
            );
        }
        return;
    };
    let gap = board.tag_spacing() * board.tag_size();
    for tag in board.tags() {
        let c = tag.corners_in_target[0];
        let at = pixel(c.x, c.y - gap * 0.25);
        label(
            image,
            nalgebra::Point2::new(at.x + 2.0, at.y),
            &format!("ID {}", tag.id),
        );
    }
    if let Some(tag) = board.tags().first() {
        let offset = gap * 0.35;
        let signs = [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)];
        for (k, (corner, (sx, sy))) in tag.corners_in_target.iter().zip(signs).enumerate() {
            let at = pixel(corner.x + sx * offset, corner.y + sy * offset);
            label(
                image,
                nalgebra::Point2::new(at.x - glyph * 0.3, at.y - glyph * 0.5),
                &k.to_string(),
            );
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::TagFamily;

    #[test]
    fn png_is_true_scale_and_carries_its_resolution() {
        let board = crate::Board::aprilgrid(2, 2, 0.04, 0.25, TagFamily::Tag36h11, 0, 1).unwrap();
        let png = board_png(&board, 254.0, false).unwrap();
        // 254 dpi = 10 000 px/m: the pHYs chunk says so.
        let at = png.windows(4).position(|w| w == b"pHYs").unwrap();
        assert_eq!(&png[at + 4..at + 8], &10_000u32.to_be_bytes());
        assert_eq!(&png[at + 8..at + 12], &10_000u32.to_be_bytes());
        assert_eq!(png[at + 12], 1, "unit: metre");
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
    }
}
