//! The camera simulator: renders the grey frame a camera with a given [`CameraModel`] sees of a
//! [`Target`] (aprilgrid, ChArUco or chessboard) at `T_camera_target`.
//!
//! Rendering is inverse-mapped: every pixel's ray is undistorted exactly (Gauss-Newton,
//! warm-started from the neighbouring pixel) and intersected with the board plane through the
//! homography `[r1 r2 t]`, so the image is exact for any pose and lens. Anti-aliasing
//! supersamples each pixel on an `s x s` grid, using the lens's local linearisation inside the
//! pixel (error far below 1e-4 px). Then exposure, optional Gaussian blur and Gaussian sensor
//! noise (seeded by the caller's RNG). Pixel convention: OpenCV's, pixel `(u, v)` covers
//! `[u - 0.5, u + 0.5) x [v - 0.5, v + 0.5)`. Rows are rendered on all cores with scoped std
//! threads. Depends on `camera_model`, `vision::target` and `geometry`.

use std::sync::{Arc, Mutex, PoisonError, Weak};

use image::GrayImage;
use nalgebra::{Matrix2, Matrix3, Vector2, Vector3};
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};
use rand_distr::{Distribution, Normal};

use handeye_core::camera_model::{CameraModel, Distortion};
use handeye_core::geometry::Pose;
use handeye_core::memory::{try_filled, try_with_capacity, NotEnoughMemory};
use handeye_vision::target::AsTarget;
use handeye_vision::Target;

/// What the simulated sensor adds to the ideal image. Grey levels are 0-255.
#[derive(Debug, Clone, PartialEq)]
pub struct RenderOptions {
    /// Samples per pixel along each axis (1 = no anti-aliasing).
    pub supersample: u32,
    /// Grey level of white paper at exposure 1.
    pub white_level: f64,
    /// Grey level of black ink at exposure 1.
    pub black_level: f64,
    /// Mean grey level of the scene behind the board.
    pub background_level: f64,
    /// Peak-to-peak variation of the background (smooth gradient and waves), grey levels.
    pub background_variation: f64,
    /// Exposure gain applied to the whole scene before clipping.
    pub exposure: f64,
    /// Gaussian blur sigma, px (0 = none): defocus and the lens's point spread.
    pub blur_sigma_px: f64,
    /// Standard deviation of additive Gaussian sensor noise, grey levels (0 = none).
    pub noise_sigma: f64,
}

impl Default for RenderOptions {
    fn default() -> Self {
        RenderOptions {
            supersample: 3,
            white_level: 215.0,
            black_level: 25.0,
            background_level: 110.0,
            background_variation: 60.0,
            exposure: 1.0,
            blur_sigma_px: 0.0,
            noise_sigma: 2.0,
        }
    }
}

/// Every pixel's undistorted ray through its centre. It depends on the lens only, and
/// undistorting is about half of a render's work, so a camera that renders many frames
/// ([`super::sim::SimCamera`]) computes it once.
pub struct PixelRays {
    /// Row-major, `None` where the lens model cannot be inverted.
    rays: Vec<Option<PixelRay>>,
}

impl PixelRays {
    /// The rays of every pixel of `camera`'s image, or the error when the table's memory cannot
    /// be had.
    pub fn new(camera: &CameraModel) -> Result<Self, NotEnoughMemory> {
        let (width, height) = (camera.width as usize, camera.height as usize);
        let what = "the simulated camera's table of pixel rays";
        let mut rays = try_with_capacity(what, width * height)?;
        for v in 0..height {
            let mut warm: Option<Vector2<f64>> = None;
            for u in 0..width {
                let xd = Vector2::new(
                    (u as f64 - camera.cx) / camera.fx,
                    (v as f64 - camera.cy) / camera.fy,
                );
                let ray =
                    undistort_warm(&camera.distortion, xd, warm).map(|(xn, jacobian_inverse)| {
                        PixelRay {
                            xn,
                            jacobian_inverse,
                        }
                    });
                // Predict the next pixel's solution along the row: Newton then starts ~1e-7
                // away.
                warm = ray
                    .as_ref()
                    .map(|r| r.xn + r.jacobian_inverse * Vector2::new(1.0 / camera.fx, 0.0));
                rays.push(ray);
            }
        }
        Ok(PixelRays { rays })
    }

    /// The rays of `camera`'s lens, shared with every other user of the same lens in this
    /// process while one of them holds it. The table is 56 bytes a pixel (52 MB at 1280 x 720),
    /// so a simulated cell of several cameras with one lens, or the tests' many simulated cells
    /// at once, would otherwise hold a copy each. Computed by the first to ask, the others
    /// waiting for it; identical to [`PixelRays::new`] of the lens.
    /// The error: a new table's memory could not be had.
    pub fn shared(camera: &CameraModel) -> Result<Arc<PixelRays>, NotEnoughMemory> {
        static TABLES: Mutex<Vec<(CameraModel, Weak<PixelRays>)>> = Mutex::new(Vec::new());
        // A panic elsewhere while the lock was held leaves the list as valid as before.
        let mut tables = TABLES.lock().unwrap_or_else(PoisonError::into_inner);
        tables.retain(|(_, table)| table.strong_count() > 0);
        if let Some(table) = tables
            .iter()
            .find(|(lens, _)| lens == camera)
            .and_then(|(_, table)| table.upgrade())
        {
            return Ok(table);
        }
        let table = Arc::new(PixelRays::new(camera)?);
        tables.push((*camera, Arc::downgrade(&table)));
        Ok(table)
    }
}

/// Renders `board` seen by `camera` at `camera_from_target`: the convenience of tests and
/// benches, which panics when the frame's memory cannot be had (a camera renders with
/// [`render_with_rays`], which returns the error).
pub fn render(
    board: &(impl AsTarget + ?Sized),
    camera: &CameraModel,
    camera_from_target: &Pose,
    options: &RenderOptions,
    rng: &mut impl Rng,
) -> GrayImage {
    PixelRays::new(camera)
        .and_then(|rays| render_with_rays(board, camera, &rays, camera_from_target, options, rng))
        .unwrap_or_else(|e| panic!("{e}"))
}

/// [`render`] with the lens's rays computed beforehand (`rays` must be of this `camera`), or
/// the error when the frame's buffers (5 bytes a pixel, 4 more with blur) cannot be had: a
/// simulated camera under a memory limit reports it as a camera error rather than aborting the
/// run.
pub fn render_with_rays(
    board: &(impl AsTarget + ?Sized),
    camera: &CameraModel,
    rays: &PixelRays,
    camera_from_target: &Pose,
    options: &RenderOptions,
    rng: &mut impl Rng,
) -> Result<GrayImage, NotEnoughMemory> {
    let board = board.as_target();
    let board: &Target = &board;
    let (width, height) = (camera.width as usize, camera.height as usize);
    assert_eq!(rays.rays.len(), width * height, "rays of another camera");
    if width == 0 || height == 0 {
        return Ok(GrayImage::new(camera.width, camera.height));
    }
    let what = format!("a simulated frame at {width}x{height}");
    let mut radiance = try_filled(&what, width * height, 0f32)?;
    let rotation = camera_from_target.rotation.to_rotation_matrix();
    let r = rotation.matrix();
    let t = camera_from_target.translation.vector;
    let camera_from_plane = Matrix3::from_columns(&[r.column(0).into(), r.column(1).into(), t]);
    // A board seen edge-on (or a degenerate pose) shows only background.
    let plane_from_camera = camera_from_plane.try_inverse();
    let threads = std::thread::available_parallelism()
        .map(|n| n.get())
        .unwrap_or(1)
        .min(height.max(1));
    let rows_per_chunk = height.div_ceil(threads).max(1);
    let background_table = &Background::new(width);
    run_parallel(radiance.chunks_mut(rows_per_chunk * width).enumerate().map(
        |(chunk_index, chunk)| {
            let first_row = chunk_index * rows_per_chunk;
            let chunk_rays = &rays.rays[first_row * width..first_row * width + chunk.len()];
            move || {
                render_rows(
                    board,
                    camera,
                    plane_from_camera.as_ref(),
                    background_table,
                    options,
                    first_row,
                    width,
                    chunk_rays,
                    chunk,
                );
            }
        },
    ));
    if options.blur_sigma_px > 0.0 {
        let mut temp = try_filled(&what, radiance.len(), 0f32)?;
        gaussian_blur(
            &mut radiance,
            &mut temp,
            (width, height),
            options.blur_sigma_px,
            threads,
        );
    }
    let noise = (options.noise_sigma > 0.0)
        .then(|| Normal::new(0.0f32, options.noise_sigma as f32).ok())
        .flatten();
    // One RNG per chunk, seeded from the caller's: deterministic for a given seed and thread
    // count, and the noise is drawn on all cores.
    let mut pixels = try_filled(&what, width * height, 0u8)?;
    let seeds: Vec<u64> = (0..threads).map(|_| rng.random()).collect();
    let noise = noise.as_ref();
    run_parallel(
        pixels
            .chunks_mut(rows_per_chunk * width)
            .zip(radiance.chunks(rows_per_chunk * width))
            .zip(seeds)
            .map(|((out, input), seed)| {
                move || {
                    let mut chunk_rng = StdRng::seed_from_u64(seed);
                    for (pixel, value) in out.iter_mut().zip(input) {
                        let noisy = match noise {
                            Some(n) => value + n.sample(&mut chunk_rng),
                            None => *value,
                        };
                        *pixel = noisy.round().clamp(0.0, 255.0) as u8;
                    }
                }
            }),
    );
    Ok(
        GrayImage::from_raw(camera.width, camera.height, pixels)
            .expect("buffer sized to the image"),
    )
}

/// What one sample ray sees: `Some(true)` white, `Some(false)` black, `None` background.
type Hit = Option<bool>;

/// A pixel centre's undistorted normalised point and the inverse distortion Jacobian there:
/// the lens linearised over the pixel.
#[derive(Clone, Copy, PartialEq)]
struct PixelRay {
    xn: Vector2<f64>,
    jacobian_inverse: Matrix2<f64>,
}

/// Casts the ray through `(dx, dy)` px from the pixel centre onto the board plane.
fn cast(
    board: &Target,
    camera: &CameraModel,
    plane_from_camera: &Matrix3<f64>,
    ray: &PixelRay,
    dx: f64,
    dy: f64,
) -> Hit {
    let step = ray.jacobian_inverse * Vector2::new(dx / camera.fx, dy / camera.fy);
    let p = plane_from_camera * Vector3::new(ray.xn.x + step.x, ray.xn.y + step.y, 1.0);
    // p.z > 0: the board point is in front of the camera.
    if p.z > 1e-12 {
        board.is_white_at(p.x / p.z, p.y / p.z)
    } else {
        None
    }
}

/// Renders a block of consecutive rows starting at `first_row` into `block` (`width` wide).
///
/// Supersampling is spent only where an edge passes: the rays through every pixel corner are
/// cast once (shared by the four pixels that meet there), and a pixel whose centre and four
/// corners see the same thing is uniform. Cells are several pixels wide, so nothing thinner
/// than a pixel can hide between the corners.
#[allow(clippy::too_many_arguments)]
fn render_rows(
    board: &Target,
    camera: &CameraModel,
    plane_from_camera: Option<&Matrix3<f64>>,
    background: &Background,
    options: &RenderOptions,
    first_row: usize,
    width: usize,
    block_rays: &[Option<PixelRay>],
    block: &mut [f32],
) {
    let s = options.supersample.max(1);
    let offsets: Vec<f64> = (0..s).map(|i| (i as f64 + 0.5) / s as f64 - 0.5).collect();
    let samples = (s * s) as f64;
    let mut top: Vec<Hit> = vec![None; width + 1];
    let mut bottom: Vec<Hit> = vec![None; width + 1];
    let mut have_top = false;
    for (k, row) in block.chunks_mut(width).enumerate() {
        let v = first_row + k;
        let background_row = background.row(v, camera.height as usize);
        let Some(plane_from_camera) = plane_from_camera else {
            for (u, out) in row.iter_mut().enumerate() {
                *out = (background.level(options, u, background_row) * options.exposure) as f32;
            }
            continue;
        };
        let rays = &block_rays[k * width..(k + 1) * width];
        let corner = |c: usize, dy: f64| -> Hit {
            let (pixel, dx) = if c < width {
                (c, -0.5)
            } else {
                (width - 1, 0.5)
            };
            rays[pixel]
                .as_ref()
                .and_then(|ray| cast(board, camera, plane_from_camera, ray, dx, dy))
        };
        if s > 1 {
            if !have_top {
                for (c, hit) in top.iter_mut().enumerate() {
                    *hit = corner(c, -0.5);
                }
            }
            for (c, hit) in bottom.iter_mut().enumerate() {
                *hit = corner(c, 0.5);
            }
        }
        for (u, out) in row.iter_mut().enumerate() {
            let background_level = background.level(options, u, background_row);
            let level = |hit: Hit| match hit {
                Some(true) => options.white_level,
                Some(false) => options.black_level,
                None => background_level,
            };
            let value = match &rays[u] {
                None => background_level,
                Some(ray) => {
                    let centre = cast(board, camera, plane_from_camera, ray, 0.0, 0.0);
                    let uniform = s == 1
                        || (top[u] == centre
                            && top[u + 1] == centre
                            && bottom[u] == centre
                            && bottom[u + 1] == centre);
                    if uniform {
                        level(centre)
                    } else {
                        let mut sum = 0.0;
                        for dy in &offsets {
                            for dx in &offsets {
                                sum += level(cast(board, camera, plane_from_camera, ray, *dx, *dy));
                            }
                        }
                        sum / samples
                    }
                }
            };
            *out = (value * options.exposure) as f32;
        }
        std::mem::swap(&mut top, &mut bottom);
        have_top = true;
    }
}

/// Undistorts normalised coordinates starting from a neighbour's solution; returns the
/// undistorted point and the inverse distortion Jacobian there.
fn undistort_warm(
    distortion: &Distortion,
    xd: Vector2<f64>,
    warm: Option<Vector2<f64>>,
) -> Option<(Vector2<f64>, Matrix2<f64>)> {
    if matches!(distortion, Distortion::None) {
        return Some((xd, Matrix2::identity()));
    }
    let mut xn = warm.unwrap_or(xd);
    for _ in 0..20 {
        let error = distortion.distort(xn) - xd;
        let jacobian_inverse = distortion.jacobian(xn).try_inverse()?;
        let error_norm = error.norm();
        if error_norm < 1e-13 {
            return Some((xn, jacobian_inverse));
        }
        xn -= jacobian_inverse * error;
        // Newton converges quadratically (the lens's second derivatives are O(1) in
        // normalised units): from an error below 1e-7 one step lands near 1e-14, i.e.
        // ~1e-11 px, so the confirming evaluation is skipped. The Jacobian moved by 1e-7
        // relative, far below what the in-pixel linearisation needs.
        if error_norm < 1e-7 {
            return Some((xn, jacobian_inverse));
        }
        if !(xn.x.is_finite() && xn.y.is_finite()) {
            break;
        }
    }
    // A cold start can still converge where a warm one could not (after a discontinuity).
    if warm.is_some() {
        return undistort_warm(distortion, xd, None);
    }
    None
}

/// The smooth non-uniform background: a gradient plus a low-frequency wave. The column part
/// is tabulated once per frame (`column_wave`), so a pixel costs a multiply-add.
struct Background {
    column_wave: Vec<f64>,
    column_ramp: Vec<f64>,
}

impl Background {
    fn new(width: usize) -> Self {
        let x = |u: usize| u as f64 / width.max(1) as f64;
        Background {
            column_wave: (0..width)
                .map(|u| (std::f64::consts::TAU * (1.3 * x(u) + 0.4)).sin())
                .collect(),
            column_ramp: (0..width).map(|u| x(u) - 0.5).collect(),
        }
    }

    /// Per-row factors: (wave amplitude, row ramp).
    fn row(&self, v: usize, height: usize) -> (f64, f64) {
        let y = v as f64 / height.max(1) as f64;
        ((std::f64::consts::TAU * 0.7 * y).cos(), 0.5 * (y - 0.5))
    }

    fn level(&self, options: &RenderOptions, u: usize, row: (f64, f64)) -> f64 {
        options.background_level
            + 0.5
                * options.background_variation
                * (0.5 * self.column_wave[u] * row.0 + self.column_ramp[u] + row.1)
    }
}

/// Separable Gaussian blur, kernel radius 3 sigma, edges clamped; rows split across
/// `threads` scoped threads for both passes; `temp` (the image's size) holds the first.
fn gaussian_blur(
    image: &mut [f32],
    temp: &mut [f32],
    (width, height): (usize, usize),
    sigma: f64,
    threads: usize,
) {
    let radius = (3.0 * sigma).ceil() as isize;
    let kernel: Vec<f32> = (-radius..=radius)
        .map(|i| (-(i * i) as f64 / (2.0 * sigma * sigma)).exp() as f32)
        .collect();
    let total: f32 = kernel.iter().sum();
    let kernel: &[f32] = &kernel.iter().map(|k| k / total).collect::<Vec<_>>();
    let rows_per_chunk = height.div_ceil(threads.max(1)).max(1);
    {
        let source: &[f32] = image;
        run_parallel(temp.chunks_mut(rows_per_chunk * width).enumerate().map(
            |(chunk_index, chunk)| {
                move || {
                    for (k, out_row) in chunk.chunks_mut(width).enumerate() {
                        let y = chunk_index * rows_per_chunk + k;
                        let row = &source[y * width..(y + 1) * width];
                        for (x, out) in out_row.iter_mut().enumerate() {
                            let mut acc = 0.0;
                            for (k, weight) in kernel.iter().enumerate() {
                                let xx = (x as isize + k as isize - radius)
                                    .clamp(0, width as isize - 1)
                                    as usize;
                                acc += weight * row[xx];
                            }
                            *out = acc;
                        }
                    }
                }
            },
        ));
    }
    let temp: &[f32] = temp;
    run_parallel(image.chunks_mut(rows_per_chunk * width).enumerate().map(
        |(chunk_index, chunk)| {
            move || {
                for (k, out_row) in chunk.chunks_mut(width).enumerate() {
                    let y = chunk_index * rows_per_chunk + k;
                    for (x, out) in out_row.iter_mut().enumerate() {
                        let mut acc = 0.0;
                        for (k, weight) in kernel.iter().enumerate() {
                            let yy = (y as isize + k as isize - radius)
                                .clamp(0, height as isize - 1)
                                as usize;
                            acc += weight * temp[yy * width + x];
                        }
                        *out = acc;
                    }
                }
            }
        },
    ));
}

/// Runs each of `jobs` on a scoped thread of its own, and on this thread any whose thread cannot
/// start (under a memory limit a new thread's stack may not fit the address space left): the
/// frame is the same either way, and the simulated camera never panics for it (issue #44: a run
/// under `ulimit -v` ends or says memory, never a signal or a panic).
fn run_parallel<F: FnOnce() + Send>(jobs: impl IntoIterator<Item = F>) {
    let slots: Vec<Mutex<Option<F>>> = jobs.into_iter().map(|job| Mutex::new(Some(job))).collect();
    // The job is taken out of its slot by whichever thread runs it (a poisoned slot still holds
    // its job: the panic that poisoned it was that job's own, and is raised again by the scope).
    let take = |slot: &Mutex<Option<F>>| slot.lock().unwrap_or_else(PoisonError::into_inner).take();
    std::thread::scope(|scope| {
        for slot in &slots {
            let started = std::thread::Builder::new().spawn_scoped(scope, move || {
                if let Some(job) = take(slot) {
                    job();
                }
            });
            if started.is_err() {
                if let Some(job) = take(slot) {
                    job();
                }
            }
        }
    });
}

#[cfg(test)]
mod tests {
    use super::*;
    use handeye_core::geometry::pose_from_rotvec;
    use handeye_vision::TagFamily;
    use nalgebra::Point3;

    #[test]
    fn one_lens_shares_one_ray_table_while_held_and_another_lens_has_its_own() {
        // A lens no other test uses, so no other holder shares it while this test runs.
        let lens = CameraModel {
            width: 64,
            height: 48,
            fx: 71.25,
            fy: 70.5,
            cx: 31.5,
            cy: 23.5,
            distortion: Distortion::RadTan {
                k1: -0.1,
                k2: 0.02,
                p1: 0.0,
                p2: 0.0,
                k3: 0.0,
            },
        };
        let first = PixelRays::shared(&lens).unwrap();
        let second = PixelRays::shared(&lens).unwrap();
        assert!(Arc::ptr_eq(&first, &second), "one table for one lens");
        assert!(
            first.rays == PixelRays::new(&lens).unwrap().rays,
            "the shared table is the lens's own"
        );
        let other_lens = CameraModel { fx: 72.0, ..lens };
        let other = PixelRays::shared(&other_lens).unwrap();
        assert!(!Arc::ptr_eq(&first, &other), "another lens, another table");
        assert!(other.rays == PixelRays::new(&other_lens).unwrap().rays);
        // Once nobody holds it, it is freed: the next holder computes it again.
        let weak = Arc::downgrade(&first);
        drop((first, second));
        assert!(weak.upgrade().is_none(), "the table outlived its holders");
    }

    #[test]
    fn fronto_parallel_render_puts_black_and_white_where_the_board_projects() {
        let board: Target =
            handeye_vision::Board::aprilgrid(1, 1, 0.08, 0.25, TagFamily::Tag36h11, 0, 1)
                .unwrap()
                .into();
        let camera = CameraModel {
            width: 320,
            height: 240,
            fx: 400.0,
            fy: 400.0,
            cx: 159.5,
            cy: 119.5,
            distortion: Distortion::None,
        };
        // Looking at the tag centre from 0.3 m: camera x = board x, camera y = -board y.
        let camera_from_target = pose_from_rotvec(
            Vector3::new(-0.04, 0.04, 0.3),
            Vector3::new(std::f64::consts::PI, 0.0, 0.0),
        );
        let options = RenderOptions {
            noise_sigma: 0.0,
            background_variation: 0.0,
            ..RenderOptions::default()
        };
        let mut rng = StdRng::seed_from_u64(1);
        let image = render(&board, &camera, &camera_from_target, &options, &mut rng);
        // The first cell inside the black border (0.5 cell in from the bottom-left corner).
        let p = camera
            .project(&(camera_from_target * Point3::new(0.005, 0.04, 0.0)))
            .unwrap();
        assert_eq!(
            image.get_pixel(p.x.round() as u32, p.y.round() as u32)[0],
            25
        );
        // The white ring just outside the border.
        let p = camera
            .project(&(camera_from_target * Point3::new(-0.005, 0.04, 0.0)))
            .unwrap();
        assert_eq!(
            image.get_pixel(p.x.round() as u32, p.y.round() as u32)[0],
            215
        );
        // Image corner: background.
        assert_eq!(image.get_pixel(0, 0)[0], 110);
    }
}
