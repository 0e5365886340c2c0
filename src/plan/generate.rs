//! Generated plans: views spread over a spherical cap above the board.
//!
//! Tilts are spread area-uniformly over the cap, azimuths follow the golden angle, and the roll
//! about the optical axis alternates in sign and grows with the index, so the relative rotations
//! between any two poses point along well-spread axes: the non-coaxial motion the solver needs.
//! A seeded jitter keeps the views off a too-regular lattice.

use rand::{Rng, SeedableRng};
use serde::{Deserialize, Serialize};

use super::LookAt;

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
}

fn default_max_tilt_deg() -> f64 {
    35.0
}
fn default_max_roll_deg() -> f64 {
    30.0
}

impl GenerateSpec {
    /// Checks the numbers describe a plan one can generate.
    pub fn validate(&self) -> Result<(), String> {
        if self.count < 3 {
            return Err(format!(
                "count: at least 3 views are needed, got {}",
                self.count
            ));
        }
        let [near, far] = self.distance;
        if !(near.is_finite() && far.is_finite() && near > 0.0 && far >= near) {
            return Err(format!(
                "distance: expected [near, far] in metres with 0 < near <= far, got [{near}, {far}]"
            ));
        }
        if !(self.max_tilt_deg > 0.0 && self.max_tilt_deg < 80.0) {
            return Err(format!(
                "max_tilt_deg: expected a value in (0, 80), got {}",
                self.max_tilt_deg
            ));
        }
        if !(self.max_roll_deg >= 0.0 && self.max_roll_deg <= 180.0) {
            return Err(format!(
                "max_roll_deg: expected a value in [0, 180], got {}",
                self.max_roll_deg
            ));
        }
        Ok(())
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
        };
        assert!(GenerateSpec { count: 2, ..good }
            .validate()
            .unwrap_err()
            .contains("count"));
        assert!(GenerateSpec {
            distance: [0.6, 0.4],
            ..good
        }
        .validate()
        .unwrap_err()
        .contains("distance"));
        assert!(GenerateSpec {
            max_tilt_deg: 90.0,
            ..good
        }
        .validate()
        .unwrap_err()
        .contains("max_tilt_deg"));
    }
}
