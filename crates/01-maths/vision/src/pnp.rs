//! The board pose `T_camera_target` from detected corners: a planar homography start on
//! undistorted normalised points, then Levenberg-Marquardt on the pixel reprojection error
//! through the full lens model.
//!
//! Parameters of the refinement: a left rotation increment `δω` (rad) on the start rotation
//! and the translation `t` (m): `R = exp(δω) R₀`. The reported covariance is in that
//! parametrisation, order `[ωx, ωy, ωz, tx, ty, tz]` (rad², m²), scaled by the residual
//! variance. A lone tag (one square) has two planar poses that explain the corners almost
//! equally well when seen near head-on; both are refined and the better kept, and
//! `ambiguity` reports the ratio of the two RMS errors. Depends on `camera_model`,
//! `vision::board`, `vision::detect`, `geometry`.

use levenberg_marquardt::{LeastSquaresProblem, LevenbergMarquardt};
use nalgebra::{
    storage::Owned, Dyn, Matrix3, Matrix6, OMatrix, OVector, Point2, Point3, Translation3,
    UnitQuaternion, Vector3, Vector6, U6,
};

use super::board::Board;
use super::detect::BoardDetection;
use super::target::AsTarget;
use super::TargetError;
use handeye_core::camera_model::CameraModel;
use handeye_core::geometry::homography::{homography, pose_from_homography};
use handeye_core::geometry::Pose;
use handeye_core::setup::ViewSigma;

/// Ratio of best to second-best RMS above which a lone tag's pose counts as ambiguous.
pub const AMBIGUITY_WARN_RATIO: f64 = 0.6;

/// The board pose with its quality figures.
#[derive(Debug, Clone, PartialEq)]
pub struct BoardPose {
    /// `T_camera_target`.
    pub camera_from_target: Pose,
    /// Root-mean-square reprojection error over all corners, px (per corner distance).
    pub rms_px: f64,
    /// Reprojection distance of every corner used, px, in correspondence order.
    pub residuals_px: Vec<f64>,
    /// Tags that contributed corners.
    pub tags_used: usize,
    /// Corners used.
    pub corners_used: usize,
    /// Pose covariance, `[ωx, ωy, ωz, tx, ty, tz]` (left rotation increment rad, translation m).
    pub covariance: Matrix6<f64>,
    /// For a lone tag: RMS of the best pose over RMS of the other planar solution (near 1 =
    /// ambiguous, see [`AMBIGUITY_WARN_RATIO`]); `None` for several tags.
    pub ambiguity: Option<f64>,
}

impl BoardPose {
    /// How precisely the view fixed the pose: the root of the rotation and of the translation
    /// trace of [`BoardPose::covariance`]; `None` when the view does not fix the pose.
    pub fn view_sigma(&self) -> Option<ViewSigma> {
        let c = &self.covariance;
        let sigma = ViewSigma {
            rotation_deg: c.fixed_view::<3, 3>(0, 0).trace().sqrt().to_degrees(),
            translation_mm: c.fixed_view::<3, 3>(3, 3).trace().sqrt() * 1e3,
        };
        sigma.is_valid().then_some(sigma)
    }

    /// True for a lone tag whose two planar solutions fit almost equally well.
    pub fn is_ambiguous(&self) -> bool {
        self.ambiguity.is_some_and(|r| r > AMBIGUITY_WARN_RATIO)
    }
}

/// Estimates `T_camera_target` from a detection of `board` by a camera with `camera`'s intrinsics.
pub fn estimate_board_pose(
    board: &(impl AsTarget + ?Sized),
    camera: &CameraModel,
    detection: &BoardDetection,
) -> Result<BoardPose, TargetError> {
    let board = board.as_target();
    if (detection.image_width, detection.image_height) != (camera.width, camera.height) {
        return Err(TargetError::ImageSizeMismatch {
            image_width: detection.image_width,
            image_height: detection.image_height,
            camera_width: camera.width,
            camera_height: camera.height,
        });
    }
    if detection.feature_count() == 0 {
        return Err(TargetError::NoTagsFound {
            rejected: detection.rejected.len(),
        });
    }
    let correspondences = board.correspondences(detection);
    // Tags of an aprilgrid; corners of a ChArUco board or chessboard (never a lone tag).
    let tags_used = match board.aprilgrid() {
        Some(grid) => detection
            .tags
            .iter()
            .filter(|t| grid.tag(t.id).is_some())
            .count(),
        None => correspondences.len().max(2),
    };
    estimate_pose_from_points(camera, &correspondences, tags_used)
}

/// PnP on `(point_in_target with z = 0, pixel)` pairs; `tags_used` only labels the result and
/// enables the lone-tag ambiguity check when it is 1.
pub fn estimate_pose_from_points(
    camera: &CameraModel,
    correspondences: &[(Point3<f64>, Point2<f64>)],
    tags_used: usize,
) -> Result<BoardPose, TargetError> {
    const REQUIRED: usize = 4;
    if correspondences.len() < REQUIRED {
        return Err(TargetError::NotEnoughCorners {
            required: REQUIRED,
            actual: correspondences.len(),
        });
    }
    let normalised: Vec<(Point3<f64>, Point2<f64>)> = correspondences
        .iter()
        .filter_map(|(p, px)| Some((*p, Point2::from(camera.undistort_to_normalised(px)?))))
        .collect();
    if normalised.len() < REQUIRED {
        return Err(TargetError::NotEnoughCorners {
            required: REQUIRED,
            actual: normalised.len(),
        });
    }
    let start = planar_pose_from_homography(&normalised)?;
    let (best, best_sse) = refine(camera, correspondences, start)?;
    let mut result = (best, best_sse);
    let mut ambiguity = None;
    if tags_used == 1 {
        let alternative = mirrored_planar_pose(&best, correspondences);
        let (other, other_sse) = match refine(camera, correspondences, alternative) {
            // Near head-on the two minima merge and the mirrored start slides back into the
            // best one; the mirrored pose itself (tilted the other way) then measures how
            // flat the valley between them is.
            Ok((other, sse)) if best.rotation.angle_to(&other.rotation) > 1e-3 => (other, sse),
            _ => (
                alternative,
                sum_of_squares(camera, correspondences, &alternative),
            ),
        };
        if other_sse < best_sse {
            result = (other, other_sse);
        }
        let (low, high) = (best_sse.min(other_sse), best_sse.max(other_sse));
        ambiguity = Some(if high > 0.0 { (low / high).sqrt() } else { 1.0 });
    }
    let (pose, _) = result;
    summarise(camera, correspondences, pose, tags_used, ambiguity)
}

/// Projects every tag corner of the board at `camera_from_target`; tags with any corner behind
/// the camera are left out. Pixels in the project convention.
pub fn reproject(
    board: &Board,
    camera: &CameraModel,
    camera_from_target: &Pose,
) -> Vec<(u32, [Point2<f64>; 4])> {
    board
        .tags()
        .iter()
        .filter_map(|tag| {
            let mut pixels = [Point2::origin(); 4];
            for (pixel, corner) in pixels.iter_mut().zip(&tag.corners_in_target) {
                *pixel = camera.project(&(camera_from_target * corner))?;
            }
            Some((tag.id, pixels))
        })
        .collect()
}

/// The board pose from the homography of board-plane points to normalised image points.
fn planar_pose_from_homography(points: &[(Point3<f64>, Point2<f64>)]) -> Result<Pose, TargetError> {
    let (plane, image): (Vec<(f64, f64)>, Vec<Point2<f64>>) =
        points.iter().map(|(p, q)| ((p.x, p.y), *q)).unzip();
    homography(&plane, &image)
        .and_then(|h| pose_from_homography(&h, &Matrix3::identity()))
        .ok_or(TargetError::PoseFailed {
            reason: "degenerate homography (collinear corners?)",
        })
}

/// The other planar solution: the board normal reflected about the line of sight to the
/// board's centre, the centre kept in place.
fn mirrored_planar_pose(pose: &Pose, correspondences: &[(Point3<f64>, Point2<f64>)]) -> Pose {
    let n = correspondences.len() as f64;
    let centre_in_target = Point3::from(
        correspondences
            .iter()
            .fold(Vector3::zeros(), |a, (p, _)| a + p.coords / n),
    );
    let centre_in_camera = pose * centre_in_target;
    let sight = centre_in_camera.coords.normalize();
    let normal = pose.rotation * Vector3::z();
    let mirrored = 2.0 * normal.dot(&sight) * sight - normal;
    let turn = UnitQuaternion::rotation_between(&normal, &mirrored).unwrap_or_else(|| {
        UnitQuaternion::from_axis_angle(&Vector3::x_axis(), std::f64::consts::PI)
    });
    let rotation = turn * pose.rotation;
    let translation = centre_in_camera.coords - rotation * centre_in_target.coords;
    Pose::from_parts(Translation3::from(translation), rotation)
}

struct Reprojection<'a> {
    camera: &'a CameraModel,
    correspondences: &'a [(Point3<f64>, Point2<f64>)],
    start_rotation: UnitQuaternion<f64>,
    params: Vector6<f64>,
}

impl Reprojection<'_> {
    fn pose(&self) -> Pose {
        pose_from_params(&self.start_rotation, &self.params)
    }
}

fn pose_from_params(start_rotation: &UnitQuaternion<f64>, params: &Vector6<f64>) -> Pose {
    let omega = Vector3::new(params[0], params[1], params[2]);
    Pose::from_parts(
        Translation3::new(params[3], params[4], params[5]),
        UnitQuaternion::from_scaled_axis(omega) * start_rotation,
    )
}

/// Left Jacobian of SO(3): d(exp(ω)·x)/dω = -[exp(ω)·x]× · J_l(ω).
fn left_jacobian(omega: &Vector3<f64>) -> Matrix3<f64> {
    let theta = omega.norm();
    let k = omega.cross_matrix();
    if theta < 1e-8 {
        return Matrix3::identity() + 0.5 * k;
    }
    let t2 = theta * theta;
    Matrix3::identity()
        + (1.0 - theta.cos()) / t2 * k
        + (theta - theta.sin()) / (t2 * theta) * k * k
}

impl LeastSquaresProblem<f64, Dyn, U6> for Reprojection<'_> {
    type ResidualStorage = Owned<f64, Dyn>;
    type JacobianStorage = Owned<f64, Dyn, U6>;
    type ParameterStorage = Owned<f64, U6>;

    fn set_params(&mut self, x: &Vector6<f64>) {
        self.params = *x;
    }

    fn params(&self) -> Vector6<f64> {
        self.params
    }

    fn residuals(&self) -> Option<OVector<f64, Dyn>> {
        let pose = self.pose();
        let mut r = OVector::<f64, Dyn>::zeros(2 * self.correspondences.len());
        for (i, (point, pixel)) in self.correspondences.iter().enumerate() {
            let predicted = self.camera.project(&(pose * point))?;
            r[2 * i] = predicted.x - pixel.x;
            r[2 * i + 1] = predicted.y - pixel.y;
        }
        Some(r)
    }

    fn jacobian(&self) -> Option<OMatrix<f64, Dyn, U6>> {
        let pose = self.pose();
        let omega = Vector3::new(self.params[0], self.params[1], self.params[2]);
        let jl = left_jacobian(&omega);
        let mut jacobian = OMatrix::<f64, Dyn, U6>::zeros(2 * self.correspondences.len());
        for (i, (point, _)) in self.correspondences.iter().enumerate() {
            let rotated = pose.rotation * point.coords;
            let (_, d_pixel) = self
                .camera
                .project_with_jacobian(&Point3::from(rotated + pose.translation.vector))?;
            let d_rotation = d_pixel * (-rotated.cross_matrix() * jl);
            for row in 0..2 {
                for col in 0..3 {
                    jacobian[(2 * i + row, col)] = d_rotation[(row, col)];
                    jacobian[(2 * i + row, col + 3)] = d_pixel[(row, col)];
                }
            }
        }
        Some(jacobian)
    }
}

/// Sum of squared reprojection errors (px²) at `pose`; infinite if a corner is behind the camera.
fn sum_of_squares(
    camera: &CameraModel,
    correspondences: &[(Point3<f64>, Point2<f64>)],
    pose: &Pose,
) -> f64 {
    correspondences
        .iter()
        .map(|(p, px)| match camera.project(&(pose * p)) {
            Some(q) => (q - px).norm_squared(),
            None => f64::INFINITY,
        })
        .sum()
}

/// LM refinement from `start`; returns the pose and the sum of squared residuals (px²).
fn refine(
    camera: &CameraModel,
    correspondences: &[(Point3<f64>, Point2<f64>)],
    start: Pose,
) -> Result<(Pose, f64), TargetError> {
    let t = start.translation.vector;
    let problem = Reprojection {
        camera,
        correspondences,
        start_rotation: start.rotation,
        params: Vector6::new(0.0, 0.0, 0.0, t.x, t.y, t.z),
    };
    let (problem, report) = LevenbergMarquardt::new()
        .with_patience(50)
        .minimize(problem);
    if report.termination.was_usage_issue() || !report.objective_function.is_finite() {
        return Err(TargetError::PoseFailed {
            reason: "refinement diverged (board behind the camera?)",
        });
    }
    // The crate's objective is half the sum of squares.
    Ok((problem.pose(), 2.0 * report.objective_function))
}

fn summarise(
    camera: &CameraModel,
    correspondences: &[(Point3<f64>, Point2<f64>)],
    pose: Pose,
    tags_used: usize,
    ambiguity: Option<f64>,
) -> Result<BoardPose, TargetError> {
    let problem = Reprojection {
        camera,
        correspondences,
        start_rotation: pose.rotation,
        params: Vector6::new(
            0.0,
            0.0,
            0.0,
            pose.translation.x,
            pose.translation.y,
            pose.translation.z,
        ),
    };
    let residuals = problem.residuals().ok_or(TargetError::PoseFailed {
        reason: "a corner projects behind the camera",
    })?;
    let jacobian = problem.jacobian().ok_or(TargetError::PoseFailed {
        reason: "a corner projects behind the camera",
    })?;
    let residuals_px: Vec<f64> = residuals
        .as_slice()
        .chunks_exact(2)
        .map(|r| r[0].hypot(r[1]))
        .collect();
    let n = residuals_px.len();
    let sse: f64 = residuals.norm_squared();
    let rms_px = (sse / n as f64).sqrt();
    // Residual variance per coordinate with 6 degrees of freedom spent on the pose.
    let dof = (2 * n).saturating_sub(6).max(1) as f64;
    let information = jacobian.transpose() * &jacobian;
    let covariance = information
        .try_inverse()
        .map(|inverse| inverse * (sse / dof))
        .unwrap_or_else(|| Matrix6::from_element(f64::INFINITY));
    Ok(BoardPose {
        camera_from_target: pose,
        rms_px,
        residuals_px,
        tags_used,
        corners_used: n,
        covariance,
        ambiguity,
    })
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::TagFamily;
    use handeye_core::camera_model::Distortion;
    use handeye_core::geometry::pose_from_rotvec;
    use rand::SeedableRng;
    use rand_distr::{Distribution, Normal};

    /// A 1280x720 lens with radial-tangential distortion (tests of the crate share it).
    pub(crate) fn camera() -> CameraModel {
        CameraModel {
            width: 1280,
            height: 720,
            fx: 910.0,
            fy: 905.0,
            cx: 640.5,
            cy: 358.7,
            distortion: Distortion::RadTan {
                k1: -0.2,
                k2: 0.05,
                p1: 0.001,
                p2: -0.0008,
                k3: 0.0,
            },
        }
    }

    #[test]
    fn recovers_pose_from_noisy_projected_corners_within_covariance_scale() {
        let board = Board::aprilgrid(6, 6, 0.04, 0.25, TagFamily::Tag36h11, 0, 1).unwrap();
        let camera = camera();
        let truth = pose_from_rotvec(Vector3::new(-0.14, 0.1, 0.6), Vector3::new(2.9, 0.3, -0.2));
        let mut rng = rand::rngs::StdRng::seed_from_u64(7);
        let noise = Normal::new(0.0, 0.1).unwrap();
        let correspondences: Vec<_> = board
            .tags()
            .iter()
            .flat_map(|t| t.corners_in_target)
            .map(|p| {
                let px = camera.project(&(truth * p)).unwrap();
                (
                    p,
                    Point2::new(px.x + noise.sample(&mut rng), px.y + noise.sample(&mut rng)),
                )
            })
            .collect();
        let estimate = estimate_pose_from_points(&camera, &correspondences, 36).unwrap();
        let angle = estimate
            .camera_from_target
            .rotation
            .angle_to(&truth.rotation);
        let offset =
            (estimate.camera_from_target.translation.vector - truth.translation.vector).norm();
        // Project floor: 0.05 deg and 0.3 mm at 0.6 m; and within 4 sigma of the covariance.
        assert!(
            angle.to_degrees() < 0.05,
            "rotation error {} deg",
            angle.to_degrees()
        );
        let sigma_r = estimate.covariance.fixed_view::<3, 3>(0, 0).trace().sqrt();
        assert!(
            angle < 4.0 * sigma_r,
            "rotation error {angle} rad vs sigma {sigma_r}"
        );
        assert!(offset < 0.0003, "translation error {offset} m");
        // 0.1 px per coordinate: RMS distance ≈ 0.14 px.
        assert!(
            (0.08..0.2).contains(&estimate.rms_px),
            "rms {}",
            estimate.rms_px
        );
        assert_eq!(estimate.corners_used, 144);
        // The covariance's translation sigma is of the order of the actual error (< 0.3 mm).
        let sigma_t = estimate.covariance.fixed_view::<3, 3>(3, 3).trace().sqrt();
        assert!(sigma_t > 1e-6 && sigma_t < 3e-4, "sigma_t {sigma_t}");
    }

    #[test]
    fn lone_tag_evaluates_both_planar_solutions_and_flags_near_affine_views() {
        let board = Board::aprilgrid(1, 1, 0.05, 0.25, TagFamily::Tag36h11, 0, 1).unwrap();
        let camera = camera();
        let corners = board.tags()[0].corners_in_target;
        let mut rng = rand::rngs::StdRng::seed_from_u64(3);
        let noise = Normal::new(0.0, 0.2).unwrap();
        let mut ratios = Vec::new();
        for (tilt_deg, distance) in [(3.0f64, 0.6), (40.0, 0.6), (20.0, 2.5)] {
            let rotation =
                UnitQuaternion::from_scaled_axis(Vector3::new(std::f64::consts::PI, 0.0, 0.0))
                    * UnitQuaternion::from_scaled_axis(
                        Vector3::new(0.3, 1.0, 0.0).normalize() * tilt_deg.to_radians(),
                    );
            let truth = Pose::from_parts(Translation3::new(-0.025, 0.025, distance), rotation);
            let correspondences: Vec<_> = corners
                .iter()
                .map(|p| {
                    let px = camera.project(&(truth * p)).unwrap();
                    (
                        *p,
                        Point2::new(px.x + noise.sample(&mut rng), px.y + noise.sample(&mut rng)),
                    )
                })
                .collect();
            let estimate = estimate_pose_from_points(&camera, &correspondences, 1).unwrap();
            let ratio = estimate.ambiguity.expect("lone tag reports its ambiguity");
            eprintln!("tilt {tilt_deg} at {distance} m: ratio {ratio}");
            assert!((0.0..=1.0).contains(&ratio));
            ratios.push(ratio);
        }
        // A small, far tag (near-affine view) has two poses that fit almost equally: flagged.
        // Close and tilted 40°, the mirrored pose is clearly worse; head-on lies between.
        assert!(ratios[2] > AMBIGUITY_WARN_RATIO, "{ratios:?}");
        assert!(ratios[1] < AMBIGUITY_WARN_RATIO, "{ratios:?}");
        assert!(ratios[0] > ratios[1], "{ratios:?}");
    }

    #[test]
    fn too_few_corners_is_a_clear_error() {
        let error =
            estimate_pose_from_points(&camera(), &[(Point3::origin(), Point2::origin())], 1)
                .unwrap_err();
        assert!(matches!(
            error,
            TargetError::NotEnoughCorners {
                required: 4,
                actual: 1
            }
        ));
    }
}
