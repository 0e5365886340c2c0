//! Lens distortion on normalised image coordinates: the models ([`Distortion`]: OpenCV's
//! `plumb_bob` = Kalibr `radtan`, OpenCV's fisheye = Kalibr `equidistant`), their Jacobians
//! (with respect to the point and to the coefficients), their inverse by Gauss-Newton, and the
//! packing of the coefficients as optimisation parameters.
//!
//! Pure maths on `nalgebra`: depends on nothing else of ours.

use nalgebra::{Matrix2, Matrix2xX, Vector2};

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
    /// [`CameraModel::distortion_coefficients`](super::CameraModel::distortion_coefficients), which writes five zeros for a file).
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

#[cfg(test)]
mod tests {
    use nalgebra::{Matrix2, Vector2};

    use super::Distortion;
    use crate::camera_model::tests::models;

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
    }
}
