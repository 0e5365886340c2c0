//! A grey frame made smaller for the report by area averaging, in integers: each output pixel is
//! the mean of the input area it covers, partly covered pixels counted by the part covered.
//!
//! Why not `image::imageops::thumbnail`: it gives each input pixel to one output pixel (aliasing
//! where the ratio is not an integer, as 1280 → 960), and its per-pixel float arithmetic was,
//! with the JPEG encoding, the largest part of a short bag import's CPU (issue #43). Here the
//! overlaps are exact integers: measured in units of `1 / (input size × output size)` of the
//! frame, input pixel `i` spans `[i·out, (i+1)·out)` and output pixel `j` spans `[j·in, (j+1)·in)`.

use image::GrayImage;

/// For each output pixel along one axis: the first input pixel it covers and the covered length
/// of each input pixel from there (integers summing to `input`).
fn overlaps(input: u32, output: u32) -> Vec<(usize, Vec<u32>)> {
    (0..output)
        .map(|j| {
            let (start, end) = (j * input, (j + 1) * input);
            let first = start / output;
            let last = (end - 1) / output;
            let weights = (first..=last)
                .map(|i| end.min((i + 1) * output) - start.max(i * output))
                .collect();
            (first as usize, weights)
        })
        .collect()
}

/// `grey` scaled to `width` x `height` (each at most the input's and at least 1) by exact area
/// averaging, rounded to the nearest grey level.
pub(super) fn area_average(grey: &GrayImage, width: u32, height: u32) -> GrayImage {
    let (in_width, in_height) = grey.dimensions();
    assert!(
        (1..=in_width).contains(&width) && (1..=in_height).contains(&height),
        "area_average only makes a frame smaller: {in_width}x{in_height} to {width}x{height}"
    );
    let columns = overlaps(in_width, width);
    let rows = overlaps(in_height, height);
    // Rows first: each input row summed into `width` columns (weights summing to `in_width`, so
    // at most 255·in_width: within u32 for any frame), then the columns of those sums into
    // `height` rows (at most 255·in_width·in_height: within u64).
    let (width, height) = (width as usize, height as usize);
    let mut row_sums = vec![0u32; width * in_height as usize];
    for (row, sums) in grey
        .as_raw()
        .chunks_exact(in_width as usize)
        .zip(row_sums.chunks_exact_mut(width))
    {
        for ((first, weights), sum) in columns.iter().zip(sums.iter_mut()) {
            *sum = weights
                .iter()
                .zip(&row[*first..])
                .map(|(&w, &p)| w * u32::from(p))
                .sum();
        }
    }
    let total = u64::from(in_width) * u64::from(in_height);
    let mut sums = vec![0u64; width];
    let mut out = Vec::with_capacity(width * height);
    for (first, weights) in &rows {
        sums.fill(0);
        for (k, &w) in weights.iter().enumerate() {
            let row = &row_sums[(first + k) * width..][..width];
            for (sum, &s) in sums.iter_mut().zip(row) {
                *sum += u64::from(w) * u64::from(s);
            }
        }
        out.extend(sums.iter().map(|&sum| ((sum + total / 2) / total) as u8));
    }
    GrayImage::from_raw(width as u32, height as u32, out).expect("width x height pixels")
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The same mean in floating point, pixel by pixel: the area each input pixel shares with
    /// the output pixel, over the output pixel's area.
    fn reference(grey: &GrayImage, width: u32, height: u32) -> Vec<f64> {
        let (w_in, h_in) = (f64::from(grey.width()), f64::from(grey.height()));
        let (sx, sy) = (w_in / f64::from(width), h_in / f64::from(height));
        let overlap = |a0: f64, a1: f64, b0: f64, b1: f64| (a1.min(b1) - a0.max(b0)).max(0.0);
        let mut out = Vec::new();
        for y in 0..height {
            for x in 0..width {
                let (x0, y0) = (f64::from(x) * sx, f64::from(y) * sy);
                let mut sum = 0.0;
                for (i, j, p) in grey.enumerate_pixels() {
                    let (i, j) = (f64::from(i), f64::from(j));
                    sum += overlap(x0, x0 + sx, i, i + 1.0)
                        * overlap(y0, y0 + sy, j, j + 1.0)
                        * f64::from(p[0]);
                }
                out.push(sum / (sx * sy));
            }
        }
        out
    }

    fn noise(width: u32, height: u32) -> GrayImage {
        let mut state = 12345u32;
        GrayImage::from_fn(width, height, |_, _| {
            state = state.wrapping_mul(1_103_515_245).wrapping_add(12345);
            image::Luma([(state >> 16) as u8])
        })
    }

    #[test]
    fn is_the_rounded_area_mean_at_ratios_that_are_not_integers() {
        // 4:3 (1280 → 960, the report's), 3:2 and a ratio with no common factor.
        for (w, h, to_w, to_h) in [(16, 12, 12, 9), (15, 10, 10, 7), (23, 17, 7, 5)] {
            let grey = noise(w, h);
            let scaled = area_average(&grey, to_w, to_h);
            assert_eq!(scaled.dimensions(), (to_w, to_h));
            for (got, want) in scaled.as_raw().iter().zip(reference(&grey, to_w, to_h)) {
                assert!(
                    (f64::from(*got) - want).abs() <= 0.5 + 1e-9,
                    "{w}x{h} to {to_w}x{to_h}: {got} against {want}"
                );
            }
        }
    }

    #[test]
    fn halves_by_the_mean_of_each_two_by_two_block_and_keeps_a_same_size_frame() {
        let grey = noise(8, 6);
        let half = area_average(&grey, 4, 3);
        for (x, y, p) in half.enumerate_pixels() {
            let block: u32 = [(0, 0), (1, 0), (0, 1), (1, 1)]
                .iter()
                .map(|(dx, dy)| u32::from(grey.get_pixel(2 * x + dx, 2 * y + dy)[0]))
                .sum();
            assert_eq!(u32::from(p[0]), (block + 2) / 4, "({x}, {y})");
        }
        assert_eq!(area_average(&grey, 8, 6), grey);
    }
}
