//! Image sharpness: how steep a frame's edges are, whatever its contrast or how much of it the
//! board fills. The one measure of the project: a hand-guided capture refuses a blurred frame
//! by it (an absolute threshold), a bag import keeps the sharpest frame of a standing interval
//! by it (a ranking).

use image::{GrayImage, ImageBuffer, Luma};

/// A frame's sharpness: the mean square of the 4-neighbour Laplacian over the mean square of
/// the (forward-difference) gradient, at half resolution (2×2 averages: sensor noise halves,
/// the work is a quarter). The ratio does not depend on the contrast or on how much of the
/// image has edges, only on how steep they are: a sharp step edge scores about 2, and blur by a
/// Gaussian of sigma s lowers it roughly as 1/s² (a board blurred by 2 px at full resolution
/// scores below 0.5). A frame without edges, or smaller than 6×6 pixels, scores 0.
pub fn sharpness(image: &GrayImage) -> f64 {
    sharpness_at(image, 2)
}

/// Largest block [`sharpness_at`] decimates by (a view of 1/64² of the frame sees no focus).
pub const MAX_BLOCK: usize = 64;

/// The same measure on a view decimated by `block` (`block`×`block` averages; 2 is
/// [`sharpness`]): the work is about one addition per pixel plus a `block²`-th of the filter's, so
/// 4 costs about half of 2. Steep edges still score about 2; blur is seen once it spans a block
/// or more (sigma of `block / 2` pixels and up). A bag import ranks a standing interval's frames
/// by it before scoring the winner with [`sharpness`]. `block` 0 or 1 is the full resolution;
/// blocks past [`MAX_BLOCK`] are taken as that.
pub fn sharpness_at<Pixels: std::ops::Deref<Target = [u8]>>(
    image: &ImageBuffer<Luma<u8>, Pixels>,
    block: usize,
) -> f64 {
    let b = block.clamp(1, MAX_BLOCK);
    let (sw, w, h) = (
        image.width() as usize,
        image.width() as usize / b,
        image.height() as usize / b,
    );
    if w < 3 || h < 3 {
        return 0.0;
    }
    // Sums of b×b blocks: b² times the averages, a scale the ratio does not see; exact (at most
    // 255·b² per block: no overflow of an i32 below blocks of 2900 pixels a side).
    let small = match b {
        2 => block_sums(image.as_raw(), sw, w, h, 2),
        4 => block_sums(image.as_raw(), sw, w, h, 4),
        _ => block_sums(image.as_raw(), sw, w, h, b),
    };
    let (mut laplacian, mut gradient) = (0f64, 0f64);
    for y in 1..h - 1 {
        // Per row in integers (at most (4·255·b²)² per pixel: no overflow in a row of u64), over
        // the row and its neighbours as slices, so the loop vectorises.
        let (up, row, down) = (
            &small[(y - 1) * w + 1..y * w - 1],
            &small[y * w..(y + 1) * w],
            &small[(y + 1) * w + 1..(y + 2) * w - 1],
        );
        let (left, centre, right) = (&row[..w - 2], &row[1..w - 1], &row[2..]);
        let (mut l_row, mut g_row) = (0u64, 0u64);
        for ((((&c, &l), &r), &u), &d) in centre.iter().zip(left).zip(right).zip(up).zip(down) {
            let square = |v: i32| u64::from(v.unsigned_abs()).pow(2);
            l_row += square(l + r + u + d - 4 * c);
            g_row += square(r - c) + square(d - c);
        }
        laplacian += l_row as f64;
        gradient += g_row as f64;
    }
    if gradient == 0.0 {
        return 0.0;
    }
    laplacian / gradient
}

/// The sums of the `b`×`b` blocks of the `w`×`h` blocks at the top left of a grey image `p` of
/// row length `sw`: each block row's columns summed over its `b` rows first (a loop the compiler
/// vectorises), then `b` columns at a time. Inlined, so a constant `b` makes its own loops.
#[inline(always)]
fn block_sums(p: &[u8], sw: usize, w: usize, h: usize, b: usize) -> Vec<i32> {
    let mut small = vec![0i32; w * h];
    // The columns' sums over `b` rows fit 16 bits (at most 255·b, b ≤ MAX_BLOCK): twice the
    // pixels an instruction of 32.
    let mut columns = vec![0u16; w * b];
    for (y, row) in small.chunks_exact_mut(w).enumerate() {
        columns.fill(0);
        for r in y * b..(y + 1) * b {
            for (c, &v) in columns.iter_mut().zip(&p[r * sw..r * sw + w * b]) {
                *c += u16::from(v);
            }
        }
        for (sum, block) in row.iter_mut().zip(columns.chunks_exact(b)) {
            *sum = block.iter().map(|&c| i32::from(c)).sum();
        }
    }
    small
}

/// A checkerboard of 16 px squares at the contrast `dark`/`light`, 256 px square: the pattern the
/// sharpness measure and the capture threshold that uses it are tested on.
pub fn checkerboard(dark: u8, light: u8) -> GrayImage {
    GrayImage::from_fn(256, 256, |x, y| {
        Luma([if (x / 16 + y / 16) % 2 == 0 {
            dark
        } else {
            light
        }])
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn blur_lowers_it_and_contrast_does_not_change_it() {
        let mut sharp_scores = Vec::new();
        for (dark, light) in [(30u8, 220u8), (100, 140)] {
            let sharp = checkerboard(dark, light);
            let slight = image::imageops::blur(&sharp, 0.7);
            let blurred = image::imageops::blur(&sharp, 5.0);
            let (s, t, b) = (sharpness(&sharp), sharpness(&slight), sharpness(&blurred));
            assert!(s > t && t > b, "{s} {t} {b}");
            // A step edge about 2; blur of sigma 5 px (2.5 at half resolution) far below.
            assert!((1.5..3.0).contains(&s), "a sharp board scores {s}");
            assert!(b < s / 4.0, "a board blurred by 5 px scores {b}, sharp {s}");
            // Decimated by 4: the same order, a sharp board still about 2.
            let (s4, b4) = (sharpness_at(&sharp, 4), sharpness_at(&blurred, 4));
            assert!(
                s4 > b4 && (1.5..3.0).contains(&s4),
                "by 4: sharp {s4}, blurred {b4}"
            );
            sharp_scores.push(s);
        }
        // The same edges at a quarter of the contrast: the same score.
        assert!(
            (sharp_scores[0] - sharp_scores[1]).abs() < 0.05 * sharp_scores[0],
            "{sharp_scores:?}"
        );
    }

    #[test]
    fn a_step_scores_far_above_a_ramp_and_a_flat_frame_scores_zero() {
        let edge = GrayImage::from_fn(20, 20, |x, _| Luma([if x < 10 { 0 } else { 200 }]));
        let ramp = GrayImage::from_fn(20, 20, |x, _| Luma([(x * 10) as u8]));
        assert!(
            sharpness(&edge) > 10.0 * sharpness(&ramp),
            "{} {}",
            sharpness(&edge),
            sharpness(&ramp)
        );
        assert_eq!(sharpness(&GrayImage::new(64, 64)), 0.0);
        assert_eq!(sharpness(&GrayImage::new(5, 40)), 0.0);
        assert_eq!(sharpness_at(&GrayImage::new(11, 40), 4), 0.0);
    }

    #[test]
    fn blocks_of_four_and_three_are_the_sums_written_out() {
        let noisy = GrayImage::from_fn(41, 27, |x, y| Luma([((x * 37 + y * 11) % 253) as u8]));
        let p = noisy.as_raw();
        for (b, w, h) in [(4usize, 10usize, 6usize), (3, 13, 9)] {
            let naive: Vec<i32> = (0..w * h)
                .map(|i| {
                    let (x, y) = (i % w, i / w);
                    (0..b * b)
                        .map(|k| i32::from(p[(b * y + k / b) * 41 + b * x + k % b]))
                        .sum()
                })
                .collect();
            assert_eq!(block_sums(p, 41, w, h, b), naive, "blocks of {b}");
        }
    }

    #[test]
    fn block_two_is_the_two_by_two_sum_written_out() {
        // The general block sum at 2 is exactly the 2×2 sums it replaced.
        let noisy = GrayImage::from_fn(37, 29, |x, y| Luma([((x * 31 + y * 17) % 251) as u8]));
        let (w, h) = (18usize, 14usize);
        let p = noisy.as_raw();
        let sums: Vec<i32> = (0..w * h)
            .map(|i| {
                let (x, y) = (i % w, i / w);
                let at = |dx: usize, dy: usize| i32::from(p[(2 * y + dy) * 37 + 2 * x + dx]);
                at(0, 0) + at(1, 0) + at(0, 1) + at(1, 1)
            })
            .collect();
        let (mut l, mut g) = (0f64, 0f64);
        for y in 1..h - 1 {
            for x in 1..w - 1 {
                let i = y * w + x;
                let c = sums[i];
                let lap = f64::from(sums[i - 1] + sums[i + 1] + sums[i - w] + sums[i + w] - 4 * c);
                let (dx, dy) = (f64::from(sums[i + 1] - c), f64::from(sums[i + w] - c));
                l += lap * lap;
                g += dx * dx + dy * dy;
            }
        }
        assert_eq!(sharpness(&noisy), l / g);
    }
}
