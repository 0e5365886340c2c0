//! The pinhole camera model with lens distortion: projection, unprojection and projection
//! Jacobians; the intrinsics file forms live in `files`, the distortion models in
//! `distortion`.
//!
//! Frames: points are in the `camera` optical frame (x right, y down, z forward), metres.
//! Pixels use OpenCV's convention (pixel centres at integer coordinates), which is also what
//! ROS `camera_info` and Kalibr intrinsics assume, so files load without any offset.
//! For optimisers (the reprojection-space refinement) it also owns the parameter packing of the
//! intrinsics, the projection Jacobians, and a projection that never fails
//! ([`CameraModel::linearise`]): the one implementation every solver uses.
//!
//! Module map:
//! * this file: [`CameraModel`] (the numbers), projection and unprojection, [`Linearised`];
//! * `distortion`: [`Distortion`] (`RadTan`, `Equidistant`), its Jacobians, its inverse and the
//!   packing of its coefficients;
//! * `files`: the ROS/OpenCV `camera_info` and Kalibr camchain YAML forms (load, save,
//!   validation) and [`CameraModelError`].
//!
//! Part of the ground floor (`handeye-core`): depends on `atomic_file` and `yaml_file` only
//! (through `files`); knows nothing of boards, detectors or robots.

mod distortion;
mod files;

pub use distortion::{Distortion, DistortionProblem, MAX_RADIAL_SCALE};
pub use files::{CameraModelError, ModelNameError, MAX_FOCAL_PER_SIZE, MIN_FOCAL_PER_SIZE};

use nalgebra::{Matrix2, Matrix2x3, Matrix2x4, Matrix2xX, Point2, Point3, Vector2, Vector3};

/// Pinhole intrinsics (px) plus distortion, for an image of `width` x `height` pixels.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CameraModel {
    /// Image width, px.
    pub width: u32,
    /// Image height, px.
    pub height: u32,
    /// Focal length along x, px.
    pub fx: f64,
    /// Focal length along y, px.
    pub fy: f64,
    /// Principal point x, px (OpenCV convention: pixel centres at integers).
    pub cx: f64,
    /// Principal point y, px.
    pub cy: f64,
    /// Lens distortion on normalised coordinates.
    pub distortion: Distortion,
}

/// One point through the camera model, linearised: what an optimiser needs per observation.
/// Made by [`CameraModel::linearise`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Linearised {
    /// Undistorted normalised coordinates `(x/z, y/z)` (depth clamped, see
    /// [`CameraModel::MIN_DEPTH_M`]).
    pub normalised: Vector2<f64>,
    /// Distorted normalised coordinates.
    pub distorted: Vector2<f64>,
    /// The pixel (OpenCV convention).
    pub pixel: Point2<f64>,
    /// The 2x3 Jacobian d(pixel)/d(point_in_camera), px/m.
    pub d_pixel_d_point: Matrix2x3<f64>,
}

impl Linearised {
    /// The 2x4 Jacobian d(pixel)/d(`fx fy cx cy`), the order of [`CameraModel::intrinsics`].
    pub fn d_pixel_d_intrinsics(&self) -> Matrix2x4<f64> {
        let xd = self.distorted;
        Matrix2x4::new(xd.x, 0.0, 1.0, 0.0, 0.0, xd.y, 0.0, 1.0)
    }
}

impl CameraModel {
    /// Depth (m) at which [`CameraModel::project_clamped`] and [`CameraModel::linearise`] clamp
    /// points at or behind the camera.
    pub const MIN_DEPTH_M: f64 = 1e-6;

    /// The pinhole intrinsics as optimisation parameters: `[fx, fy, cx, cy]`, px.
    pub fn intrinsics(&self) -> [f64; 4] {
        [self.fx, self.fy, self.cx, self.cy]
    }

    /// Sets the pinhole intrinsics from `[fx, fy, cx, cy]`, px (the order of
    /// [`CameraModel::intrinsics`]).
    pub fn set_intrinsics(&mut self, [fx, fy, cx, cy]: [f64; 4]) {
        (self.fx, self.fy, self.cx, self.cy) = (fx, fy, cx, cy);
    }

    /// Projection for optimisers that never fails: a point at or behind the camera is pushed to
    /// the depth [`CameraModel::MIN_DEPTH_M`], so it lands far off and a step that moves a point
    /// there is rejected instead of aborting the solve. Equals [`CameraModel::project`] for
    /// points in front of that depth.
    pub fn project_clamped(&self, point_in_camera: &Point3<f64>) -> Point2<f64> {
        let z = point_in_camera.z.max(Self::MIN_DEPTH_M);
        let xn = Vector2::new(point_in_camera.x / z, point_in_camera.y / z);
        self.pixel_from_normalised(self.distortion.distort(xn))
    }

    /// [`CameraModel::project_clamped`] with the Jacobian d(pixel)/d(point_in_camera) and the
    /// intermediate coordinates the intrinsics and coefficient Jacobians need
    /// ([`Linearised::d_pixel_d_intrinsics`], [`CameraModel::d_pixel_d_coefficients`]).
    pub fn linearise(&self, point_in_camera: &Point3<f64>) -> Linearised {
        let (x, y) = (point_in_camera.x, point_in_camera.y);
        let z = point_in_camera.z.max(Self::MIN_DEPTH_M);
        let normalised = Vector2::new(x / z, y / z);
        let distorted = self.distortion.distort(normalised);
        let d_normalised = Matrix2x3::new(1.0 / z, 0.0, -x / (z * z), 0.0, 1.0 / z, -y / (z * z));
        let focal = Matrix2::new(self.fx, 0.0, 0.0, self.fy);
        Linearised {
            normalised,
            distorted,
            pixel: self.pixel_from_normalised(distorted),
            d_pixel_d_point: focal * self.distortion.jacobian(normalised) * d_normalised,
        }
    }

    /// The 2 x [`Distortion::coefficient_count`] Jacobian d(pixel)/d(distortion coefficients)
    /// at the undistorted normalised coordinates `normalised`.
    pub fn d_pixel_d_coefficients(&self, normalised: Vector2<f64>) -> Matrix2xX<f64> {
        let mut j = self.distortion.coefficient_jacobian(normalised);
        j.row_mut(0).scale_mut(self.fx);
        j.row_mut(1).scale_mut(self.fy);
        j
    }

    /// Projects a point in the camera frame (m) to a pixel; `None` for points at or behind
    /// the camera's centre plane (z ≤ 0).
    pub fn project(&self, point_in_camera: &Point3<f64>) -> Option<Point2<f64>> {
        // `is_nan() ||` keeps NaN coordinates out as well.
        if point_in_camera.z.is_nan() || point_in_camera.z <= 1e-12 {
            return None;
        }
        let xn = Vector2::new(
            point_in_camera.x / point_in_camera.z,
            point_in_camera.y / point_in_camera.z,
        );
        Some(self.pixel_from_normalised(self.distortion.distort(xn)))
    }

    /// Projects a point and returns the 2x3 Jacobian d(pixel)/d(point_in_camera).
    pub fn project_with_jacobian(
        &self,
        point_in_camera: &Point3<f64>,
    ) -> Option<(Point2<f64>, Matrix2x3<f64>)> {
        let pixel = self.project(point_in_camera)?;
        let (x, y, z) = (point_in_camera.x, point_in_camera.y, point_in_camera.z);
        let xn = Vector2::new(x / z, y / z);
        let d_normalised = Matrix2x3::new(1.0 / z, 0.0, -x / (z * z), 0.0, 1.0 / z, -y / (z * z));
        let focal = Matrix2::new(self.fx, 0.0, 0.0, self.fy);
        Some((pixel, focal * self.distortion.jacobian(xn) * d_normalised))
    }

    /// The unit ray (camera frame) through a pixel, undistorting iteratively. For a pixel
    /// outside the lens model's valid range the distorted direction is returned instead
    /// (never NaN).
    pub fn unproject(&self, pixel: &Point2<f64>) -> Vector3<f64> {
        let xd = self.normalised_distorted(pixel);
        let xn = self.distortion.undistort(xd).unwrap_or(xd);
        Vector3::new(xn.x, xn.y, 1.0).normalize()
    }

    /// Undistorted normalised coordinates `(x/z, y/z)` of a pixel, if the undistortion converges.
    pub fn undistort_to_normalised(&self, pixel: &Point2<f64>) -> Option<Vector2<f64>> {
        self.distortion.undistort(self.normalised_distorted(pixel))
    }

    fn normalised_distorted(&self, pixel: &Point2<f64>) -> Vector2<f64> {
        Vector2::new((pixel.x - self.cx) / self.fx, (pixel.y - self.cy) / self.fy)
    }

    fn pixel_from_normalised(&self, xd: Vector2<f64>) -> Point2<f64> {
        Point2::new(self.fx * xd.x + self.cx, self.fy * xd.y + self.cy)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A radial-tangential and a fisheye model of one 1280x720 camera: the fixture of every
    /// `camera_model` test.
    pub(super) fn models() -> [CameraModel; 2] {
        let base = CameraModel {
            width: 1280,
            height: 720,
            fx: 900.0,
            fy: 905.0,
            cx: 641.3,
            cy: 359.2,
            distortion: Distortion::None,
        };
        [
            CameraModel {
                distortion: Distortion::RadTan {
                    k1: -0.28,
                    k2: 0.09,
                    p1: 0.0007,
                    p2: -0.0005,
                    k3: -0.01,
                },
                ..base
            },
            CameraModel {
                distortion: Distortion::Equidistant {
                    k1: -0.01,
                    k2: 0.02,
                    k3: -0.015,
                    k4: 0.004,
                },
                ..base
            },
        ]
    }

    #[test]
    fn unproject_inverts_project_to_1e9_px_over_the_image() {
        for model in models() {
            for v in (0..720).step_by(60) {
                for u in (0..1280).step_by(80) {
                    let pixel = Point2::new(u as f64, v as f64);
                    let ray = model.unproject(&pixel);
                    assert!((ray.norm() - 1.0).abs() < 1e-12);
                    let back = model.project(&Point3::from(ray * 0.7)).unwrap();
                    assert!((back - pixel).norm() < 1e-9, "{model:?} {pixel} -> {back}");
                }
            }
        }
    }

    #[test]
    fn points_behind_the_camera_do_not_project() {
        for model in models() {
            assert!(model.project(&Point3::new(0.1, 0.1, -0.5)).is_none());
            assert!(model.project(&Point3::new(0.1, 0.1, 0.0)).is_none());
        }
    }

    #[test]
    fn projection_jacobian_matches_finite_differences_to_1e6_relative() {
        for model in models() {
            let p = Point3::new(0.12, -0.08, 0.6);
            let (_, j) = model.project_with_jacobian(&p).unwrap();
            for axis in 0..3 {
                let mut d = Vector3::zeros();
                d[axis] = 1e-6;
                let numeric =
                    (model.project(&(p + d)).unwrap() - model.project(&(p - d)).unwrap()) / 2e-6;
                let column = j.column(axis);
                assert!((numeric - column).norm() < 1e-6 * j.norm(), "axis {axis}");
            }
        }
    }

    #[test]
    fn intrinsics_packing_round_trips() {
        let mut model = models()[0];
        model.set_intrinsics([1.0, 2.0, 3.0, 4.0]);
        assert_eq!(model.intrinsics(), [1.0, 2.0, 3.0, 4.0]);
        assert_eq!(
            (model.fx, model.fy, model.cx, model.cy),
            (1.0, 2.0, 3.0, 4.0)
        );
    }

    #[test]
    fn coefficient_and_intrinsics_jacobians_match_central_differences() {
        for model in models() {
            for p in [
                Point3::new(0.12, -0.08, 0.6),
                Point3::new(-0.3, 0.2, 0.5),
                Point3::new(1e-5, -2e-5, 0.7),
            ] {
                let lin = model.linearise(&p);
                let xn = lin.normalised;
                let analytic = model.d_pixel_d_coefficients(xn);
                let c = model.distortion.coefficients();
                assert_eq!(analytic.ncols(), c.len());
                let h = 1e-6;
                for i in 0..c.len() {
                    let at = |delta: f64| {
                        let mut moved = c.clone();
                        moved[i] += delta;
                        CameraModel {
                            distortion: model.distortion.with_coefficients(&moved).unwrap(),
                            ..model
                        }
                        .project_clamped(&p)
                    };
                    let numeric = (at(h) - at(-h)) / (2.0 * h);
                    let column = analytic.column(i);
                    // Pixels move ~1e2..1e3 px per unit coefficient: 1e-6 px is rounding.
                    assert!(
                        (numeric - column).norm() < 1e-6 * column.norm().max(1.0),
                        "{:?} coefficient {i}: {numeric} vs {column}",
                        model.distortion
                    );
                }
                let analytic = lin.d_pixel_d_intrinsics();
                for i in 0..4 {
                    let at = |delta: f64| {
                        let mut moved = model;
                        let mut k = model.intrinsics();
                        k[i] += delta;
                        moved.set_intrinsics(k);
                        moved.project_clamped(&p)
                    };
                    let numeric = (at(h) - at(-h)) / (2.0 * h);
                    let column = analytic.column(i);
                    assert!((numeric - column).norm() < 1e-6, "intrinsic {i}");
                }
            }
        }
    }

    #[test]
    fn linearise_agrees_with_project_in_front_and_stays_finite_behind() {
        for model in models() {
            let p = Point3::new(0.12, -0.08, 0.6);
            let (pixel, jacobian) = model.project_with_jacobian(&p).unwrap();
            let lin = model.linearise(&p);
            assert_eq!(lin.pixel, pixel);
            assert_eq!(model.project_clamped(&p), pixel);
            assert!((lin.d_pixel_d_point - jacobian).norm() <= 1e-12 * jacobian.norm());
            assert_eq!(lin.distorted, model.distortion.distort(lin.normalised));
            // Behind the camera, where `project` refuses: finite numbers, so an optimiser can
            // evaluate and reject the step.
            let behind = model.linearise(&Point3::new(0.1, 0.1, -0.5));
            assert!(model.project(&Point3::new(0.1, 0.1, -0.5)).is_none());
            assert!(behind.pixel.coords.iter().all(|v| v.is_finite()));
            assert!(behind.d_pixel_d_point.iter().all(|v| v.is_finite()));
        }
    }
}
