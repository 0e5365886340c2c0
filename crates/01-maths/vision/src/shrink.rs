//! A grey frame made smaller for people (the report's frames, the console's live view) by box
//! filtering: `fast_image_resize`'s box convolution, each output pixel a mean of the input
//! pixels under it, in SIMD fixed point.
//!
//! Why not `image::imageops::thumbnail`: it gives each input pixel to one output pixel (aliasing
//! where the ratio is not an integer, as 1280 → 960), and its per-pixel float arithmetic was,
//! with the JPEG encoding, the largest part of a short bag import's CPU (issue #43).

use fast_image_resize::images::{Image, ImageRef};
use fast_image_resize::{FilterType, PixelType, ResizeAlg, ResizeOptions, Resizer};
use image::GrayImage;

/// `grey` scaled to `width` x `height` by a box filter; what went wrong otherwise (a size of
/// zero).
pub fn box_shrink(grey: &GrayImage, width: u32, height: u32) -> Result<GrayImage, String> {
    let source = ImageRef::new(grey.width(), grey.height(), grey.as_raw(), PixelType::U8)
        .map_err(|e| e.to_string())?;
    let mut scaled = Image::new(width, height, PixelType::U8);
    Resizer::new()
        .resize(
            &source,
            &mut scaled,
            &ResizeOptions::new().resize_alg(ResizeAlg::Convolution(FilterType::Box)),
        )
        .map_err(|e| e.to_string())?;
    GrayImage::from_raw(width, height, scaled.into_vec())
        .ok_or_else(|| format!("a {width}x{height} frame"))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The range of the input pixels the output pixel `(x, y)`'s area overlaps.
    fn covered_range(grey: &GrayImage, (width, height): (u32, u32), x: u32, y: u32) -> (u8, u8) {
        let (sx, sy) = (
            f64::from(grey.width()) / f64::from(width),
            f64::from(grey.height()) / f64::from(height),
        );
        let (x0, y0) = (f64::from(x) * sx, f64::from(y) * sy);
        let mut range = (u8::MAX, u8::MIN);
        for (i, j, p) in grey.enumerate_pixels() {
            let (i, j) = (f64::from(i), f64::from(j));
            if i + 1.0 > x0 && i < x0 + sx && j + 1.0 > y0 && j < y0 + sy {
                range = (range.0.min(p[0]), range.1.max(p[0]));
            }
        }
        range
    }

    fn noise(width: u32, height: u32) -> GrayImage {
        let mut state = 12345u32;
        GrayImage::from_fn(width, height, |_, _| {
            state = state.wrapping_mul(1_103_515_245).wrapping_add(12345);
            image::Luma([(state >> 16) as u8])
        })
    }

    #[test]
    fn invents_no_value_outside_what_each_output_pixel_covers_at_ratios_that_are_not_integers() {
        // 4:3 (1280 → 960, the report's), 3:2 and a ratio with no common factor: no ringing, no
        // aliasing into a pixel from outside its area, a flat frame stays flat.
        for (w, h, to_w, to_h) in [(16, 12, 12, 9), (15, 10, 10, 7), (23, 17, 7, 5)] {
            let grey = noise(w, h);
            let scaled = box_shrink(&grey, to_w, to_h).unwrap();
            assert_eq!(scaled.dimensions(), (to_w, to_h));
            for (x, y, p) in scaled.enumerate_pixels() {
                let (low, high) = covered_range(&grey, (to_w, to_h), x, y);
                assert!(
                    (low..=high).contains(&p[0]),
                    "{w}x{h} to {to_w}x{to_h} at ({x}, {y}): {} outside {low}..={high}",
                    p[0]
                );
            }
            let flat = GrayImage::from_pixel(w, h, image::Luma([77]));
            let scaled = box_shrink(&flat, to_w, to_h).unwrap();
            assert!(scaled.pixels().all(|p| p[0] == 77));
        }
    }

    #[test]
    fn halves_by_the_mean_of_each_two_by_two_block_and_keeps_a_same_size_frame() {
        let grey = noise(8, 6);
        let half = box_shrink(&grey, 4, 3).unwrap();
        for (x, y, p) in half.enumerate_pixels() {
            let block: u32 = [(0, 0), (1, 0), (0, 1), (1, 1)]
                .iter()
                .map(|(dx, dy)| u32::from(grey.get_pixel(2 * x + dx, 2 * y + dy)[0]))
                .sum();
            let mean = f64::from(block) / 4.0;
            assert!(
                (f64::from(p[0]) - mean).abs() <= 1.0,
                "({x}, {y}): {} against {mean}",
                p[0]
            );
        }
        assert_eq!(box_shrink(&grey, 8, 6).unwrap(), grey);
    }
}
