//! The pinhole camera model with lens distortion: projection, unprojection, projection
//! Jacobians, and the intrinsics file forms (ROS/OpenCV `camera_info` YAML, Kalibr camchain
//! YAML).
//!
//! Frames: points are in the `camera` optical frame (x right, y down, z forward), metres.
//! Pixels use OpenCV's convention (pixel centres at integer coordinates), which is also what
//! ROS `camera_info` and Kalibr intrinsics assume, so files load without any offset.
//! Distortion models: `RadTan` is OpenCV's `plumb_bob` (k1 k2 p1 p2 k3, Kalibr `radtan`),
//! `Equidistant` is OpenCV's fisheye model (k1..k4 on the angle, Kalibr `equidistant`).
//! For optimisers (the reprojection-space refinement) it also owns the parameter packing of the
//! intrinsics and distortion coefficients, their Jacobians, and a projection that never fails
//! ([`CameraModel::linearise`]): the one implementation every solver uses.
//! Part of the ground floor (see `tests/layers.rs`): depends on `atomic_file` only; knows
//! nothing of boards, detectors or robots.

use std::path::{Path, PathBuf};

use nalgebra::{Matrix2, Matrix2x3, Matrix2x4, Matrix2xX, Point2, Point3, Vector2, Vector3};
use serde_yaml_ng::Value;

use crate::atomic_file::write_atomic;

/// Lens distortion applied to normalised image coordinates `(x/z, y/z)`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Distortion {
    /// An ideal pinhole.
    None,
    /// Radial-tangential (OpenCV `plumb_bob`, Kalibr `radtan`).
    RadTan {
        /// Radial coefficient of r².
        k1: f64,
        /// Radial coefficient of r⁴.
        k2: f64,
        /// First tangential coefficient.
        p1: f64,
        /// Second tangential coefficient.
        p2: f64,
        /// Radial coefficient of r⁶.
        k3: f64,
    },
    /// Equidistant fisheye (OpenCV `fisheye`, ROS/Kalibr `equidistant`): θd = θ(1 + k1θ² + ... + k4θ⁸).
    Equidistant {
        /// Coefficient of θ².
        k1: f64,
        /// Coefficient of θ⁴.
        k2: f64,
        /// Coefficient of θ⁶.
        k3: f64,
        /// Coefficient of θ⁸.
        k4: f64,
    },
}

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

/// Why an intrinsics file could not be used.
#[derive(Debug, thiserror::Error)]
pub enum CameraModelError {
    /// The file could not be read or written.
    #[error("intrinsics file {path}: cannot read or write")]
    Io {
        /// The file.
        path: PathBuf,
        /// The I/O failure.
        #[source]
        source: std::io::Error,
    },
    /// The file is not YAML.
    // The parser's error is the problem itself (no further cause): in the message, not also a
    // `#[source]`, so `{:#}` chains print it once.
    #[error("intrinsics file {path}: not valid YAML: {problem}")]
    Yaml {
        /// The file.
        path: PathBuf,
        /// The parser's error.
        problem: serde_yaml_ng::Error,
    },
    /// The YAML is neither a `camera_info` file nor a Kalibr camchain.
    #[error(
        "intrinsics file {path}: neither a camera_info YAML (needs `camera_matrix`) nor a Kalibr \
         camchain (needs `cam0`)"
    )]
    UnknownFormat {
        /// The file.
        path: PathBuf,
    },
    /// A required key is absent.
    #[error("intrinsics file {path}: missing key `{key}`")]
    MissingKey {
        /// The file.
        path: PathBuf,
        /// The YAML path of the key.
        key: String,
    },
    /// A key holds a value of the wrong form or out of range.
    #[error("intrinsics file {path}: `{key}` must be {expected}, found {found}")]
    BadValue {
        /// The file.
        path: PathBuf,
        /// The YAML path of the key.
        key: String,
        /// What was expected.
        expected: String,
        /// What was found.
        found: String,
    },
}

/// How many Gauss-Newton steps unprojection takes at most; converges in 3-6 for real lenses.
const UNDISTORT_MAX_ITERATIONS: usize = 30;

impl Distortion {
    /// Applies the distortion to normalised coordinates.
    pub fn distort(&self, xn: Vector2<f64>) -> Vector2<f64> {
        match *self {
            Distortion::None => xn,
            Distortion::RadTan { k1, k2, p1, p2, k3 } => {
                let (x, y) = (xn.x, xn.y);
                let r2 = x * x + y * y;
                let radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3));
                Vector2::new(
                    x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x),
                    y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y,
                )
            }
            Distortion::Equidistant { k1, k2, k3, k4 } => {
                let r = xn.norm();
                if r < 1e-12 {
                    return xn;
                }
                let theta = r.atan();
                let t2 = theta * theta;
                let theta_d = theta * (1.0 + t2 * (k1 + t2 * (k2 + t2 * (k3 + t2 * k4))));
                xn * (theta_d / r)
            }
        }
    }

    /// The 2x2 Jacobian of [`Distortion::distort`] at `xn` (analytic).
    pub fn jacobian(&self, xn: Vector2<f64>) -> Matrix2<f64> {
        match *self {
            Distortion::None => Matrix2::identity(),
            Distortion::RadTan { k1, k2, p1, p2, k3 } => {
                let (x, y) = (xn.x, xn.y);
                let r2 = x * x + y * y;
                let radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3));
                let d_radial = k1 + r2 * (2.0 * k2 + 3.0 * k3 * r2);
                let cross = 2.0 * x * y * d_radial + 2.0 * p1 * x + 2.0 * p2 * y;
                Matrix2::new(
                    radial + 2.0 * x * x * d_radial + 2.0 * p1 * y + 6.0 * p2 * x,
                    cross,
                    cross,
                    radial + 2.0 * y * y * d_radial + 6.0 * p1 * y + 2.0 * p2 * x,
                )
            }
            Distortion::Equidistant { k1, k2, k3, k4 } => {
                let r = xn.norm();
                if r < 1e-9 {
                    return Matrix2::identity();
                }
                let theta = r.atan();
                let t2 = theta * theta;
                let theta_d = theta * (1.0 + t2 * (k1 + t2 * (k2 + t2 * (k3 + t2 * k4))));
                let d_theta_d =
                    1.0 + t2 * (3.0 * k1 + t2 * (5.0 * k2 + t2 * (7.0 * k3 + t2 * 9.0 * k4)));
                let scale = theta_d / r;
                let d_scale = (d_theta_d / (1.0 + r * r) * r - theta_d) / (r * r);
                Matrix2::identity() * scale + (xn * xn.transpose()) * (d_scale / r)
            }
        }
    }

    /// Inverts the distortion by Gauss-Newton from the distorted point; `None` if it does
    /// not converge (a point outside the lens model's monotonic range).
    pub fn undistort(&self, xd: Vector2<f64>) -> Option<Vector2<f64>> {
        if matches!(self, Distortion::None) {
            return Some(xd);
        }
        let mut xn = xd;
        for _ in 0..UNDISTORT_MAX_ITERATIONS {
            let error = self.distort(xn) - xd;
            if error.norm() < 1e-14 {
                return Some(xn);
            }
            let step = self.jacobian(xn).try_inverse()? * error;
            xn -= step;
            if !xn.iter().all(|v| v.is_finite()) {
                return None;
            }
        }
        ((self.distort(xn) - xd).norm() < 1e-9).then_some(xn)
    }

    /// How many coefficients the model has as optimisation parameters: 0 (`None`), 5
    /// (`RadTan`: k1 k2 p1 p2 k3) or 4 (`Equidistant`: k1..k4).
    pub fn coefficient_count(&self) -> usize {
        match self {
            Distortion::None => 0,
            Distortion::RadTan { .. } => 5,
            Distortion::Equidistant { .. } => 4,
        }
    }

    /// The coefficients as optimisation parameters, in the order of
    /// [`Distortion::coefficient_count`] (empty for `None`; unlike
    /// [`CameraModel::distortion_coefficients`], which writes five zeros for a file).
    pub fn coefficients(&self) -> Vec<f64> {
        match *self {
            Distortion::None => Vec::new(),
            Distortion::RadTan { k1, k2, p1, p2, k3 } => vec![k1, k2, p1, p2, k3],
            Distortion::Equidistant { k1, k2, k3, k4 } => vec![k1, k2, k3, k4],
        }
    }

    /// The same model with the coefficients `c` (order of [`Distortion::coefficients`]);
    /// `None` when `c` does not hold exactly [`Distortion::coefficient_count`] numbers.
    pub fn with_coefficients(&self, c: &[f64]) -> Option<Distortion> {
        if c.len() != self.coefficient_count() {
            return None;
        }
        Some(match self {
            Distortion::None => Distortion::None,
            Distortion::RadTan { .. } => Distortion::RadTan {
                k1: c[0],
                k2: c[1],
                p1: c[2],
                p2: c[3],
                k3: c[4],
            },
            Distortion::Equidistant { .. } => Distortion::Equidistant {
                k1: c[0],
                k2: c[1],
                k3: c[2],
                k4: c[3],
            },
        })
    }

    /// The 2 x [`Distortion::coefficient_count`] Jacobian of [`Distortion::distort`] at `xn`
    /// with respect to the coefficients (analytic; the distortion is linear in them, so it does
    /// not depend on their values).
    pub fn coefficient_jacobian(&self, xn: Vector2<f64>) -> Matrix2xX<f64> {
        match *self {
            Distortion::None => Matrix2xX::zeros(0),
            Distortion::RadTan { .. } => {
                let (x, y) = (xn.x, xn.y);
                let r2 = x * x + y * y;
                let r4 = r2 * r2;
                Matrix2xX::from_row_slice(&[
                    x * r2,
                    x * r4,
                    2.0 * x * y,
                    r2 + 2.0 * x * x,
                    x * r4 * r2,
                    y * r2,
                    y * r4,
                    r2 + 2.0 * y * y,
                    2.0 * x * y,
                    y * r4 * r2,
                ])
            }
            Distortion::Equidistant { .. } => {
                // θd is linear in the coefficients: d/dk_i = xn/r · θ^(2i+3).
                let r = xn.norm();
                let mut j = Matrix2xX::zeros(4);
                if r > 1e-12 {
                    let theta = r.atan();
                    let mut power = theta * theta * theta;
                    for i in 0..4 {
                        let column = xn * (power / r);
                        j[(0, i)] = column.x;
                        j[(1, i)] = column.y;
                        power *= theta * theta;
                    }
                }
                j
            }
        }
    }
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

    /// Checks the model's numbers (positive finite focal lengths and size, finite coefficients).
    pub fn validate(&self, path: &Path) -> Result<(), CameraModelError> {
        let bad = |key: &str, expected: &str, found: String| CameraModelError::BadValue {
            path: path.to_path_buf(),
            key: key.to_string(),
            expected: expected.to_string(),
            found,
        };
        if self.width == 0 || self.height == 0 {
            return Err(bad(
                "image size",
                "positive width and height (px)",
                format!("{}x{}", self.width, self.height),
            ));
        }
        for (key, value) in [("fx", self.fx), ("fy", self.fy)] {
            if !(value.is_finite() && value > 0.0) {
                return Err(bad(key, "a positive focal length (px)", value.to_string()));
            }
        }
        for (key, value) in [("cx", self.cx), ("cy", self.cy)] {
            if !value.is_finite() {
                return Err(bad(key, "a finite principal point (px)", value.to_string()));
            }
        }
        let coefficients = self.distortion_coefficients();
        if !coefficients.iter().all(|v| v.is_finite()) {
            return Err(bad(
                "distortion coefficients",
                "finite numbers",
                format!("{coefficients:?}"),
            ));
        }
        Ok(())
    }

    /// The distortion coefficients in file order (`plumb_bob`: k1 k2 p1 p2 k3; `equidistant`: k1..k4).
    pub fn distortion_coefficients(&self) -> Vec<f64> {
        match self.distortion {
            Distortion::None => vec![0.0; 5],
            Distortion::RadTan { k1, k2, p1, p2, k3 } => vec![k1, k2, p1, p2, k3],
            Distortion::Equidistant { k1, k2, k3, k4 } => vec![k1, k2, k3, k4],
        }
    }

    /// Loads intrinsics from a ROS/OpenCV `camera_info` YAML or a Kalibr camchain YAML (its
    /// `cam0`), detected by their keys.
    pub fn load(path: &Path) -> Result<Self, CameraModelError> {
        let text = std::fs::read_to_string(path).map_err(|source| CameraModelError::Io {
            path: path.to_path_buf(),
            source,
        })?;
        Self::from_yaml_str(&text, path)
    }

    /// Parses intrinsics YAML text; `path` only names the source in errors.
    pub fn from_yaml_str(text: &str, path: &Path) -> Result<Self, CameraModelError> {
        let value: Value =
            serde_yaml_ng::from_str(text).map_err(|problem| CameraModelError::Yaml {
                path: path.to_path_buf(),
                problem,
            })?;
        let reader = Reader { path };
        let model = if value.get("camera_matrix").is_some() {
            reader.camera_info(&value)?
        } else if let Some(cam0) = value.get("cam0") {
            reader.kalibr(cam0)?
        } else {
            return Err(CameraModelError::UnknownFormat {
                path: path.to_path_buf(),
            });
        };
        model.validate(path)?;
        Ok(model)
    }

    /// The ROS `camera_info` YAML text of this model (`plumb_bob` or `equidistant`).
    pub fn to_camera_info_yaml(&self, camera_name: &str) -> String {
        let (model_name, coefficients) = match self.distortion {
            Distortion::Equidistant { .. } => ("equidistant", self.distortion_coefficients()),
            _ => ("plumb_bob", self.distortion_coefficients()),
        };
        let list = |values: &[f64]| {
            values
                .iter()
                .map(|v| format!("{v:?}"))
                .collect::<Vec<_>>()
                .join(", ")
        };
        let (fx, fy, cx, cy) = (self.fx, self.fy, self.cx, self.cy);
        format!(
            "# Pixel centres at integer coordinates (OpenCV/ROS convention).\n\
             image_width: {w}\nimage_height: {h}\ncamera_name: {camera_name}\n\
             camera_matrix:\n  rows: 3\n  cols: 3\n  data: [{k}]\n\
             distortion_model: {model_name}\n\
             distortion_coefficients:\n  rows: 1\n  cols: {n}\n  data: [{d}]\n\
             rectification_matrix:\n  rows: 3\n  cols: 3\n  data: [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]\n\
             projection_matrix:\n  rows: 3\n  cols: 4\n  data: [{p}]\n",
            w = self.width,
            h = self.height,
            k = list(&[fx, 0.0, cx, 0.0, fy, cy, 0.0, 0.0, 1.0]),
            n = coefficients.len(),
            d = list(&coefficients),
            p = list(&[fx, 0.0, cx, 0.0, 0.0, fy, cy, 0.0, 0.0, 0.0, 1.0, 0.0]),
        )
    }

    /// Writes this model as a ROS `camera_info` YAML (atomically).
    pub fn save_camera_info(&self, path: &Path) -> Result<(), CameraModelError> {
        let name = path
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_else(|| "camera".to_string());
        write_atomic(path, self.to_camera_info_yaml(&name).as_bytes()).map_err(|source| {
            CameraModelError::Io {
                path: path.to_path_buf(),
                source,
            }
        })
    }
}

/// Pulls typed values out of a YAML tree, naming the file and key path in every error.
struct Reader<'a> {
    path: &'a Path,
}

impl Reader<'_> {
    fn missing(&self, key: &str) -> CameraModelError {
        CameraModelError::MissingKey {
            path: self.path.to_path_buf(),
            key: key.to_string(),
        }
    }

    fn bad(&self, key: &str, expected: &str, found: &Value) -> CameraModelError {
        // Flow style (`[800.0]`), never block style: `- 800.0` reads as a negative number.
        // JSON is flow-style YAML; a mapping with non-string keys falls back to YAML.
        let found = serde_json::to_string(found)
            .or_else(|_| serde_yaml_ng::to_string(found).map(|s| s.trim().to_string()))
            .unwrap_or_else(|_| "?".to_string());
        CameraModelError::BadValue {
            path: self.path.to_path_buf(),
            key: key.to_string(),
            expected: expected.to_string(),
            found,
        }
    }

    fn get<'v>(
        &self,
        node: &'v Value,
        key: &str,
        full_key: &str,
    ) -> Result<&'v Value, CameraModelError> {
        node.get(key).ok_or_else(|| self.missing(full_key))
    }

    fn size(&self, value: &Value, key: &str) -> Result<u32, CameraModelError> {
        value
            .as_u64()
            .and_then(|v| u32::try_from(v).ok())
            .filter(|v| *v > 0)
            .ok_or_else(|| self.bad(key, "a positive integer (px)", value))
    }

    fn numbers(
        &self,
        value: &Value,
        key: &str,
        lengths: &[usize],
    ) -> Result<Vec<f64>, CameraModelError> {
        let expected = format!(
            "a list of {} numbers",
            lengths
                .iter()
                .map(|n| n.to_string())
                .collect::<Vec<_>>()
                .join(" or ")
        );
        let list = value
            .as_sequence()
            .ok_or_else(|| self.bad(key, &expected, value))?;
        let numbers: Option<Vec<f64>> = list.iter().map(Value::as_f64).collect();
        match numbers {
            Some(numbers) if lengths.contains(&numbers.len()) => Ok(numbers),
            _ => Err(self.bad(key, &expected, value)),
        }
    }

    fn camera_info(&self, root: &Value) -> Result<CameraModel, CameraModelError> {
        let width = self.size(self.get(root, "image_width", "image_width")?, "image_width")?;
        let height = self.size(
            self.get(root, "image_height", "image_height")?,
            "image_height",
        )?;
        let matrix = self.get(root, "camera_matrix", "camera_matrix")?;
        let k = self.numbers(
            self.get(matrix, "data", "camera_matrix.data")?,
            "camera_matrix.data",
            &[9],
        )?;
        if k[1] != 0.0 || k[3] != 0.0 || k[6] != 0.0 || k[7] != 0.0 || k[8] != 1.0 {
            return Err(self.bad(
                "camera_matrix.data",
                "[fx, 0, cx, 0, fy, cy, 0, 0, 1] (no skew)",
                &matrix["data"],
            ));
        }
        let model_name = match root.get("distortion_model") {
            None => "plumb_bob".to_string(),
            Some(v) => v
                .as_str()
                .ok_or_else(|| self.bad("distortion_model", "a string", v))?
                .to_string(),
        };
        let coefficients = match root.get("distortion_coefficients") {
            None => Vec::new(),
            Some(node) => self.numbers(
                self.get(node, "data", "distortion_coefficients.data")?,
                "distortion_coefficients.data",
                &[0, 4, 5, 8],
            )?,
        };
        let distortion = self.distortion(&model_name, &coefficients, "distortion_model")?;
        Ok(CameraModel {
            width,
            height,
            fx: k[0],
            fy: k[4],
            cx: k[2],
            cy: k[5],
            distortion,
        })
    }

    fn kalibr(&self, cam0: &Value) -> Result<CameraModel, CameraModelError> {
        if let Some(model) = cam0.get("camera_model") {
            if model.as_str() != Some("pinhole") {
                return Err(self.bad("cam0.camera_model", "`pinhole`", model));
            }
        }
        let intrinsics = self.numbers(
            self.get(cam0, "intrinsics", "cam0.intrinsics")?,
            "cam0.intrinsics",
            &[4],
        )?;
        let resolution = self.get(cam0, "resolution", "cam0.resolution")?;
        let size = self.numbers(resolution, "cam0.resolution", &[2])?;
        let to_size = |v: f64| {
            (v.fract() == 0.0 && v > 0.0 && v < u32::MAX as f64)
                .then_some(v as u32)
                .ok_or_else(|| self.bad("cam0.resolution", "[width, height] in px", resolution))
        };
        let model_name = self
            .get(cam0, "distortion_model", "cam0.distortion_model")?
            .as_str()
            .ok_or_else(|| {
                self.bad(
                    "cam0.distortion_model",
                    "a string",
                    &cam0["distortion_model"],
                )
            })?
            .to_string();
        let coefficients = self.numbers(
            self.get(cam0, "distortion_coeffs", "cam0.distortion_coeffs")?,
            "cam0.distortion_coeffs",
            &[0, 4, 5],
        )?;
        let distortion = self.distortion(&model_name, &coefficients, "cam0.distortion_model")?;
        Ok(CameraModel {
            width: to_size(size[0])?,
            height: to_size(size[1])?,
            fx: intrinsics[0],
            fy: intrinsics[1],
            cx: intrinsics[2],
            cy: intrinsics[3],
            distortion,
        })
    }

    fn distortion(&self, name: &str, c: &[f64], key: &str) -> Result<Distortion, CameraModelError> {
        let count_error = |expected: &str| CameraModelError::BadValue {
            path: self.path.to_path_buf(),
            key: format!("{key} coefficients"),
            expected: expected.to_string(),
            found: format!("{} coefficients for `{name}`", c.len()),
        };
        match name {
            "plumb_bob" | "radtan" => match c.len() {
                0 => Ok(Distortion::None),
                4 | 5 => Ok(Distortion::RadTan {
                    k1: c[0],
                    k2: c[1],
                    p1: c[2],
                    p2: c[3],
                    k3: c.get(4).copied().unwrap_or(0.0),
                }),
                _ => Err(count_error("4 or 5 coefficients (k1 k2 p1 p2 [k3])")),
            },
            "equidistant" | "fisheye" => match c.len() {
                4 => Ok(Distortion::Equidistant {
                    k1: c[0],
                    k2: c[1],
                    k3: c[2],
                    k4: c[3],
                }),
                _ => Err(count_error("4 coefficients (k1 k2 k3 k4)")),
            },
            "none" => Ok(Distortion::None),
            _ => Err(CameraModelError::BadValue {
                path: self.path.to_path_buf(),
                key: key.to_string(),
                expected: "plumb_bob, radtan, equidistant, fisheye or none".to_string(),
                found: name.to_string(),
            }),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn models() -> [CameraModel; 2] {
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
    fn distortion_jacobian_matches_central_differences() {
        for model in models() {
            for xn in [
                Vector2::new(0.31, -0.22),
                Vector2::new(-0.6, 0.35),
                Vector2::new(1e-4, 2e-4),
            ] {
                let h = 1e-6;
                let d = &model.distortion;
                let dx = (d.distort(xn + Vector2::new(h, 0.0))
                    - d.distort(xn - Vector2::new(h, 0.0)))
                    / (2.0 * h);
                let dy = (d.distort(xn + Vector2::new(0.0, h))
                    - d.distort(xn - Vector2::new(0.0, h)))
                    / (2.0 * h);
                let numeric = Matrix2::from_columns(&[dx, dy]);
                assert!((numeric - d.jacobian(xn)).norm() < 1e-8, "{d:?} at {xn}");
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
    fn coefficient_packing_round_trips_and_refuses_a_wrong_count() {
        for model in models() {
            let d = model.distortion;
            let c = d.coefficients();
            assert_eq!(c.len(), d.coefficient_count());
            assert_eq!(d.with_coefficients(&c), Some(d));
            assert_eq!(d.with_coefficients(&c[1..]), None);
            let shifted: Vec<f64> = c.iter().map(|v| v + 0.5).collect();
            assert_eq!(
                d.with_coefficients(&shifted).map(|e| e.coefficients()),
                Some(shifted)
            );
        }
        assert_eq!(Distortion::None.coefficients(), Vec::<f64>::new());
        assert_eq!(
            Distortion::None.with_coefficients(&[]),
            Some(Distortion::None)
        );
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

    #[test]
    fn camera_info_round_trips_through_save_and_load() {
        let dir = tempfile::tempdir().unwrap();
        for (i, model) in models().into_iter().enumerate() {
            let path = dir.path().join(format!("cam{i}.yaml"));
            model.save_camera_info(&path).unwrap();
            let loaded = CameraModel::load(&path).unwrap();
            assert_eq!(loaded, model);
        }
    }

    #[test]
    fn kalibr_camchain_loads_cam0() {
        let text = "cam0:\n  camera_model: pinhole\n  intrinsics: [461.6, 460.3, 363.0, 248.1]\n  \
                    distortion_model: radtan\n  distortion_coeffs: [-0.2917, 0.08228, 5.333e-05, -0.0001578]\n  \
                    resolution: [752, 480]\n  rostopic: /cam0/image_raw\n";
        let model = CameraModel::from_yaml_str(text, Path::new("camchain.yaml")).unwrap();
        assert_eq!((model.width, model.height), (752, 480));
        assert_eq!(model.fx, 461.6);
        assert_eq!(
            model.distortion,
            Distortion::RadTan {
                k1: -0.2917,
                k2: 0.08228,
                p1: 5.333e-05,
                p2: -0.0001578,
                k3: 0.0
            }
        );
    }

    #[test]
    fn bad_files_name_the_key_and_expectation() {
        let path = Path::new("bad.yaml");
        let error = CameraModel::from_yaml_str("foo: 1\n", path).unwrap_err();
        assert!(
            matches!(error, CameraModelError::UnknownFormat { .. }),
            "{error}"
        );
        let error = CameraModel::from_yaml_str(
            "image_width: 640\nimage_height: 480\ncamera_matrix: {data: [1, 0, 2, 0, 1, 2, 0, 0]}\n",
            path,
        )
        .unwrap_err();
        let message = error.to_string();
        assert!(
            message.contains("camera_matrix.data") && message.contains("9 numbers"),
            "{message}"
        );
        let error = CameraModel::from_yaml_str(
            "image_width: 640\nimage_height: 480\ncamera_matrix: {data: [-5, 0, 2, 0, 1, 2, 0, 0, 1]}\n",
            path,
        )
        .unwrap_err();
        assert!(error.to_string().contains("fx"), "{error}");
        let error = CameraModel::from_yaml_str(
            "image_width: 640\nimage_height: 480\ncamera_matrix: {data: [5, 0, 2, 0, 1, 2, 0, 0, 1]}\n\
             distortion_model: rational_polynomial\ndistortion_coefficients: {data: [0, 0, 0, 0, 0, 0, 0, 0]}\n",
            path,
        )
        .unwrap_err();
        assert!(error.to_string().contains("rational_polynomial"), "{error}");
    }
}
