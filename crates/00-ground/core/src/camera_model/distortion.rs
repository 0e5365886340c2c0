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

/// How far the radial distortion may scale a radius inside the image (`r_d / r`, either way):
/// real lenses stay well within (a strong barrel lens about 0.5 at its corners); a model past it
/// is a typo or a fit gone wrong, and projects the board to nonsense.
pub const MAX_RADIAL_SCALE: f64 = 10.0;

/// How many radii the check of [`Distortion::check_over_image`] walks from the centre out.
const RADIAL_CHECK_STEPS: usize = 4000;

/// Why a distortion model is not a lens over its image: the coefficient most to blame, its
/// value and what goes wrong (see [`Distortion::check_over_image`]).
#[derive(Debug, Clone, PartialEq)]
pub struct DistortionProblem {
    /// The coefficient's name (`k1`, `p2`...).
    pub coefficient: &'static str,
    /// Its value.
    pub value: f64,
    /// What a lens needs (for "must be ...").
    pub expected: String,
    /// What this model does instead, with where (px from the principal point).
    pub problem: String,
}

impl Distortion {
    /// Checks that the model is a lens over an image whose farthest corner lies at the distorted
    /// normalised radius `corner_radius` (pixel distance over the focal length): walking out from
    /// the centre to that corner, the distorted radius keeps growing (the model does not fold
    /// over, so every pixel has one direction), it scales the radius by no more than
    /// [`MAX_RADIAL_SCALE`] either way, and the whole map stays locally one-to-one (a positive
    /// Jacobian determinant, which the tangential terms could break). `focal_px` only turns radii
    /// into pixels for the message. An equidistant model is walked in the ray angle θ up to 90°:
    /// the corners of a fisheye image past that are outside its image circle.
    pub fn check_over_image(
        &self,
        corner_radius: f64,
        focal_px: f64,
    ) -> Result<(), DistortionProblem> {
        // (name, value, power of the radius the term multiplies in the scale r_d / r)
        let radial: Vec<(&'static str, f64, i32)> = match *self {
            Distortion::None => return Ok(()),
            Distortion::RadTan { k1, k2, k3, .. } => {
                vec![("k1", k1, 2), ("k2", k2, 4), ("k3", k3, 6)]
            }
            Distortion::Equidistant { k1, k2, k3, k4 } => {
                vec![("k1", k1, 2), ("k2", k2, 4), ("k3", k3, 6), ("k4", k4, 8)]
            }
        };
        let is_fisheye = matches!(self, Distortion::Equidistant { .. });
        // Radius (RadTan: r = |xn|; equidistant: θ) at which the walk gives up: the scale bound
        // means the corner is reached by MAX_RADIAL_SCALE · corner_radius.
        let mut end = MAX_RADIAL_SCALE * corner_radius;
        if is_fisheye {
            end = end.min(std::f64::consts::FRAC_PI_2);
        }
        let blame = |r: f64| {
            radial
                .iter()
                .copied()
                .max_by(|a, b| {
                    (a.1 * r.powi(a.2))
                        .abs()
                        .total_cmp(&(b.1 * r.powi(b.2)).abs())
                })
                .map(|(name, value, _)| (name, value))
                .unwrap_or(("k1", 0.0))
        };
        let px = |distorted: f64| distorted * focal_px;
        let mut reached = 0.0;
        for step in 1..=RADIAL_CHECK_STEPS {
            let r = end * step as f64 / RADIAL_CHECK_STEPS as f64;
            let scale = 1.0 + radial.iter().map(|(_, k, p)| k * r.powi(*p)).sum::<f64>();
            let slope = 1.0
                + radial
                    .iter()
                    .map(|(_, k, p)| f64::from(p + 1) * k * r.powi(*p))
                    .sum::<f64>();
            let distorted = r * scale;
            if !(scale.is_finite() && (1.0 / MAX_RADIAL_SCALE..=MAX_RADIAL_SCALE).contains(&scale))
            {
                let (coefficient, value) = blame(r);
                return Err(DistortionProblem {
                    coefficient,
                    value,
                    expected: format!(
                        "a lens distortion that scales a radius inside the image by {:.1}x to \
                         {MAX_RADIAL_SCALE}x",
                        1.0 / MAX_RADIAL_SCALE
                    ),
                    problem: format!(
                        "it scales the radius by {scale:.3e}x at {:.0} px from the principal \
                         point (the image's farthest corner is {:.0} px away)",
                        px(r),
                        px(corner_radius)
                    ),
                });
            }
            if slope <= 0.0 {
                let (coefficient, value) = blame(r);
                return Err(DistortionProblem {
                    coefficient,
                    value,
                    expected: "a radial distortion that keeps growing out to the image's \
                               corners (one direction per pixel)"
                        .to_string(),
                    problem: format!(
                        "the model folds over at {:.0} px from the principal point, inside the \
                         image (its farthest corner is {:.0} px away): pixels beyond map back \
                         inwards",
                        px(distorted),
                        px(corner_radius)
                    ),
                });
            }
            reached = r;
            if distorted >= corner_radius {
                break;
            }
        }
        if let Distortion::RadTan { p1, p2, .. } = *self {
            for direction in 0..16 {
                let angle = f64::from(direction) * std::f64::consts::PI / 8.0;
                for step in 1..=64 {
                    let r = reached * f64::from(step) / 64.0;
                    let xn = Vector2::new(r * angle.cos(), r * angle.sin());
                    if self.jacobian(xn).determinant() <= 0.0 {
                        let (coefficient, value) = if p1.abs() >= p2.abs() {
                            ("p1", p1)
                        } else {
                            ("p2", p2)
                        };
                        return Err(DistortionProblem {
                            coefficient,
                            value,
                            expected: "a tangential distortion that keeps the image one-to-one"
                                .to_string(),
                            problem: format!(
                                "the map stops being one-to-one for rays {:.0} px (undistorted) \
                                 from the principal point, before the image's farthest corner \
                                 ({:.0} px away)",
                                px(r),
                                px(corner_radius)
                            ),
                        });
                    }
                }
            }
        }
        Ok(())
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
