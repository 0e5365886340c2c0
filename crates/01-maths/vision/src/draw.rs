//! Small raster drawing for annotated frames and printed boards: lines, crosses and text in a
//! built-in 3x5 pixel font (scaled by whole pixels). Coordinates are pixels in the project
//! convention (centres at integers), and [`jpeg`] and [`grey_jpeg`], the one JPEG encoder of
//! frames shown to people (annotated live frames, the report's previews).
//! Depends on the `image` and `jpeg-encoder` crates only.

use image::{GenericImage, Pixel};
use nalgebra::Point2;

/// Sets a pixel if it lies inside the image.
fn put<I: GenericImage>(image: &mut I, x: i64, y: i64, colour: I::Pixel) {
    if x >= 0 && y >= 0 && (x as u64) < image.width() as u64 && (y as u64) < image.height() as u64 {
        image.put_pixel(x as u32, y as u32, colour);
    }
}

/// Fills the axis-aligned rectangle `[x, x + w) x [y, y + h)`, clipped to the image.
pub fn fill_rect<I: GenericImage>(image: &mut I, x: i64, y: i64, w: i64, h: i64, colour: I::Pixel)
where
    I::Pixel: Pixel,
{
    for yy in y.max(0)..(y + h).min(image.height() as i64) {
        for xx in x.max(0)..(x + w).min(image.width() as i64) {
            image.put_pixel(xx as u32, yy as u32, colour);
        }
    }
}

/// Draws a line `thickness` px wide (square brush), clipped to the image.
pub fn line<I: GenericImage>(
    image: &mut I,
    from: Point2<f64>,
    to: Point2<f64>,
    thickness: u32,
    colour: I::Pixel,
) {
    let length = (to - from).norm();
    if !length.is_finite() {
        return;
    }
    // Far off-image endpoints would make the loop long; such lines are clipped anyway.
    let limit = 4.0 * (image.width() + image.height()) as f64;
    if from.coords.amax() > limit || to.coords.amax() > limit {
        return;
    }
    let steps = (length.ceil() as usize).max(1) * 2;
    let half = thickness as i64 / 2;
    for i in 0..=steps {
        let p = from + (to - from) * (i as f64 / steps as f64);
        let (x, y) = (p.x.round() as i64, p.y.round() as i64);
        for dy in -half..=(thickness as i64 - 1 - half) {
            for dx in -half..=(thickness as i64 - 1 - half) {
                put(image, x + dx, y + dy, colour);
            }
        }
    }
}

/// Draws a `+` of half-size `radius` px centred on `at`.
pub fn cross<I: GenericImage>(image: &mut I, at: Point2<f64>, radius: f64, colour: I::Pixel) {
    line(
        image,
        at - nalgebra::Vector2::new(radius, 0.0),
        at + nalgebra::Vector2::new(radius, 0.0),
        1,
        colour,
    );
    line(
        image,
        at - nalgebra::Vector2::new(0.0, radius),
        at + nalgebra::Vector2::new(0.0, radius),
        1,
        colour,
    );
}

/// An annotated frame (grey with coloured marks) as JPEG at `quality` (1–100), for a page or
/// a live view: `jpeg-encoder` (SIMD) with the colour at half resolution (4:2:0), as cameras and
/// browsers use; the marks keep their place in the full-resolution grey. A quarter of the
/// `image` crate's encoder's time and three fifths of its size (measured on a 960x540 frame:
/// 2.95 ms, 50 KB against 11.9 ms, 85 KB), which had been a quarter of a bag import's CPU.
/// `Err` names what failed (a frame wider or taller than 65535 px).
pub fn jpeg(frame: &image::RgbImage, quality: u8) -> Result<Vec<u8>, String> {
    encode_jpeg(
        frame.as_raw(),
        (frame.width(), frame.height()),
        jpeg_encoder::ColorType::Rgb,
        quality,
    )
}

/// A grey frame as grey JPEG at `quality`: one plane, no colour conversion (a 960x540 frame of a
/// bag import took about 2.2 ms in a profile, against [`jpeg`]'s 2.95 ms). `Err` as [`jpeg`]'s.
pub fn grey_jpeg(frame: &image::GrayImage, quality: u8) -> Result<Vec<u8>, String> {
    encode_jpeg(
        frame.as_raw(),
        (frame.width(), frame.height()),
        jpeg_encoder::ColorType::Luma,
        quality,
    )
}

fn encode_jpeg(
    pixels: &[u8],
    (width, height): (u32, u32),
    colour: jpeg_encoder::ColorType,
    quality: u8,
) -> Result<Vec<u8>, String> {
    let size = |n: u32| u16::try_from(n).map_err(|_| format!("{n} px is too large for JPEG"));
    let (width, height) = (size(width)?, size(height)?);
    let mut bytes = Vec::new();
    let mut encoder = jpeg_encoder::Encoder::new(&mut bytes, quality);
    encoder.set_sampling_factor(jpeg_encoder::SamplingFactor::R_4_2_0);
    encoder
        .encode(pixels, width, height, colour)
        .map_err(|e| e.to_string())?;
    Ok(bytes)
}

/// Width in pixels of `text` drawn at `scale`.
pub fn text_width(text: &str, scale: u32) -> u32 {
    text.chars().count() as u32 * 4 * scale
}

/// Draws `text` with its top-left corner at `(x, y)`, each font pixel `scale` px square.
/// Lower case is drawn as upper case; characters without a glyph are drawn as `?`.
pub fn text<I: GenericImage>(
    image: &mut I,
    x: i64,
    y: i64,
    scale: u32,
    text: &str,
    colour: I::Pixel,
) where
    I::Pixel: Pixel,
{
    let s = scale.max(1) as i64;
    for (k, c) in text.chars().enumerate() {
        let rows = glyph(c);
        for (r, bits) in rows.iter().enumerate() {
            for col in 0..3 {
                if bits & (0b100 >> col) != 0 {
                    fill_rect(
                        image,
                        x + (4 * k as i64 + col) * s,
                        y + r as i64 * s,
                        s,
                        s,
                        colour,
                    );
                }
            }
        }
    }
}

/// The 3x5 glyph of a character: five rows, top first, bit 2 = left column.
fn glyph(c: char) -> [u8; 5] {
    match c.to_ascii_uppercase() {
        '0' => [7, 5, 5, 5, 7],
        '1' => [2, 6, 2, 2, 7],
        '2' => [7, 1, 7, 4, 7],
        '3' => [7, 1, 7, 1, 7],
        '4' => [5, 5, 7, 1, 1],
        '5' => [7, 4, 7, 1, 7],
        '6' => [7, 4, 7, 5, 7],
        '7' => [7, 1, 1, 1, 1],
        '8' => [7, 5, 7, 5, 7],
        '9' => [7, 5, 7, 1, 7],
        'A' => [2, 5, 7, 5, 5],
        'B' => [6, 5, 6, 5, 6],
        'C' => [3, 4, 4, 4, 3],
        'D' => [6, 5, 5, 5, 6],
        'E' => [7, 4, 6, 4, 7],
        'F' => [7, 4, 6, 4, 4],
        'G' => [3, 4, 5, 5, 3],
        'H' => [5, 5, 7, 5, 5],
        'I' => [7, 2, 2, 2, 7],
        'J' => [1, 1, 1, 5, 2],
        'K' => [5, 5, 6, 5, 5],
        'L' => [4, 4, 4, 4, 7],
        'M' => [5, 7, 7, 5, 5],
        'N' => [6, 5, 5, 5, 5],
        'O' => [2, 5, 5, 5, 2],
        'P' => [6, 5, 6, 4, 4],
        'Q' => [2, 5, 5, 6, 3],
        'R' => [6, 5, 6, 5, 5],
        'S' => [3, 4, 2, 1, 6],
        'T' => [7, 2, 2, 2, 2],
        'U' => [5, 5, 5, 5, 7],
        'V' => [5, 5, 5, 5, 2],
        'W' => [5, 5, 7, 7, 5],
        'X' => [5, 5, 2, 5, 5],
        'Y' => [5, 5, 2, 2, 2],
        'Z' => [7, 1, 2, 4, 7],
        '.' => [0, 0, 0, 0, 2],
        ',' => [0, 0, 0, 2, 4],
        ':' => [0, 2, 0, 2, 0],
        '-' => [0, 0, 7, 0, 0],
        '_' => [0, 0, 0, 0, 7],
        '=' => [0, 7, 0, 7, 0],
        '/' => [1, 1, 2, 4, 4],
        '(' => [2, 4, 4, 4, 2],
        '%' => [5, 1, 2, 4, 5],
        ')' => [2, 1, 1, 1, 2],
        ' ' => [0, 0, 0, 0, 0],
        _ => [7, 1, 2, 0, 2],
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_annotated_frame_decodes_to_its_grey_and_its_marks() {
        // Grey squares with a magenta line and a green cross, as the report draws them.
        let mut frame = image::RgbImage::from_fn(320, 180, |x, y| {
            let v = if (x / 40 + y / 40) % 2 == 0 { 40 } else { 210 };
            image::Rgb([v, v, v])
        });
        let magenta = image::Rgb([255, 0, 255]);
        line(
            &mut frame,
            Point2::new(10.0, 100.0),
            Point2::new(300.0, 100.0),
            2,
            magenta,
        );
        cross(
            &mut frame,
            Point2::new(60.0, 20.0),
            6.0,
            image::Rgb([0, 230, 0]),
        );
        let bytes = jpeg(&frame, 80).unwrap();
        // Decoded by the `image` crate's decoder (not the encoder's own code).
        let decoded = image::load_from_memory_with_format(&bytes, image::ImageFormat::Jpeg)
            .unwrap()
            .to_rgb8();
        assert_eq!(decoded.dimensions(), (320, 180));
        // Away from edges and marks the grey comes back within a few levels.
        for (x, y) in [(20, 60), (60, 60), (140, 150), (300, 20)] {
            let (got, want) = (decoded.get_pixel(x, y), frame.get_pixel(x, y));
            for c in 0..3 {
                assert!(
                    got[c].abs_diff(want[c]) <= 6,
                    "({x}, {y}): {got:?} vs {want:?}"
                );
            }
        }
        // The line is still magenta (red and blue well above green) on bright and dark squares,
        // the cross's centre green.
        for x in [30, 70, 150, 250] {
            let p = decoded.get_pixel(x, 100);
            assert!(p[0] > p[1] + 80 && p[2] > p[1] + 80, "({x}, 100): {p:?}");
        }
        let c = decoded.get_pixel(60, 20);
        assert!(c[1] > c[0] + 60 && c[1] > c[2] + 60, "cross: {c:?}");
        assert!(jpeg(&image::RgbImage::new(70_000, 1), 80).is_err());
    }
}
