//! Sub-pixel refinement of chessboard X-corners (ChArUco and plain chessboards) by gradient
//! orthogonality: at the true corner `q`, every image gradient `g(p)` near it is orthogonal to
//! `p - q` (it lies on an edge through `q`, or in a flat region where `g = 0`), so
//! `q = (Σ w g gᵀ)⁻¹ Σ w g gᵀ p` — Förstner's corner operator, the same criterion as OpenCV's
//! `cornerSubPix`. Gradients are sampled on a sub-pixel grid centred on the current estimate
//! (bilinear interpolation), Gaussian-weighted, and the estimate iterates to a fixed point.
//!
//! The integrator may unify this with the aprilgrid X-corner refinement (`vision::xcorner`).
//! Pixel convention: the project's (pixel centres at integers). Depends on nothing else in
//! the crate.

use image::GrayImage;
use nalgebra::{Matrix2, Point2, Vector2};

/// Largest half-window, px (measured on OpenCV-rendered chessboard frames: 0.4 of a square up
/// to 12 px, Gaussian weight σ = half-window, gives 0.035 px RMS where 0.3 / 7 px / σ = half/1.5
/// gave 0.041 px).
const MAX_HALF: f64 = 12.0;
/// Smallest half-window, px.
const MIN_HALF: f64 = 2.0;
/// Iterations at most.
const ITERATIONS: usize = 20;
/// Stop when an iteration moves the corner less than this, px.
const EPSILON: f64 = 1e-3;

/// Half-window for a corner whose squares are `square_px` pixels across (nearest
/// neighbouring corner distance): 0.4 of a square keeps the neighbouring corners' edges out.
pub fn window_for_square(square_px: f64) -> f64 {
    (square_px * 0.4).clamp(MIN_HALF, MAX_HALF)
}

/// Refines a corner starting at `start` with a half-window of `half` px; `None` when the
/// window leaves the image, the gradients do not pin a point (flat or a single edge) or the
/// estimate wanders off by more than the half-window.
pub fn refine(image: &GrayImage, start: Point2<f64>, half: f64) -> Option<Point2<f64>> {
    refine_masked(image, start, half, None)
}

/// Which samples of the window count: those within `band` squares of one of the two grid
/// lines through the corner, where `to_squares` maps a pixel offset to square units (the
/// inverse of the matrix whose columns are the pixel steps to the neighbouring corners along
/// the two grid directions). The edges through the corner lie on those lines; a ChArUco
/// marker's border, which does not pass through the corner, lies outside the band.
#[derive(Debug, Clone, Copy)]
pub struct GridMask {
    /// Pixel offset to square units.
    pub to_squares: Matrix2<f64>,
    /// Half-width of the band around each grid line, squares.
    pub band: f64,
}

/// [`refine`] counting only the samples `mask` keeps.
pub fn refine_masked(
    image: &GrayImage,
    start: Point2<f64>,
    half: f64,
    mask: Option<GridMask>,
) -> Option<Point2<f64>> {
    let (w, h) = (image.width() as f64, image.height() as f64);
    let mut q = start;
    let sigma = half;
    // Samples every half pixel; their offsets and Gaussian weights are the same in every
    // iteration.
    let steps = (half * 2.0).ceil() as i64;
    let samples: Vec<(Vector2<f64>, f64)> = (-steps..=steps)
        .flat_map(|j| (-steps..=steps).map(move |i| (i, j)))
        .map(|(i, j)| {
            let offset = Vector2::new(i as f64, j as f64) * (half / steps as f64);
            let weight = (-offset.norm_squared() / (2.0 * sigma * sigma)).exp();
            (offset, weight)
        })
        .collect();
    for _ in 0..ITERATIONS {
        if q.x - half < 1.0 || q.y - half < 1.0 || q.x + half > w - 2.0 || q.y + half > h - 2.0 {
            return None;
        }
        let mut a = Matrix2::zeros();
        let mut b = Vector2::zeros();
        for (offset, weight) in &samples {
            let p = q + offset;
            if let Some(mask) = &mask {
                let s = mask.to_squares * (p - start);
                if s.x.abs() > mask.band && s.y.abs() > mask.band {
                    continue;
                }
            }
            // Inside the image by a pixel (checked above), so every sample is.
            let g = gradient(image, p.x, p.y);
            let ggt = g * g.transpose() * *weight;
            a += ggt;
            b += ggt * p.coords;
        }
        let det = a.determinant();
        let trace = a.trace();
        // Both eigenvalues must be substantial: two edges cross here.
        if !(det > 1e-6 * trace * trace && trace > 0.0) {
            return None;
        }
        let next = Point2::from(a.try_inverse()? * b);
        let moved = (next - q).norm();
        q = next;
        if (q - start).norm() > half {
            return None;
        }
        if moved < EPSILON {
            break;
        }
    }
    Some(q)
}

/// Bilinear grey level at `p`, `None` outside the image.
pub fn grey_at(image: &GrayImage, p: Point2<f64>) -> Option<f64> {
    let inside = p.x >= 0.0
        && p.y >= 0.0
        && p.x + 1.0 < image.width() as f64
        && p.y + 1.0 < image.height() as f64;
    inside.then(|| sample(image, p.x, p.y))
}

/// Bilinear grey level at `(x, y)` (inside the image by one pixel, so `x, y ≥ 0`).
fn sample(image: &GrayImage, x: f64, y: f64) -> f64 {
    let (x0, fx) = split(x);
    let (y0, fy) = split(y);
    bilinear(image, x0, fx, y0, fy)
}

/// A non-negative coordinate as its pixel (`floor`) and the fraction beyond it. Truncation is
/// `floor` for these, and far cheaper than the library call `floor` becomes on baseline
/// x86-64 (an `i32` cast is one instruction where a `usize` cast takes several; images are far
/// narrower than `i32::MAX`).
fn split(t: f64) -> (usize, f64) {
    let i = t as i32;
    (i as usize, t - f64::from(i))
}

/// Bilinear grey level between pixels `(x0, y0)` and `(x0 + 1, y0 + 1)` at fractions `fx, fy`.
fn bilinear(image: &GrayImage, x0: usize, fx: f64, y0: usize, fy: f64) -> f64 {
    let width = image.width() as usize;
    let at = y0 * width + x0;
    let raw = image.as_raw();
    let (upper, lower) = (&raw[at..at + 2], &raw[at + width..at + width + 2]);
    let top = f64::from(upper[0]) * (1.0 - fx) + f64::from(upper[1]) * fx;
    let bottom = f64::from(lower[0]) * (1.0 - fx) + f64::from(lower[1]) * fx;
    top * (1.0 - fy) + bottom * fy
}

/// Central-difference gradient of the bilinear image (the two samples along x share their
/// row and fraction, the two along y their column).
fn gradient(image: &GrayImage, x: f64, y: f64) -> Vector2<f64> {
    const D: f64 = 0.5;
    let ((x0, fx), (y0, fy)) = (split(x), split(y));
    let ((left, fl), (right, fr)) = (split(x - D), split(x + D));
    let ((up, fu), (down, fd)) = (split(y - D), split(y + D));
    Vector2::new(
        bilinear(image, right, fr, y0, fy) - bilinear(image, left, fl, y0, fy),
        bilinear(image, x0, fx, down, fd) - bilinear(image, x0, fx, up, fu),
    ) / (2.0 * D)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A blurred X-corner at `(cx, cy)`, edges rotated 20° off the pixel axes (a smooth
    /// step of about a pixel, like a lens's blur).
    fn x_corner(cx: f64, cy: f64) -> GrayImage {
        let (c, s) = (20f64.to_radians().cos(), 20f64.to_radians().sin());
        GrayImage::from_fn(40, 40, |u, v| {
            let (x, y) = (u as f64 - cx, v as f64 - cy);
            let (xr, yr) = (c * x + s * y, -s * x + c * y);
            let value = 115.0 + 85.0 * (xr / 0.8).tanh() * (yr / 0.8).tanh();
            image::Luma([value.round() as u8])
        })
    }

    #[test]
    fn an_x_corner_is_found_to_a_hundredth_of_a_pixel() {
        let image = x_corner(19.37, 20.81);
        let q = refine(&image, Point2::new(18.6, 21.5), 5.0).unwrap();
        assert!((q - Point2::new(19.37, 20.81)).norm() < 0.01, "{q}");
    }

    #[test]
    fn a_flat_window_is_refused() {
        let image = GrayImage::from_pixel(40, 40, image::Luma([128]));
        assert!(refine(&image, Point2::new(20.0, 20.0), 5.0).is_none());
    }
}
