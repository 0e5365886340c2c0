//! X-corners (saddle points): where two dark and two bright quadrants meet, as at the corners
//! of a chessboard's squares or where a Kalibr aprilgrid's tags touch its corner squares.
//!
//! [`refine_saddle`] moves a corner estimate to the saddle point of the image intensity to
//! sub-pixel precision, as Kalibr and most chessboard pipelines do: smooth the patch around
//! the estimate, fit a quadratic surface `I(x, y) = a·x² + b·x·y + c·y² + d·x + e·y + f` by
//! Gaussian-weighted least squares, step to its stationary point, and repeat until the step is
//! tiny. An ideal X-junction seen through any homography and a symmetric blur is point
//! symmetric about its centre, so the fit centred there has no linear term: the fixed point is
//! the junction itself, free of the bias edge fitting has at a corner. [`is_x_junction`]
//! checks that a point looks like an X-junction at all (four alternating sectors on a ring).
//!
//! Pixel convention: the project's (OpenCV's), pixel `(u, v)` has its centre at integer
//! coordinates. Depends on nothing else of ours (the `image` and `nalgebra` crates only).

use image::GrayImage;
use nalgebra::{Matrix6, Point2, Vector6};

/// Steps taken at most by [`refine_saddle`].
const MAX_ITERATIONS: usize = 20;
/// A step shorter than this ends the iteration, px.
const CONVERGED_PX: f64 = 1e-3;

/// Refines `initial` (px) to the saddle point of the image intensity within `half_window` px
/// (2 to 20: the patch is smoothed by a Gaussian of sigma `half_window / 2`, and the fit uses
/// the pixels within `half_window - 0.5` of the estimate, weighted by a Gaussian of the same
/// sigma tapered to zero at that radius). Choose the window inside the X-junction's four
/// quadrants: no other edge within it. `None` when the patch leaves the image, the surface is
/// not a saddle there (an edge, a plain corner, flat paper), the iteration does not settle, or
/// the saddle lies farther than `half_window` from `initial`.
pub fn refine_saddle(
    image: &GrayImage,
    initial: Point2<f64>,
    half_window: u32,
) -> Option<Point2<f64>> {
    if !((2..=20).contains(&half_window) && initial.x.is_finite() && initial.y.is_finite()) {
        return None;
    }
    let r = half_window as i64;
    let sigma_weight = half_window as f64 / 2.0;
    // The patch spans ±half_window px around the pixel nearest the estimate: a circle of this
    // radius around the estimate stays inside it.
    let reach = half_window as f64 - 0.5;
    // Smoothing before the fit: noise averages out, and a sharp X becomes smooth enough for
    // the quadratic model to hold over the window (and to be a saddle from a start ~2 px off).
    let sigma_smooth = half_window as f64 / 2.0;
    let pad = (3.0 * sigma_smooth).ceil() as i64;
    let mut p = initial;
    // The smoothed patch around the pixel nearest the estimate, kept while that pixel stays.
    let mut cached: Option<((i64, i64), Patch)> = None;
    for _ in 0..MAX_ITERATIONS {
        let (cx, cy) = (p.x.round() as i64, p.y.round() as i64);
        let patch = match cached {
            Some((at, patch)) if at == (cx, cy) => patch,
            _ => Patch::smoothed(image, cx, cy, r, pad, sigma_smooth)?,
        };
        let mut normal = Matrix6::<f64>::zeros();
        let mut rhs = Vector6::<f64>::zeros();
        for dy in -r..=r {
            for dx in -r..=r {
                // Offsets from the current estimate.
                let x = (cx + dx) as f64 - p.x;
                let y = (cy + dy) as f64 - p.y;
                // A Gaussian tapered to zero at `reach`: the window is round and has no edge,
                // so the pixels it takes in are balanced about the estimate.
                let d2 = x * x + y * y;
                let taper = (1.0 - d2 / (reach * reach)).max(0.0);
                let w = (-d2 / (2.0 * sigma_weight * sigma_weight)).exp() * taper * taper;
                let basis = Vector6::new(x * x, x * y, y * y, x, y, 1.0);
                normal += w * basis * basis.transpose();
                rhs += w * patch.at(dx, dy) * basis;
            }
        }
        cached = Some(((cx, cy), patch));
        let q = normal.cholesky()?.solve(&rhs);
        let (a, b, c, d, e) = (q[0], q[1], q[2], q[3], q[4]);
        // Stationary point of the quadric: [2a b; b 2c]·s = -[d; e]; a saddle needs det < 0.
        let det = 4.0 * a * c - b * b;
        // (NaN fails the test too.)
        if det.is_nan() || det >= 0.0 {
            return None;
        }
        let step = Point2::new((-2.0 * c * d + b * e) / det, (b * d - 2.0 * a * e) / det);
        if !(step.x.is_finite() && step.y.is_finite()) || step.coords.norm() > r as f64 {
            return None;
        }
        p += step.coords;
        if (p - initial).norm() > r as f64 {
            return None;
        }
        if step.coords.norm() < CONVERGED_PX {
            return Some(p);
        }
    }
    None
}

/// Whether `at` (px) looks like an X-junction on a ring of `radius` px: going round it, the
/// intensity (bilinear) crosses its mean exactly four times, opposite sectors agree, and the
/// two bright and two dark sectors differ by at least `min_contrast` grey levels. A plain
/// corner (one dark quadrant) crosses twice, an edge twice, flat paper not at all.
pub fn is_x_junction(image: &GrayImage, at: Point2<f64>, radius: f64, min_contrast: f64) -> bool {
    const SAMPLES: usize = 32;
    let mut ring = [0.0; SAMPLES];
    for (k, value) in ring.iter_mut().enumerate() {
        let angle = k as f64 * std::f64::consts::TAU / SAMPLES as f64;
        match bilinear(
            image,
            at.x + radius * angle.cos(),
            at.y + radius * angle.sin(),
        ) {
            Some(v) => *value = v,
            None => return false,
        }
    }
    let mean = ring.iter().sum::<f64>() / SAMPLES as f64;
    let crossings = (0..SAMPLES)
        .filter(|&k| (ring[k] > mean) != (ring[(k + 1) % SAMPLES] > mean))
        .count();
    if crossings != 4 {
        return false;
    }
    // Contrast between the sectors: the brightest and darkest of the ring, and the point
    // symmetry of an X (opposite samples alike) against a corner's asymmetry.
    let (min, max) = ring
        .iter()
        .fold((f64::MAX, f64::MIN), |(lo, hi), &v| (lo.min(v), hi.max(v)));
    let contrast = max - min;
    let asymmetry = (0..SAMPLES / 2)
        .map(|k| (ring[k] - ring[k + SAMPLES / 2]).abs())
        .sum::<f64>()
        / (SAMPLES / 2) as f64;
    contrast >= min_contrast && asymmetry < 0.25 * contrast
}

/// Bilinear intensity at `(x, y)` (pixel centres at integers), `None` outside the image.
fn bilinear(image: &GrayImage, x: f64, y: f64) -> Option<f64> {
    let (x0, y0) = (x.floor(), y.floor());
    if x0 < 0.0 || y0 < 0.0 || x0 + 1.0 >= image.width() as f64 || y0 + 1.0 >= image.height() as f64
    {
        return None;
    }
    let (fx, fy) = (x - x0, y - y0);
    let (i, j) = (x0 as u32, y0 as u32);
    let v = |u: u32, w: u32| image.get_pixel(u, w)[0] as f64;
    Some(
        (1.0 - fy) * ((1.0 - fx) * v(i, j) + fx * v(i + 1, j))
            + fy * ((1.0 - fx) * v(i, j + 1) + fx * v(i + 1, j + 1)),
    )
}

/// A Gaussian-smoothed square patch of half-size `r` around `(cx, cy)`.
struct Patch {
    r: i64,
    values: Vec<f64>,
}

impl Patch {
    /// `None` when the patch and its smoothing margin `pad` leave the image.
    fn smoothed(
        image: &GrayImage,
        cx: i64,
        cy: i64,
        r: i64,
        pad: i64,
        sigma: f64,
    ) -> Option<Patch> {
        let outer = r + pad;
        if cx - outer < 0
            || cy - outer < 0
            || cx + outer >= image.width() as i64
            || cy + outer >= image.height() as i64
        {
            return None;
        }
        let kernel: Vec<f64> = (-pad..=pad)
            .map(|k| (-(k * k) as f64 / (2.0 * sigma * sigma)).exp())
            .collect();
        let total: f64 = kernel.iter().sum();
        let kernel: Vec<f64> = kernel.iter().map(|k| k / total).collect();
        let raw = |dx: i64, dy: i64| image.get_pixel((cx + dx) as u32, (cy + dy) as u32)[0] as f64;
        // Rows first (over the padded height), then columns.
        let rows_side = (2 * outer + 1) as usize;
        let side = (2 * r + 1) as usize;
        let mut horizontal = vec![0.0; rows_side * side];
        for (row, dy) in (-outer..=outer).enumerate() {
            for (col, dx) in (-r..=r).enumerate() {
                horizontal[row * side + col] = kernel
                    .iter()
                    .zip(-pad..=pad)
                    .map(|(k, o)| k * raw(dx + o, dy))
                    .sum();
            }
        }
        let mut values = vec![0.0; side * side];
        for row in 0..side {
            for col in 0..side {
                values[row * side + col] = kernel
                    .iter()
                    .enumerate()
                    .map(|(o, k)| k * horizontal[(row + o) * side + col])
                    .sum();
            }
        }
        Some(Patch { r, values })
    }

    fn at(&self, dx: i64, dy: i64) -> f64 {
        let side = 2 * self.r + 1;
        self.values[((dy + self.r) * side + dx + self.r) as usize]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// An X-junction at `centre` between two lines through it (directions `a1`, `a2` in
    /// radians), drawn with 32x32 supersampling (edges placed to 1/64 px): dark where the two
    /// signed distances agree.
    fn x_image(centre: Point2<f64>, a1: f64, a2: f64, noise: u32) -> GrayImage {
        let mut state = noise.wrapping_mul(2_654_435_761).max(1);
        GrayImage::from_fn(48, 48, |u, v| {
            let mut sum = 0.0;
            for k in 0..1024 {
                let x = u as f64 + ((k % 32) as f64 + 0.5) / 32.0 - 0.5 - centre.x;
                let y = v as f64 + ((k / 32) as f64 + 0.5) / 32.0 - 0.5 - centre.y;
                let s1 = -a1.sin() * x + a1.cos() * y;
                let s2 = -a2.sin() * x + a2.cos() * y;
                sum += if (s1 > 0.0) == (s2 > 0.0) {
                    30.0
                } else {
                    220.0
                };
            }
            // A small xorshift for sensor noise (±noise grey levels).
            state ^= state << 13;
            state ^= state >> 17;
            state ^= state << 5;
            let n = if noise == 0 {
                0.0
            } else {
                (state % (2 * noise + 1)) as f64 - noise as f64
            };
            image::Luma([(sum / 1024.0 + n).round().clamp(0.0, 255.0) as u8])
        })
    }

    #[test]
    fn saddle_is_found_to_a_small_fraction_of_a_pixel_through_perspective_and_noise() {
        for (k, (cx, cy, a1, a2)) in [
            (23.3, 24.1, 0.0, 90.0),
            (24.71, 22.45, 20.0, 95.0),
            (22.5, 25.5, -35.0, 40.0),
            (24.02, 23.87, 10.0, 60.0),
        ]
        .into_iter()
        .enumerate()
        {
            let truth = Point2::new(cx, cy);
            for noise in [0, 3] {
                let image = x_image(
                    truth,
                    f64::to_radians(a1),
                    f64::to_radians(a2),
                    noise + k as u32,
                );
                let start = truth + nalgebra::Vector2::new(1.4, -1.1);
                let found = refine_saddle(&image, start, 4).expect("a saddle");
                let error = (found - truth).norm();
                // Noise-free: the edges are placed to 1/64 px; noisy: ±3 grey levels.
                let limit = if noise == 0 { 0.03 } else { 0.05 };
                assert!(
                    error < limit,
                    "case {k} noise {noise}: {found} vs {truth}: {error} px"
                );
                assert!(is_x_junction(&image, found, 3.0, 40.0), "case {k}");
            }
        }
    }

    #[test]
    fn edges_plain_corners_flat_patches_and_borders_are_refused() {
        // A plain corner: one dark quadrant.
        let corner = GrayImage::from_fn(40, 40, |u, v| {
            image::Luma([if u < 20 && v < 20 { 30 } else { 220 }])
        });
        let at = Point2::new(19.5, 19.5);
        assert!(!is_x_junction(&corner, at, 3.0, 40.0));
        let edge = GrayImage::from_fn(40, 40, |u, _| image::Luma([if u < 20 { 30 } else { 220 }]));
        assert!(refine_saddle(&edge, at, 4).is_none());
        assert!(!is_x_junction(&edge, at, 3.0, 40.0));
        let flat = GrayImage::from_pixel(40, 40, image::Luma([128]));
        assert!(refine_saddle(&flat, at, 4).is_none());
        assert!(!is_x_junction(&flat, at, 3.0, 40.0));
        // Too close to the border for the window, and an out-of-range window.
        let x = x_image(Point2::new(3.0, 3.0), 0.0, 1.5, 0);
        assert!(refine_saddle(&x, Point2::new(3.0, 3.0), 4).is_none());
        assert!(refine_saddle(&x, Point2::new(24.0, 24.0), 1).is_none());
        assert!(refine_saddle(&x, Point2::new(f64::NAN, 24.0), 4).is_none());
    }
}
