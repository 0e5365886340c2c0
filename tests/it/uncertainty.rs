//! Is the solver's 1-sigma honest? A Monte Carlo check over many simulated sessions in pose
//! space: draw a true cell (both unknowns), robot poses that look at the target, and noisy
//! `T_camera_target` with the noise the solver is told about; solve with the default method and
//! compare the true error of each unknown with its reported covariance.
//!
//! The check is per axis (rotation about, and translation along, each axis of frame `a` of
//! `T_a_b`): the true error component over its reported sigma is a standard normal if the
//! covariance is right, so it falls within 1 sigma 68.3 % and within 3 sigma 99.73 % of the time.

use handeye_core::geometry::{rotvec, Pose};
use handeye_core::setup::{PosePair, Setup};
use handeye_solve::{self as solve, NoiseModel, SolveOptions};
use nalgebra::{Translation3, UnitQuaternion, Vector3};
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};
use rand_distr::{Distribution, Normal};

fn random_pose(rng: &mut StdRng, translation_m: f64, angle_rad: f64) -> Pose {
    let t = Vector3::from_fn(|_, _| rng.random_range(-1.0..1.0) * translation_m);
    let axis = Vector3::from_fn(|_, _| rng.random_range(-1.0..1.0f64));
    let axis = if axis.norm() < 1e-3 {
        Vector3::z()
    } else {
        axis.normalize()
    };
    let angle = rng.random_range(-1.0..1.0) * angle_rad;
    Pose::from_parts(
        Translation3::from(t),
        UnitQuaternion::from_scaled_axis(axis * angle),
    )
}

/// Eye-in-hand session: the camera views the board from 0.4–0.7 m, tilted up to 35°.
fn simulate(
    rng: &mut StdRng,
    setup: Setup,
    poses: usize,
    noise: &NoiseModel,
) -> (Pose, Pose, Vec<PosePair>) {
    let camera_mount = random_pose(rng, 0.1, std::f64::consts::PI);
    let target_mount = match setup {
        Setup::EyeInHand => {
            let mut p = random_pose(rng, 0.2, std::f64::consts::PI);
            p.translation.vector += Vector3::new(0.6, 0.0, 0.0);
            p
        }
        Setup::EyeToHand => random_pose(rng, 0.05, std::f64::consts::PI),
    };
    let nr = Normal::new(0.0, noise.rotation_sigma_rad).unwrap();
    let nt = Normal::new(0.0, noise.translation_sigma_m).unwrap();
    let mut pairs = Vec::new();
    for _ in 0..poses {
        // A view of the target: T_camera_target with the board in front of the camera.
        let tilt = random_pose(rng, 0.0, 35f64.to_radians());
        let distance = rng.random_range(0.4..0.7);
        let camera_from_target = Pose::from_parts(
            Translation3::new(
                rng.random_range(-0.05..0.05),
                rng.random_range(-0.05..0.05),
                distance,
            ),
            tilt.rotation * UnitQuaternion::from_euler_angles(std::f64::consts::PI, 0.0, 0.0),
        );
        let base_from_flange = match setup {
            // T_camera_target = inv(X) inv(T_base_flange) Y  =>  T_base_flange = Y inv(A) inv(X)
            Setup::EyeInHand => {
                target_mount * camera_from_target.inverse() * camera_mount.inverse()
            }
            // T_camera_target = inv(T_base_camera) T_base_flange T_flange_target
            Setup::EyeToHand => camera_mount * camera_from_target * target_mount.inverse(),
        };
        let dr = Vector3::from_fn(|_, _| nr.sample(rng));
        let dt = Vector3::from_fn(|_, _| nt.sample(rng));
        let measured = Pose::from_parts(
            Translation3::from(camera_from_target.translation.vector + dt),
            UnitQuaternion::from_scaled_axis(dr) * camera_from_target.rotation,
        );
        pairs.push(PosePair::new(base_from_flange, measured));
    }
    (camera_mount, target_mount, pairs)
}

#[derive(Default)]
struct Coverage {
    within_1: usize,
    within_3: usize,
    total: usize,
}

impl Coverage {
    fn add(&mut self, error: f64, sigma: f64) {
        let z = (error / sigma).abs();
        self.within_1 += usize::from(z <= 1.0);
        self.within_3 += usize::from(z <= 3.0);
        self.total += 1;
    }
    fn p1(&self) -> f64 {
        self.within_1 as f64 / self.total as f64
    }
    fn p3(&self) -> f64 {
        self.within_3 as f64 / self.total as f64
    }
}

/// Runs `trials` sessions and returns coverage for
/// [camera rotation, camera translation, target rotation, target translation].
fn coverage(
    setup: Setup,
    trials: usize,
    poses: usize,
    seed: u64,
    model_over_truth: f64,
) -> [Coverage; 4] {
    let mut rng = StdRng::seed_from_u64(seed);
    let noise = NoiseModel {
        rotation_sigma_rad: 0.1f64.to_radians(),
        translation_sigma_m: 0.5e-3,
    };
    let options = SolveOptions {
        noise: NoiseModel {
            rotation_sigma_rad: noise.rotation_sigma_rad * model_over_truth,
            translation_sigma_m: noise.translation_sigma_m * model_over_truth,
        },
        ..SolveOptions::default()
    };
    let mut out: [Coverage; 4] = Default::default();
    for _ in 0..trials {
        let (camera_truth, target_truth, pairs) = simulate(&mut rng, setup, poses, &noise);
        let calibration = solve::solve(setup, &pairs, &options).expect("simulated session solves");
        let u = calibration
            .uncertainty
            .expect("the refined method reports a covariance");
        for (k, (estimate, truth)) in [
            (calibration.camera_mount, camera_truth),
            (calibration.target_mount, target_truth),
        ]
        .iter()
        .enumerate()
        {
            // Same perturbation as the covariance: R_est = exp(δθ)·R_true, t_est = t_true + δt.
            let d_theta = rotvec(&(estimate.rotation * truth.rotation.inverse()));
            let d_t = estimate.translation.vector - truth.translation.vector;
            for axis in 0..3 {
                let r = 6 * k + axis;
                out[2 * k].add(d_theta[axis], u.covariance[(r, r)].sqrt());
                out[2 * k + 1].add(d_t[axis], u.covariance[(r + 3, r + 3)].sqrt());
            }
        }
    }
    out
}

/// `model_over_truth`: how much larger the solver's noise model is than the injected noise.
fn check(setup: Setup, seed: u64, model_over_truth: f64) {
    // 400 sessions × 3 axes = 1200 per quantity; the binomial standard error of a 68 % rate is
    // 1.3 % (axes of one session are correlated, so allow ±5 %); at 3 sigma expect ≥ 98.5 %.
    let results = coverage(setup, 400, 12, seed, model_over_truth);
    let (camera, target) = setup.unknown_names();
    let names = [
        format!("{camera} rotation"),
        format!("{camera} translation"),
        format!("{target} rotation"),
        format!("{target} translation"),
    ];
    for (name, c) in names.iter().zip(&results) {
        eprintln!(
            "{setup} (noise model {model_over_truth}× the truth) {name}: within 1 sigma {:.1} %, within 3 sigma {:.1} % ({} axis samples)",
            100.0 * c.p1(),
            100.0 * c.p3(),
            c.total
        );
    }
    for (name, c) in names.iter().zip(&results) {
        assert!(
            (c.p1() - 0.683).abs() < 0.05,
            "{setup} {name}: {:.1} % within 1 sigma, expected 68.3 % ± 5 %",
            100.0 * c.p1()
        );
        assert!(
            c.p3() >= 0.985,
            "{setup} {name}: {:.1} % within 3 sigma, expected ≥ 98.5 %",
            100.0 * c.p3()
        );
    }
}

#[test]
fn reported_sigma_covers_the_true_error_eye_in_hand() {
    check(Setup::EyeInHand, 7, 1.0);
}

/// The usual case on a real cell: the configured noise is pessimistic. The a-posteriori variance
/// factor must bring the sigma down to the real scatter rather than report 4× too much.
#[test]
fn reported_sigma_is_honest_with_a_pessimistic_noise_model() {
    check(Setup::EyeInHand, 13, 4.0);
}

#[test]
fn reported_sigma_covers_the_true_error_eye_to_hand() {
    check(Setup::EyeToHand, 11, 1.0);
}
