//! Generated plans: views spread over a spherical cap above the board.
//!
//! Tilts are spread area-uniformly over the cap, azimuths follow the golden angle, and the roll
//! about the optical axis alternates in sign and grows with the index, so the relative rotations
//! between any two poses point along well-spread axes: the non-coaxial motion the solver needs.
//! A seeded jitter keeps the views off a too-regular lattice.

use rand::{Rng, SeedableRng};
use serde::{Deserialize, Serialize};

use super::LookAt;
use handeye_core::camera_model::CameraModel;
use handeye_core::geometry::readable;
use handeye_vision::Target;

/// How to generate a plan.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GenerateSpec {
    /// Number of views.
    pub count: usize,
    /// Nearest and farthest camera-to-board-centre distance, m.
    pub distance: [f64; 2],
    /// Largest tilt of the optical axis from the board normal, degrees.
    #[serde(default = "default_max_tilt_deg")]
    pub max_tilt_deg: f64,
    /// Largest roll about the optical axis, degrees.
    #[serde(default = "default_max_roll_deg")]
    pub max_roll_deg: f64,
    /// Seed of the jitter.
    #[serde(default)]
    pub seed: u64,
    /// How far the views push the board across the image: the share (0–1) of the room between
    /// the centred board and the image border (less the session's image margin), along
    /// directions that go round the image. Default: 0.8 when the cell config has no intrinsics
    /// (estimating them needs corners all over the image), 0 otherwise (a centred board).
    #[serde(default)]
    pub image_spread: Option<f64>,
}

fn default_max_tilt_deg() -> f64 {
    35.0
}
fn default_max_roll_deg() -> f64 {
    30.0
}

/// Largest camera-to-board distance a generated plan may ask for, m.
pub const MAX_DISTANCE_M: f64 = 10.0;

/// A generated-plan spec value out of range: the field, the value and what is accepted.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{field}: expected {expected}, found {found}")]
pub struct GenerateSpecError {
    /// The spec's key (`count`, `distance`, ...).
    pub field: &'static str,
    /// The value as written.
    pub found: String,
    /// What is accepted.
    pub expected: String,
}

impl GenerateSpec {
    /// Checks the numbers describe a plan one can generate, and one of a sane size (at most
    /// [`MAX_PLAN_POSES`](super::MAX_PLAN_POSES) views).
    pub fn validate(&self) -> Result<(), GenerateSpecError> {
        let bad = |field, found: String, expected: String| {
            Err(GenerateSpecError {
                field,
                found,
                expected,
            })
        };
        if !(3..=super::MAX_PLAN_POSES).contains(&self.count) {
            return bad(
                "count",
                self.count.to_string(),
                format!(
                    "a number of views in [3, {}] (3 is the fewest that fix both unknowns)",
                    super::MAX_PLAN_POSES
                ),
            );
        }
        let [near, far] = self.distance;
        if !(near.is_finite()
            && far.is_finite()
            && near > 0.0
            && far >= near
            && far <= MAX_DISTANCE_M)
        {
            return bad(
                "distance",
                format!("[{}, {}]", readable(near), readable(far)),
                format!("[near, far] in metres with 0 < near <= far <= {MAX_DISTANCE_M}"),
            );
        }
        if !(self.max_tilt_deg > 0.0 && self.max_tilt_deg < 80.0) {
            return bad(
                "max_tilt_deg",
                readable(self.max_tilt_deg),
                "a value in (0, 80) °".into(),
            );
        }
        if !(self.max_roll_deg >= 0.0 && self.max_roll_deg <= 180.0) {
            return bad(
                "max_roll_deg",
                readable(self.max_roll_deg),
                "a value in [0, 180] °".into(),
            );
        }
        if let Some(spread) = self.image_spread {
            if !(0.0..=1.0).contains(&spread) {
                return bad(
                    "image_spread",
                    readable(spread),
                    "a share of the room in [0, 1]".into(),
                );
            }
        }
        Ok(())
    }
}

/// Default `image_spread` when the intrinsics are to be estimated from the run.
pub const IMAGE_SPREAD_FOR_INTRINSICS: f64 = 0.8;

/// Turns each view so the board appears off-centre (`LookAt::board_in_image_deg`): view `i`
/// along the image direction `i` golden angles round, by `spread` of the largest offset that
/// keeps every board corner `margin_px` inside the image. A view whose centred board is already
/// too close to the border stays centred.
pub fn spread_across_image(
    views: &mut [LookAt],
    spread: f64,
    camera: &CameraModel,
    board: &Target,
    margin_px: f64,
) {
    if spread <= 0.0 {
        return;
    }
    let points = super::check::board_points(board);
    let centre = super::check::board_centre(board);
    let golden_angle = std::f64::consts::PI * (3.0 - 5f64.sqrt());
    for (i, view) in views.iter_mut().enumerate() {
        let direction = i as f64 * golden_angle + std::f64::consts::FRAC_PI_4;
        let at = |degrees: f64| LookAt {
            board_in_image_deg: [direction.cos() * degrees, direction.sin() * degrees],
            ..*view
        };
        let fits = |degrees: f64| {
            let camera_from_target = at(degrees).target_from_camera(&centre).inverse();
            super::check::board_margin(camera, &camera_from_target, &points) >= margin_px
        };
        if !fits(0.0) {
            continue;
        }
        // The margin shrinks as the board moves out: bisect for the largest offset that fits.
        let (mut inside, mut outside) = (0.0, 59.0);
        if fits(outside) {
            inside = outside;
        }
        for _ in 0..40 {
            let middle = 0.5 * (inside + outside);
            if fits(middle) {
                inside = middle;
            } else {
                outside = middle;
            }
        }
        *view = at(spread * inside);
    }
}

/// The views of a generated plan.
pub fn generate(spec: &GenerateSpec) -> Vec<LookAt> {
    let golden_angle_deg = 180.0 * (3.0 - 5f64.sqrt());
    let mut rng = rand::rngs::StdRng::seed_from_u64(spec.seed);
    let n = spec.count as f64;
    (0..spec.count)
        .map(|i| {
            let k = i as f64 + 0.5;
            // Area-uniform over the cap: 1 − cos(tilt) grows linearly with the index.
            let cos_max = spec.max_tilt_deg.to_radians().cos();
            let tilt = (1.0 - (1.0 - cos_max) * k / n).acos().to_degrees();
            let tilt = (tilt + rng.random_range(-2.0..2.0)).clamp(0.0, spec.max_tilt_deg);
            let azimuth = (i as f64 * golden_angle_deg + rng.random_range(-10.0..10.0)) % 360.0;
            let sign = if i % 2 == 0 { 1.0 } else { -1.0 };
            let roll = sign * spec.max_roll_deg * ((k / n) * 0.8 + 0.2 * rng.random::<f64>());
            let [near, far] = spec.distance;
            let distance = near + (far - near) * rng.random::<f64>();
            LookAt {
                distance,
                azimuth_deg: azimuth,
                elevation_deg: 90.0 - tilt,
                roll_deg: roll,
                board_in_image_deg: [0.0, 0.0],
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn views_stay_inside_the_spec() {
        let spec = GenerateSpec {
            count: 40,
            distance: [0.45, 0.7],
            max_tilt_deg: 35.0,
            max_roll_deg: 30.0,
            seed: 3,
            image_spread: None,
        };
        spec.validate().unwrap();
        let views = generate(&spec);
        assert_eq!(views.len(), 40);
        for v in &views {
            v.validate().unwrap();
            assert!(v.distance >= 0.45 && v.distance <= 0.7);
            assert!(90.0 - v.elevation_deg <= 35.0 + 1e-9);
            assert!(v.roll_deg.abs() <= 30.0 + 1e-9);
        }
        // Spread: both large and small tilts, both roll signs.
        assert!(views.iter().any(|v| 90.0 - v.elevation_deg > 28.0));
        assert!(views.iter().any(|v| 90.0 - v.elevation_deg < 8.0));
        assert!(
            views.iter().any(|v| v.roll_deg > 10.0) && views.iter().any(|v| v.roll_deg < -10.0)
        );
    }

    #[test]
    fn bad_specs_are_refused() {
        let good = GenerateSpec {
            count: 10,
            distance: [0.4, 0.6],
            max_tilt_deg: 30.0,
            max_roll_deg: 20.0,
            seed: 0,
            image_spread: None,
        };
        good.validate().unwrap();
        let field = |spec: GenerateSpec| spec.validate().unwrap_err().field;
        assert_eq!(field(GenerateSpec { count: 2, ..good }), "count");
        let huge = GenerateSpec {
            count: 100_000_000,
            ..good
        }
        .validate()
        .unwrap_err();
        assert_eq!(huge.field, "count");
        assert_eq!(huge.found, "100000000");
        assert!(huge.expected.contains("[3, 1000]"), "{huge}");
        let far = GenerateSpec {
            distance: [0.4, 1e300],
            ..good
        }
        .validate()
        .unwrap_err();
        assert_eq!(far.found, "[0.4, 1e300]", "{far}");
        assert_eq!(
            field(GenerateSpec {
                distance: [0.6, 0.4],
                ..good
            }),
            "distance"
        );
        assert_eq!(
            field(GenerateSpec {
                max_tilt_deg: 90.0,
                ..good
            }),
            "max_tilt_deg"
        );
    }
}
