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
    let steps = (half * 2.0).ceil() as i64; // samples every half pixel
    for _ in 0..ITERATIONS {
        if q.x - half < 1.0 || q.y - half < 1.0 || q.x + half > w - 2.0 || q.y + half > h - 2.0 {
            return None;
        }
        let mut a = Matrix2::zeros();
        let mut b = Vector2::zeros();
        for j in -steps..=steps {
            for i in -steps..=steps {
                let offset = Vector2::new(i as f64, j as f64) * (half / steps as f64);
                let p = q + offset;
                if let Some(mask) = &mask {
                    let s = mask.to_squares * (p - start);
                    if s.x.abs() > mask.band && s.y.abs() > mask.band {
                        continue;
                    }
                }
                let weight = (-offset.norm_squared() / (2.0 * sigma * sigma)).exp();
                let g = gradient(image, p.x, p.y);
                let ggt = g * g.transpose() * weight;
                a += ggt;
                b += ggt * p.coords;
            }
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

/// Bilinear grey level at `(x, y)` (inside the image by one pixel).
fn sample(image: &GrayImage, x: f64, y: f64) -> f64 {
    let (x0, y0) = (x.floor(), y.floor());
    let (fx, fy) = (x - x0, y - y0);
    let (x0, y0) = (x0 as u32, y0 as u32);
    let p = |xx: u32, yy: u32| f64::from(image.get_pixel(xx, yy)[0]);
    let top = p(x0, y0) * (1.0 - fx) + p(x0 + 1, y0) * fx;
    let bottom = p(x0, y0 + 1) * (1.0 - fx) + p(x0 + 1, y0 + 1) * fx;
    top * (1.0 - fy) + bottom * fy
}

/// Central-difference gradient of the bilinear image.
fn gradient(image: &GrayImage, x: f64, y: f64) -> Vector2<f64> {
    const D: f64 = 0.5;
    Vector2::new(
        sample(image, x + D, y) - sample(image, x - D, y),
        sample(image, x, y + D) - sample(image, x, y - D),
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
