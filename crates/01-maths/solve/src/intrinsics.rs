//! Intrinsics from scratch: Zhang's closed form from the board homographies of the frames, the
//! board poses those imply, and the whole chain to a joint reprojection-space calibration of
//! hand-eye, base-world and intrinsics with distortion.
//!
//! Frames: board corners are in the target frame and must lie on its `z = 0` plane (every board
//! the crate knows is planar); pixels in the OpenCV convention. Zhang's constraints are solved
//! with zero skew, in pixel coordinates normalised around the image centre so the linear system
//! is well conditioned. The closed form ignores distortion; the joint refinement then fits it.
//! Pure: no I/O. Depends on `geometry`, the camera model type and nalgebra only.

use nalgebra::{DMatrix, Matrix3, Point2, Vector3};

use super::reprojection::{
    refine_reprojection, Frame, ReprojectionCalibration, ReprojectionOptions,
};
use super::{solve, Calibration, SolveError, SolveOptions};
use handeye_core::camera_model::{CameraModel, Distortion};
use handeye_core::geometry::homography::{self, homography};
use handeye_core::geometry::Pose;
use handeye_core::setup::{PosePair, Setup};

/// Fewest corners a frame needs to give a homography.
pub const MIN_CORNERS_PER_FRAME: usize = 8;
/// Fewest frames (with homographies) Zhang's method with zero skew needs in practice.
pub const MIN_FRAMES: usize = 3;
/// Ratio of the second-smallest to the largest singular value of Zhang's system below which the
/// intrinsics are called unobservable. Tilted views give ~1e-2; fronto-parallel ones ~1e-6 and
/// below (the null space is then four-dimensional).
const DEGENERACY_RATIO: f64 = 1e-4;
/// Tilt spread (largest − smallest, degrees) below which the views are too alike.
const MIN_TILT_SPREAD_DEG: f64 = 5.0;

/// Board-plane points (target `x`, `y`, m) and their pixels.
type PlanePoints = (Vec<(f64, f64)>, Vec<Point2<f64>>);

/// The board plane and pixels of a frame; errors when a corner is off the `z = 0` plane.
fn plane_points(index: usize, frame: &Frame) -> Result<PlanePoints, SolveError> {
    let mut plane = Vec::with_capacity(frame.corners.len());
    let mut pixels = Vec::with_capacity(frame.corners.len());
    for c in &frame.corners {
        if c.point_in_target.z.abs() > 1e-9 {
            return Err(SolveError::IntrinsicsFailed(format!(
                "frame {index}: board corner {:?} m is off the target's z = 0 plane; Zhang's method needs a planar board",
                [c.point_in_target.x, c.point_in_target.y, c.point_in_target.z]
            )));
        }
        plane.push((c.point_in_target.x, c.point_in_target.y));
        pixels.push(c.pixel);
    }
    Ok((plane, pixels))
}

/// The board pose `T_camera_target` a homography implies under a pinhole camera (distortion
/// ignored); `None` when it does not give a usable rotation.
pub fn pose_from_homography(h: &Matrix3<f64>, camera: &CameraModel) -> Option<Pose> {
    let k = Matrix3::new(
        camera.fx, 0.0, camera.cx, 0.0, camera.fy, camera.cy, 0.0, 0.0, 1.0,
    );
    homography::pose_from_homography(h, &k)
}

fn tilt_deg(pose: &Pose) -> f64 {
    let normal = pose.rotation * Vector3::z();
    normal.z.abs().min(1.0).acos().to_degrees()
}

/// Zhang's closed-form intrinsics (zero skew, no distortion) for an image of `width` x `height`
/// from the frames' board corners.
///
/// Refuses with [`SolveError::DegenerateIntrinsics`] when the views do not determine the
/// intrinsics (all boards fronto-parallel, or all tilted alike), saying what to add.
pub fn zhang_intrinsics(
    frames: &[Frame],
    width: u32,
    height: u32,
) -> Result<CameraModel, SolveError> {
    if width == 0 || height == 0 {
        return Err(SolveError::IntrinsicsFailed(format!(
            "image size {width}x{height} px must be positive"
        )));
    }
    let (w, h) = (f64::from(width), f64::from(height));
    // Pixel normalisation: centre and scale by the mean image size.
    let s = 2.0 / (w + h);
    let n = Matrix3::new(
        s,
        0.0,
        -s * (w - 1.0) / 2.0,
        0.0,
        s,
        -s * (h - 1.0) / 2.0,
        0.0,
        0.0,
        1.0,
    );
    let mut homographies = Vec::new();
    let (mut umin, mut umax, mut vmin, mut vmax) = (f64::MAX, f64::MIN, f64::MAX, f64::MIN);
    for (index, frame) in frames.iter().enumerate() {
        if frame.corners.len() < MIN_CORNERS_PER_FRAME {
            continue;
        }
        let (plane, pixels) = plane_points(index, frame)?;
        for p in &pixels {
            umin = umin.min(p.x);
            umax = umax.max(p.x);
            vmin = vmin.min(p.y);
            vmax = vmax.max(p.y);
        }
        if let Some(hm) = homography(&plane, &pixels) {
            homographies.push(hm);
        }
    }
    let coverage_percent = if homographies.is_empty() {
        0.0
    } else {
        100.0 * ((umax - umin) * (vmax - vmin) / (w * h)).clamp(0.0, 1.0)
    };
    // A nominal camera (≈ 65° across) only to estimate the tilts for the message and the check.
    let nominal = CameraModel {
        width,
        height,
        fx: w,
        fy: w,
        cx: (w - 1.0) / 2.0,
        cy: (h - 1.0) / 2.0,
        distortion: Distortion::None,
    };
    let tilts: Vec<f64> = homographies
        .iter()
        .filter_map(|hm| pose_from_homography(hm, &nominal).map(|p| tilt_deg(&p)))
        .collect();
    let degenerate = |tilts: &[f64]| SolveError::DegenerateIntrinsics {
        frames: homographies.len(),
        min_tilt_deg: tilts
            .iter()
            .copied()
            .fold(f64::INFINITY, f64::min)
            .min(90.0),
        max_tilt_deg: tilts.iter().copied().fold(0.0, f64::max),
        coverage_percent,
    };
    if homographies.len() < MIN_FRAMES {
        return Err(SolveError::TooFewSamples {
            found: homographies.len(),
            required: MIN_FRAMES,
        });
    }
    // Zhang's constraints on B = K⁻ᵀK⁻¹ with B12 = 0: unknowns (B11, B22, B13, B23, B33).
    let v = |hm: &Matrix3<f64>, i: usize, j: usize| {
        let (hi, hj) = (hm.column(i), hm.column(j));
        [
            hi[0] * hj[0],
            hi[1] * hj[1],
            hi[2] * hj[0] + hi[0] * hj[2],
            hi[2] * hj[1] + hi[1] * hj[2],
            hi[2] * hj[2],
        ]
    };
    let mut system = DMatrix::zeros(2 * homographies.len(), 5);
    for (k, hm) in homographies.iter().enumerate() {
        let hn = n * hm;
        let hn = hn / hn.norm();
        let v12 = v(&hn, 0, 1);
        let v11 = v(&hn, 0, 0);
        let v22 = v(&hn, 1, 1);
        for c in 0..5 {
            system[(2 * k, c)] = v12[c];
            system[(2 * k + 1, c)] = v11[c] - v22[c];
        }
    }
    let svd = system.clone().svd(false, true);
    let mut order: Vec<usize> = (0..svd.singular_values.len()).collect();
    order.sort_by(|&a, &b| svd.singular_values[b].total_cmp(&svd.singular_values[a]));
    let largest = svd.singular_values[order[0]];
    let second_smallest = svd.singular_values[order[order.len() - 2]];
    let tilt_spread = tilts.iter().copied().fold(0.0, f64::max)
        - tilts.iter().copied().fold(f64::INFINITY, f64::min);
    if largest.is_nan() || largest <= 0.0 || second_smallest / largest < DEGENERACY_RATIO {
        return Err(degenerate(&tilts));
    }
    if tilt_spread < MIN_TILT_SPREAD_DEG && tilts.iter().all(|t| *t < 10.0) {
        return Err(degenerate(&tilts));
    }
    let v_t = svd
        .v_t
        .ok_or_else(|| SolveError::IntrinsicsFailed("SVD failed".to_string()))?;
    let b = v_t.row(order[order.len() - 1]).into_owned();
    let (b11, b22, b13, b23, b33) = (b[0], b[1], b[2], b[3], b[4]);
    let v0 = -b23 / b22;
    let lambda = b33 - (b13 * b13 + v0 * (-b11 * b23)) / b11;
    let alpha2 = lambda / b11;
    let beta2 = lambda / b22;
    if !(alpha2 > 0.0 && beta2 > 0.0 && alpha2.is_finite() && beta2.is_finite()) {
        return Err(degenerate(&tilts));
    }
    let (alpha, beta) = (alpha2.sqrt(), beta2.sqrt());
    let u0 = -b13 * alpha2 / lambda;
    // Back from normalised to pixel coordinates: K = N⁻¹ · K_normalised.
    let camera = CameraModel {
        width,
        height,
        fx: alpha / s,
        fy: beta / s,
        cx: u0 / s + (w - 1.0) / 2.0,
        cy: v0 / s + (h - 1.0) / 2.0,
        distortion: Distortion::None,
    };
    let sane = camera.fx.is_finite()
        && camera.fy.is_finite()
        && camera.fx > 0.05 * w
        && camera.fy > 0.05 * w
        && camera.fx < 50.0 * w
        && (camera.fx / camera.fy - 1.0).abs() < 0.5
        && camera.cx > -0.5 * w
        && camera.cx < 1.5 * w
        && camera.cy > -0.5 * h
        && camera.cy < 1.5 * h;
    if !sane {
        return Err(degenerate(&tilts));
    }
    Ok(camera)
}

/// Calibrates a cell whose camera has no intrinsics yet: Zhang's closed form, board poses from
/// the homographies, the pose-space solve on those, then the joint reprojection refinement with
/// intrinsics and `plumb_bob` distortion free (robot corrections as `options` say).
///
/// Returns the closed-form camera, the board-pose pairs it gives, the pose-space answer on them
/// and the joint answer.
pub fn calibrate_from_scratch(
    setup: Setup,
    frames: &[Frame],
    width: u32,
    height: u32,
    pose_options: &SolveOptions,
    options: &ReprojectionOptions,
) -> Result<FromScratch, SolveError> {
    let initial = zhang_intrinsics(frames, width, height)?;
    let mut pairs = Vec::new();
    let mut used = Vec::new();
    for (index, frame) in frames.iter().enumerate() {
        if frame.corners.len() < MIN_CORNERS_PER_FRAME {
            continue;
        }
        let (plane, pixels) = plane_points(index, frame)?;
        let Some(pose) =
            homography(&plane, &pixels).and_then(|h| pose_from_homography(&h, &initial))
        else {
            continue;
        };
        let mut pair = PosePair::new(frame.base_from_flange, pose);
        pair.id = frame.id.clone();
        pairs.push(pair);
        used.push(frame.clone());
    }
    // The closed-form poses are rough (no distortion yet): a loose noise model, no convention check.
    let mut loose = pose_options.clone();
    loose.noise.rotation_sigma_rad = loose.noise.rotation_sigma_rad.max(0.5f64.to_radians());
    loose.noise.translation_sigma_m = loose.noise.translation_sigma_m.max(5e-3);
    loose.check_conventions = false;
    loose.drop_outliers = false;
    let pose_space = solve(setup, &pairs, &loose)?;
    // Stage 1: intrinsics only (distortion held at zero) from the rough start; stage 2: all.
    let stage1 = refine_reprojection(
        setup,
        &used,
        &initial,
        &pose_space.camera_mount,
        &pose_space.target_mount,
        &ReprojectionOptions {
            refine_intrinsics: true,
            refine_distortion: false,
            robot_prior: None,
            robust: super::RobustLoss::None,
            covariance: false,
            estimate_noise: false,
            ..options.clone()
        },
    )?;
    let joint = refine_reprojection(
        setup,
        frames,
        &stage1.camera,
        &stage1.camera_mount,
        &stage1.target_mount,
        &ReprojectionOptions {
            refine_intrinsics: true,
            refine_distortion: true,
            ..options.clone()
        },
    )?;
    Ok(FromScratch {
        initial,
        pairs,
        pose_space,
        joint,
    })
}

/// What [`calibrate_from_scratch`] found.
#[derive(Debug, Clone)]
pub struct FromScratch {
    /// Zhang's closed-form camera (no distortion).
    pub initial: CameraModel,
    /// Board poses from the homographies with the closed-form camera, paired with the robot poses
    /// (frames with too few corners left out).
    pub pairs: Vec<PosePair>,
    /// The pose-space answer on those pairs.
    pub pose_space: Calibration,
    /// The joint reprojection answer with intrinsics and distortion fitted.
    pub joint: ReprojectionCalibration,
}

/// Tilt (degrees) from which a view counts as tilted for intrinsics.
pub const TILTED_VIEW_DEG: f64 = 15.0;
/// Share of the image's 4x4 cells the board corners must reach over all views, percent.
pub const MIN_IMAGE_COVERAGE_PERCENT: f64 = 50.0;

/// How well a set of views constrains the intrinsics: tilt variety and image coverage.
#[derive(Debug, Clone, PartialEq)]
pub struct IntrinsicsCoverage {
    /// Views tilted by at least [`TILTED_VIEW_DEG`].
    pub tilted_views: usize,
    /// Largest angle between the tilt directions (in the image plane) of two tilted views,
    /// folded to 0..90°; near 0 means all tilts are about one axis.
    pub tilt_direction_spread_deg: f64,
    /// Largest tilt of any view, degrees.
    pub max_tilt_deg: f64,
    /// Share of the image's 4x4 cells reached by some board corner, percent.
    pub coverage_percent: f64,
}

impl IntrinsicsCoverage {
    /// Measures views given as `T_camera_target` with the board corners' pixels in each.
    pub fn measure(
        camera_from_target: &[Pose],
        pixels: &[Vec<Point2<f64>>],
        width: u32,
        height: u32,
    ) -> IntrinsicsCoverage {
        let mut directions = Vec::new();
        let mut max_tilt_deg: f64 = 0.0;
        for pose in camera_from_target {
            let normal = pose.rotation * Vector3::z();
            let tilt = tilt_deg(pose);
            max_tilt_deg = max_tilt_deg.max(tilt);
            if tilt >= TILTED_VIEW_DEG {
                directions.push(normal.y.atan2(normal.x));
            }
        }
        let mut spread: f64 = 0.0;
        for (i, a) in directions.iter().enumerate() {
            for b in &directions[i + 1..] {
                // Tilt axes are lines: fold the angle between directions to 0..90°.
                let d = (a - b).rem_euclid(std::f64::consts::PI);
                spread = spread.max(d.min(std::f64::consts::PI - d).to_degrees());
            }
        }
        let mut cells = [[false; 4]; 4];
        let (w, h) = (f64::from(width.max(1)), f64::from(height.max(1)));
        for p in pixels.iter().flatten() {
            let (cx, cy) = ((p.x + 0.5) / w * 4.0, (p.y + 0.5) / h * 4.0);
            if (0.0..4.0).contains(&cx) && (0.0..4.0).contains(&cy) {
                cells[cy as usize][cx as usize] = true;
            }
        }
        let reached = cells.iter().flatten().filter(|c| **c).count();
        IntrinsicsCoverage {
            tilted_views: directions.len(),
            tilt_direction_spread_deg: spread,
            max_tilt_deg,
            coverage_percent: 100.0 * reached as f64 / 16.0,
        }
    }

    /// What is missing for the intrinsics to be estimated from these views, if anything.
    pub fn problem(&self) -> Option<String> {
        let mut missing = Vec::new();
        if self.tilted_views < 2 || self.tilt_direction_spread_deg < 30.0 {
            missing.push(format!(
                "tilt variety ({} views tilted by ≥ {TILTED_VIEW_DEG:.0}°, largest tilt {:.1}°, tilt axes {:.0}° apart; add views with the board tilted by 20–45° about two different axes)",
                self.tilted_views, self.max_tilt_deg, self.tilt_direction_spread_deg
            ));
        }
        if self.coverage_percent < MIN_IMAGE_COVERAGE_PERCENT {
            missing.push(format!(
                "image coverage (board corners reach {:.0} % of the image's 4x4 cells, need {MIN_IMAGE_COVERAGE_PERCENT:.0} %; add views with the board near the image corners and edges)",
                self.coverage_percent
            ));
        }
        (!missing.is_empty()).then(|| {
            format!(
                "these views do not constrain the camera intrinsics: {}",
                missing.join("; ")
            )
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Point3;

    #[test]
    fn pose_from_homography_recovers_a_tilted_board() {
        let camera = CameraModel {
            width: 1280,
            height: 720,
            fx: 800.0,
            fy: 800.0,
            cx: 640.0,
            cy: 360.0,
            distortion: Distortion::None,
        };
        let truth = handeye_core::geometry::pose_from_rotvec(
            Vector3::new(-0.1, 0.05, 0.6),
            Vector3::new(0.4, -0.3, 0.2),
        );
        let plane: Vec<(f64, f64)> = (0..6)
            .flat_map(|i| (0..6).map(move |j| (0.04 * i as f64, 0.04 * j as f64)))
            .collect();
        let pixels: Vec<Point2<f64>> = plane
            .iter()
            .map(|&(x, y)| camera.project(&(truth * Point3::new(x, y, 0.0))).unwrap())
            .collect();
        let h = homography(&plane, &pixels).unwrap();
        let pose = pose_from_homography(&h, &camera).unwrap();
        // Noise-free: the decomposition is exact to numerical precision.
        assert!((pose.translation.vector - truth.translation.vector).norm() < 1e-9);
        assert!(pose.rotation.angle_to(&truth.rotation) < 1e-9);
    }

    #[test]
    fn coverage_says_what_a_set_of_views_lacks_for_intrinsics() {
        let view = |rotvec: [f64; 3]| {
            handeye_core::geometry::pose_from_rotvec(
                Vector3::new(0.0, 0.0, 0.6),
                Vector3::from(rotvec),
            )
        };
        // Corners spread over the whole 1280x720 image.
        let spread: Vec<Point2<f64>> = (0..8)
            .flat_map(|i| {
                (0..8).map(move |j| Point2::new(80.0 + 160.0 * i as f64, 45.0 + 90.0 * j as f64))
            })
            .collect();
        let centre: Vec<Point2<f64>> = spread
            .iter()
            .map(|p| Point2::new(560.0 + p.x / 8.0, 300.0 + p.y / 8.0))
            .collect();
        // Fronto-parallel views, corners only near the centre: both things are missing.
        let flat = [
            view([0.0, 0.0, 0.3]),
            view([0.0, 0.0, -0.2]),
            view([0.0, 0.0, 1.0]),
        ];
        let c = IntrinsicsCoverage::measure(
            &flat,
            &[centre.clone(), centre.clone(), centre],
            1280,
            720,
        );
        assert_eq!(c.tilted_views, 0);
        let problem = c.problem().unwrap();
        assert!(
            problem.contains("tilt variety") && problem.contains("image coverage"),
            "{problem}"
        );
        // Tilted by 30° about x and about y, corners across the image: constrained.
        let tilted = [
            view([0.52, 0.0, 0.0]),
            view([0.0, 0.52, 0.0]),
            view([0.0, 0.0, 0.0]),
        ];
        let c = IntrinsicsCoverage::measure(
            &tilted,
            &[spread.clone(), spread.clone(), spread],
            1280,
            720,
        );
        assert_eq!(c.tilted_views, 2);
        assert!((c.tilt_direction_spread_deg - 90.0).abs() < 1e-6, "{c:?}");
        assert_eq!(c.coverage_percent, 100.0);
        assert!(c.problem().is_none(), "{c:?}");
    }
}
