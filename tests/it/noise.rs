//! Issue #19, items 1–2: the pose-space default estimates the board-pose noise from the data
//! and is robust to gross outliers. Seeded synthetic eye-in-hand cells (N = 20, ≥ 12 seeds per
//! case) compare the default against the maximum-likelihood answer computed with the true noise
//! model (and, with outliers, on the inliers alone).

use crate::util::median;
use handeye_core::geometry::Pose;
use handeye_core::notice::{NoticeKind, Severity};
use handeye_core::setup::{predict, PosePair, Setup};
use handeye_solve::verdict::{self, Accuracy, Basis};
use handeye_solve::{
    self as solve, Calibration, EstimateNoise, NoiseModel, NoiseSource, SolveOptions,
};
use nalgebra::{Translation3, UnitQuaternion, Vector3};
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};
use rand_distr::{Distribution, Normal, UnitSphere};

const SAMPLES: usize = 20;
const SEEDS: u64 = 16;

fn random_axis(rng: &mut StdRng) -> Vector3<f64> {
    let v: [f64; 3] = UnitSphere.sample(rng);
    Vector3::from(v)
}

fn random_pose(rng: &mut StdRng, max_angle: f64, max_t: f64) -> Pose {
    let axis = random_axis(rng);
    let angle = rng.random_range(0.0..max_angle);
    let t = Vector3::from_fn(|_, _| rng.random_range(-max_t..max_t));
    Pose::from_parts(
        Translation3::from(t),
        UnitQuaternion::from_scaled_axis(axis * angle),
    )
}

struct Cell {
    camera_mount: Pose,
    target_mount: Pose,
    pairs: Vec<PosePair>,
}

/// Random truth, `SAMPLES` robot poses tilted 15–40° about axes near x, y, z in turn.
fn cell(seed: u64) -> Cell {
    let mut rng = StdRng::seed_from_u64(seed);
    let camera_mount = random_pose(&mut rng, std::f64::consts::PI, 0.2);
    let target_mount = random_pose(&mut rng, std::f64::consts::PI, 0.8);
    let home = random_pose(&mut rng, std::f64::consts::PI, 0.4);
    let pairs = (0..SAMPLES)
        .map(|k| {
            let mut axis = Vector3::zeros();
            axis[k % 3] = 1.0;
            let axis = (axis + 0.5 * random_axis(&mut rng)).normalize();
            let angle = rng.random_range(15f64.to_radians()..40f64.to_radians());
            let t = Vector3::from_fn(|_, _| rng.random_range(-0.15..0.15));
            let tilt = Pose::from_parts(
                Translation3::from(t),
                UnitQuaternion::from_scaled_axis(axis * angle),
            );
            let base_from_flange = home * tilt;
            let camera_from_target = predict(
                Setup::EyeInHand,
                &camera_mount,
                &target_mount,
                &base_from_flange,
            );
            PosePair::new(base_from_flange, camera_from_target)
        })
        .collect();
    Cell {
        camera_mount,
        target_mount,
        pairs,
    }
}

/// Board-pose noise: per-axis rotation (rad, camera frame) and translation (m).
#[derive(Clone, Copy, Debug)]
enum Noise {
    Gaussian {
        rotation: f64,
        translation: f64,
    },
    /// Uniform in ±bound per axis (the paper's experiment).
    Uniform {
        rotation: f64,
        translation: f64,
    },
}

impl Noise {
    fn gaussian(deg: f64, mm: f64) -> Noise {
        Noise::Gaussian {
            rotation: deg.to_radians(),
            translation: mm * 1e-3,
        }
    }

    /// The true per-axis standard deviations.
    fn model(self) -> NoiseModel {
        match self {
            Noise::Gaussian {
                rotation,
                translation,
            } => NoiseModel {
                rotation_sigma_rad: rotation,
                translation_sigma_m: translation,
            },
            Noise::Uniform {
                rotation,
                translation,
            } => NoiseModel {
                rotation_sigma_rad: rotation / 3f64.sqrt(),
                translation_sigma_m: translation / 3f64.sqrt(),
            },
        }
    }

    fn apply(self, pairs: &mut [PosePair], seed: u64) {
        let mut rng = StdRng::seed_from_u64(seed ^ 0x5eed);
        for p in pairs {
            let (dr, dt) = match self {
                Noise::Gaussian {
                    rotation,
                    translation,
                } => {
                    let (nr, nt) = (
                        Normal::new(0.0, rotation).unwrap(),
                        Normal::new(0.0, translation).unwrap(),
                    );
                    (
                        Vector3::from_fn(|_, _| nr.sample(&mut rng)),
                        Vector3::from_fn(|_, _| nt.sample(&mut rng)),
                    )
                }
                Noise::Uniform {
                    rotation,
                    translation,
                } => (
                    Vector3::from_fn(|_, _| rng.random_range(-rotation..rotation)),
                    Vector3::from_fn(|_, _| rng.random_range(-translation..translation)),
                ),
            };
            let a = p.camera_from_target;
            p.camera_from_target = Pose::from_parts(
                Translation3::from(a.translation.vector + dt),
                UnitQuaternion::from_scaled_axis(dr) * a.rotation,
            );
        }
    }
}

/// Plants gross outliers on `indices`: 10–30° and 30–80 mm off, random directions.
fn plant_outliers(pairs: &mut [PosePair], indices: &[usize], seed: u64) {
    let mut rng = StdRng::seed_from_u64(seed ^ 0xbad);
    for &i in indices {
        let angle = rng.random_range(10f64.to_radians()..30f64.to_radians());
        let shift = rng.random_range(0.03..0.08);
        let a = pairs[i].camera_from_target;
        pairs[i].camera_from_target = Pose::from_parts(
            Translation3::from(a.translation.vector + random_axis(&mut rng) * shift),
            UnitQuaternion::from_scaled_axis(random_axis(&mut rng) * angle) * a.rotation,
        );
    }
}

/// The maximum-likelihood answer with the true noise model, every given sample kept.
fn ml_options(noise: NoiseModel) -> SolveOptions {
    SolveOptions {
        noise,
        estimate_noise: EstimateNoise::NONE,
        drop_outliers: false,
        ..SolveOptions::default()
    }
}

/// Errors of (camera mount rotation rad, translation m, target mount rotation, translation).
fn errors(c: &Calibration, cell: &Cell) -> [f64; 4] {
    let e = |found: &Pose, truth: &Pose| {
        (
            found.rotation.angle_to(&truth.rotation),
            (found.translation.vector - truth.translation.vector).norm(),
        )
    };
    let (a, b) = e(&c.camera_mount, &cell.camera_mount);
    let (d, f) = e(&c.target_mount, &cell.target_mount);
    [a, b, d, f]
}

const FIGURES: [&str; 4] = [
    "T_flange_camera rotation",
    "T_flange_camera translation",
    "T_base_target rotation",
    "T_base_target translation",
];

/// Adds `found`'s errors against `cell`'s truth to each figure's list.
fn push_errors(lists: &mut [Vec<f64>], found: &Calibration, cell: &Cell) {
    for (list, e) in lists.iter_mut().zip(errors(found, cell)) {
        list.push(e);
    }
}

/// The median over the seeds of each figure's errors.
fn medians(errors: &[Vec<f64>]) -> [f64; 4] {
    std::array::from_fn(|k| median(errors[k].clone()))
}

/// Median errors of the default and of the reference over the seeds, per figure.
struct Comparison {
    default: [f64; 4],
    reference: [f64; 4],
    /// Another answer for the note (name, median errors): the previous default.
    fixed: Option<(&'static str, [f64; 4])>,
}

impl Comparison {
    fn ratios(&self) -> [f64; 4] {
        std::array::from_fn(|k| self.default[k] / self.reference[k])
    }

    fn assert_within(&self, label: &str, margin: f64) {
        let ratios = self.ratios();
        for k in 0..4 {
            let fixed = self
                .fixed
                .map(|(name, f)| format!(", {name} {:.3}", f[k] / self.reference[k]))
                .unwrap_or_default();
            eprintln!(
                "{label}: {}: default {:.4e}, reference {:.4e}, ratio {:.3}{fixed}",
                FIGURES[k], self.default[k], self.reference[k], ratios[k]
            );
        }
        for k in 0..4 {
            assert!(
                ratios[k] <= margin,
                "{label}: {} median error {:.3}x the reference (allowed {margin}x)",
                FIGURES[k],
                ratios[k]
            );
        }
    }
}

/// Default vs ML-with-the-true-noise on clean data; asserts no sample is dropped and the
/// answer is exactly the plain fit of every sample.
fn compare_clean(noise: Noise, first_seed: u64) -> Comparison {
    let mut default = vec![Vec::new(); 4];
    let mut reference = vec![Vec::new(); 4];
    let mut fixed = vec![Vec::new(); 4];
    for seed in first_seed..first_seed + SEEDS {
        let mut c = cell(seed);
        noise.apply(&mut c.pairs, seed);
        let found = solve::solve(Setup::EyeInHand, &c.pairs, &SolveOptions::default()).unwrap();
        assert!(
            found.dropped.is_empty(),
            "seed {seed}: a clean set dropped {:?}",
            found.dropped
        );
        let plain = SolveOptions {
            drop_outliers: false,
            ..SolveOptions::default()
        };
        let every = solve::solve(Setup::EyeInHand, &c.pairs, &plain).unwrap();
        assert_eq!(
            (found.camera_mount, found.target_mount),
            (every.camera_mount, every.target_mount),
            "seed {seed}: the robust default must be the plain fit on clean data"
        );
        let ml = solve::solve(Setup::EyeInHand, &c.pairs, &ml_options(noise.model())).unwrap();
        let old = solve::solve(
            Setup::EyeInHand,
            &c.pairs,
            &ml_options(NoiseModel::default()),
        )
        .unwrap();
        push_errors(&mut default, &found, &c);
        push_errors(&mut reference, &ml, &c);
        push_errors(&mut fixed, &old, &c);
    }
    Comparison {
        default: medians(&default),
        reference: medians(&reference),
        fixed: Some(("fixed 0.2°/1 mm", medians(&fixed))),
    }
}

#[test]
fn estimated_noise_matches_ml_with_the_true_noise_1deg_half_mm() {
    compare_clean(Noise::gaussian(1.0, 0.5), 100).assert_within("1°/0.5 mm", 1.10);
}

#[test]
fn estimated_noise_matches_ml_with_the_true_noise_005deg_3mm() {
    let comparison = compare_clean(Noise::gaussian(0.05, 3.0), 200);
    comparison.assert_within("0.05°/3 mm", 1.10);
    // The margin tells: the previous fixed-noise default fails it here (issue #19: 4.9×).
    let (_, fixed) = comparison.fixed.unwrap();
    assert!(fixed[0] / comparison.reference[0] > 1.10);
}

#[test]
fn estimated_noise_matches_ml_with_the_true_noise_paper_uniform() {
    let noise = Noise::Uniform {
        rotation: 1f64.to_radians(),
        translation: 2e-3,
    };
    compare_clean(noise, 300).assert_within("uniform 1°/2 mm", 1.10);
}

#[test]
fn gross_outliers_are_left_out_named_and_the_answer_matches_ml_on_the_inliers() {
    let noise = Noise::gaussian(0.2, 1.0);
    let mut default = vec![Vec::new(); 4];
    let mut reference = vec![Vec::new(); 4];
    let mut kept = vec![Vec::new(); 4];
    for seed in 400..400 + SEEDS {
        let mut c = cell(seed);
        noise.apply(&mut c.pairs, seed);
        // 10 %: two of twenty, at seed-dependent places.
        let first = (seed as usize * 7) % SAMPLES;
        let mut planted = vec![first, (first + 1 + seed as usize % 9) % SAMPLES];
        planted.sort_unstable();
        plant_outliers(&mut c.pairs, &planted, seed);
        let found = solve::solve(Setup::EyeInHand, &c.pairs, &SolveOptions::default()).unwrap();
        assert_eq!(found.dropped, planted, "seed {seed}");
        for &i in &planted {
            let named = found.notices.iter().any(|w| {
                w.kind == NoticeKind::DroppedOutliers
                    && w.severity == Severity::Warning
                    && w.message.contains(&format!("sample {i} "))
                    && w.message.contains("sigmas")
            });
            assert!(
                named,
                "seed {seed}: sample {i} not named: {:?}",
                found.notices
            );
        }
        let inliers: Vec<PosePair> = (0..SAMPLES)
            .filter(|i| !planted.contains(i))
            .map(|i| c.pairs[i].clone())
            .collect();
        let ml = solve::solve(Setup::EyeInHand, &inliers, &ml_options(noise.model())).unwrap();
        let every = SolveOptions {
            drop_outliers: false,
            ..SolveOptions::default()
        };
        let pulled = solve::solve(Setup::EyeInHand, &c.pairs, &every).unwrap();
        push_errors(&mut kept, &pulled, &c);
        push_errors(&mut default, &found, &c);
        push_errors(&mut reference, &ml, &c);
    }
    Comparison {
        default: medians(&default),
        reference: medians(&reference),
        // Fitting every sample (the previous default): pulled far off, for the note.
        fixed: Some(("every sample kept", medians(&kept))),
    }
    .assert_within("10 % gross outliers", 1.25);
}

#[test]
fn estimated_noise_is_reported_and_close_to_the_truth() {
    let noise = Noise::gaussian(1.0, 0.5);
    let mut c = cell(7);
    noise.apply(&mut c.pairs, 7);
    let found = solve::solve(Setup::EyeInHand, &c.pairs, &SolveOptions::default()).unwrap();
    let estimate = found.noise.expect("pose-space answers report their noise");
    assert_eq!(estimate.rotation, NoiseSource::Estimated);
    assert_eq!(estimate.translation, NoiseSource::Estimated);
    // 60 residual rows per group: the estimate is good to about ±20 %.
    assert!(
        (estimate.rotation_sigma_deg / 1.0 - 1.0).abs() < 0.3,
        "{estimate:?}"
    );
    assert!(
        (estimate.translation_sigma_mm / 0.5 - 1.0).abs() < 0.3,
        "{estimate:?}"
    );
    assert!(found
        .notices
        .iter()
        .any(|w| w.kind == NoticeKind::NoiseEstimate && w.severity == Severity::Info));
    // χ²/dof at the estimated noise is 1 by construction.
    let factor = found.uncertainty.as_ref().unwrap().variance_factor;
    assert!((factor - 1.0).abs() < 0.05, "variance factor {factor}");
}

#[test]
fn explicit_sigmas_win_over_the_estimate() {
    let mut c = cell(8);
    Noise::gaussian(1.0, 0.5).apply(&mut c.pairs, 8);
    let given = NoiseModel {
        rotation_sigma_rad: 0.3f64.to_radians(),
        translation_sigma_m: 2e-3,
    };
    let options = SolveOptions {
        noise: given,
        estimate_noise: EstimateNoise {
            rotation: false,
            translation: true,
        },
        ..SolveOptions::default()
    };
    let found = solve::solve(Setup::EyeInHand, &c.pairs, &options).unwrap();
    let used = found.noise.unwrap();
    assert_eq!(used.rotation, NoiseSource::Given);
    assert!((used.rotation_sigma_deg - 0.3).abs() < 1e-12, "{used:?}");
    assert_eq!(used.translation, NoiseSource::Estimated);
    // Estimated from the data (true 0.5 mm), not left at the given 2 mm.
    assert!(
        (used.translation_sigma_mm / 0.5 - 1.0).abs() < 0.3,
        "{used:?}"
    );
}

#[test]
fn too_few_samples_keep_the_configured_noise() {
    let mut c = cell(9);
    Noise::gaussian(1.0, 0.5).apply(&mut c.pairs, 9);
    c.pairs.truncate(6);
    let found = solve::solve(Setup::EyeInHand, &c.pairs, &SolveOptions::default()).unwrap();
    let used = found.noise.unwrap();
    assert_eq!(used.rotation, NoiseSource::TooFewSamples);
    assert!((used.rotation_sigma_deg - 0.2).abs() < 1e-12, "{used:?}");
}

/// Flange-pose noise of the robot: per-axis rotation (rad) and translation (m) in the flange
/// frame, `T_base_flange ← T_base_flange · exp(δ)`.
fn add_robot_noise(pairs: &mut [PosePair], rotation: f64, translation: f64, seed: u64) {
    let mut rng = StdRng::seed_from_u64(seed ^ 0x0b07);
    let (nr, nt) = (
        Normal::new(0.0, rotation).unwrap(),
        Normal::new(0.0, translation).unwrap(),
    );
    for p in pairs {
        let dr = Vector3::from_fn(|_, _| nr.sample(&mut rng));
        let dt = Vector3::from_fn(|_, _| nt.sample(&mut rng));
        p.base_from_flange *=
            Pose::from_parts(Translation3::from(dt), UnitQuaternion::from_scaled_axis(dr));
    }
}

/// One noise case of the Monte Carlo: board-pose noise, optional robot noise (deg, mm).
struct McCase {
    label: &'static str,
    board: Noise,
    robot: Option<(f64, f64)>,
}

/// Per unknown (camera mount, target mount) and kind (rotation, translation): the true error
/// against the reported covariance over many seeded sets.
#[derive(Default, Clone)]
struct Honesty {
    /// Σ squared total error and Σ reported total variance (the RMS / RMS figure).
    error2: f64,
    sigma2: f64,
    /// Per-axis z-scores within 1 and 3 sigma, and their count.
    within_1: usize,
    within_3: usize,
    axes: usize,
}

impl Honesty {
    fn ratio(&self) -> f64 {
        (self.error2 / self.sigma2).sqrt()
    }
    fn p1(&self) -> f64 {
        self.within_1 as f64 / self.axes as f64
    }
    fn p3(&self) -> f64 {
        self.within_3 as f64 / self.axes as f64
    }
}

/// Runs `sets` seeded sets of `case` with the default solve; returns the four figures.
fn honesty(case: &McCase, first_seed: u64, sets: u64) -> [Honesty; 4] {
    let mut out: [Honesty; 4] = Default::default();
    for seed in first_seed..first_seed + sets {
        let mut c = cell(seed);
        case.board.apply(&mut c.pairs, seed);
        if let Some((deg, mm)) = case.robot {
            add_robot_noise(&mut c.pairs, deg.to_radians(), mm * 1e-3, seed);
        }
        let found = solve::solve(Setup::EyeInHand, &c.pairs, &SolveOptions::default()).unwrap();
        let u = found.uncertainty.as_ref().unwrap();
        for (k, (estimate, truth)) in [
            (found.camera_mount, c.camera_mount),
            (found.target_mount, c.target_mount),
        ]
        .iter()
        .enumerate()
        {
            // The covariance's perturbation: R_est = exp(δθ)·R_true, t_est = t_true + δt.
            let d_theta =
                handeye_core::geometry::rotvec(&(estimate.rotation * truth.rotation.inverse()));
            let d_t = estimate.translation.vector - truth.translation.vector;
            for (kind, error) in [d_theta, d_t].into_iter().enumerate() {
                let h = &mut out[2 * k + kind];
                for axis in 0..3 {
                    let r = 6 * k + 3 * kind + axis;
                    let variance = u.covariance[(r, r)];
                    let z = (error[axis] / variance.sqrt()).abs();
                    h.within_1 += usize::from(z <= 1.0);
                    h.within_3 += usize::from(z <= 3.0);
                    h.axes += 1;
                    h.error2 += error[axis] * error[axis];
                    h.sigma2 += variance;
                }
            }
        }
    }
    out
}

fn mc_cases() -> [McCase; 5] {
    [
        McCase {
            label: "0.2°/1 mm",
            board: Noise::gaussian(0.2, 1.0),
            robot: None,
        },
        McCase {
            label: "1°/0.5 mm",
            board: Noise::gaussian(1.0, 0.5),
            robot: None,
        },
        McCase {
            label: "0.05°/3 mm",
            board: Noise::gaussian(0.05, 3.0),
            robot: None,
        },
        McCase {
            label: "uniform 1°/2 mm",
            board: Noise::Uniform {
                rotation: 1f64.to_radians(),
                translation: 2e-3,
            },
            robot: None,
        },
        McCase {
            label: "0.2°/1 mm + robot 0.05°/0.2 mm",
            board: Noise::gaussian(0.2, 1.0),
            robot: Some((0.05, 0.2)),
        },
    ]
}

/// Issue #19: the reported 1-sigma describes the true error under every noise case: per
/// unknown RMS error / RMS 1-sigma within 0.8–1.25, and per-axis coverage 68 ± 5 % within
/// 1 sigma, ≥ 98.5 % within 3 sigma.
///
/// 300 sets per case (900 axis samples per figure; the binomial standard error of a 68 % rate
/// is 1.6 %, more with the axes of one set correlated): about a second in CI, so always on.
/// `HANDEYE_LONG_MC=1` runs 2000 sets per case with the same margins, for the figures.
///
/// The earlier check of this (60 sets per case, RMS ratio only) saw 0.78 for the
/// T_flange_camera translation at 1°/0.5 mm. That was its seeds, not the estimator: the same
/// case over the next five blocks of 60 seeds gives 0.98, 1.03, 1.06, 1.01 and 0.98 (1 sigma
/// 65–71 %), and 0.98 over the 300 sets here; 60 sets are too few for a ±20 % margin on the
/// worst of 16 figures.
#[test]
fn reported_sigma_covers_the_true_error_per_axis_under_every_noise_case() {
    let long = std::env::var("HANDEYE_LONG_MC").is_ok_and(|v| v == "1");
    let sets = if long { 2000 } else { 300 };
    let mut outside = Vec::new();
    for (k, case) in mc_cases().iter().enumerate() {
        let figures = honesty(case, 5000 + 10_000 * k as u64, sets);
        for (name, h) in FIGURES.iter().zip(&figures) {
            eprintln!(
                "{}: {name}: RMS error / RMS 1-sigma {:.3}, within 1 sigma {:.1} %, within 3 sigma {:.1} % ({} axis samples)",
                case.label,
                h.ratio(),
                100.0 * h.p1(),
                100.0 * h.p3(),
                h.axes
            );
            if !(0.8..=1.25).contains(&h.ratio()) || (h.p1() - 0.683).abs() > 0.05 || h.p3() < 0.985
            {
                outside.push(format!(
                    "{}: {name}: ratio {:.3}, 1 sigma {:.1} %, 3 sigma {:.1} %",
                    case.label,
                    h.ratio(),
                    100.0 * h.p1(),
                    100.0 * h.p3()
                ));
            }
        }
    }
    assert!(
        outside.is_empty(),
        "outside ratio 0.8–1.25, 1 sigma 68.3 ± 5 %, 3 sigma ≥ 98.5 %: {outside:?}"
    );
}

#[test]
fn result_file_holds_the_noise_used_and_reads_it_back() {
    let mut c = cell(11);
    Noise::gaussian(0.5, 2.0).apply(&mut c.pairs, 11);
    let found = solve::solve(Setup::EyeInHand, &c.pairs, &SolveOptions::default()).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("result.yaml");
    handeye_records::result::ResultFile::from_calibration(&found, &c.pairs)
        .save(&path)
        .unwrap();
    let text = std::fs::read_to_string(&path).unwrap();
    assert!(
        text.contains("noise:") && text.contains("rotation: estimated"),
        "{text}"
    );
    let back = handeye_records::result::ResultFile::load(&path)
        .unwrap()
        .to_calibration(&path)
        .unwrap();
    assert_eq!(back.noise, found.noise);
}

/// Views of mixed precision, drawn at random from the class a real session holds (a far board,
/// a board at the image's edge, a few tags: each view's board pose 1–8 times noisier than the
/// typical one, in 10–40 % of the views), each sample carrying its view's 1-sigma as the pose
/// estimate gives it (mis-estimated by up to ±25 %, as one frame's residuals estimate it):
/// - no clean view is dropped as an outlier, and at most one in a hundred is flagged;
/// - the answer is within 1.25× the maximum-likelihood answer that knows every view's true
///   noise (median errors over the sets);
/// - a recorded robot pose that is wrong (1.5–3°, 10–20 mm), at a view of any precision, is
///   still dropped and named.
///
/// The same sets solved without the views' sigmas (every view taken as equally good, as before
/// samples recorded them) drop clean views: the class is one the old rule gets wrong.
#[test]
fn views_of_mixed_precision_are_weighted_not_dropped_and_wrong_robot_poses_still_are() {
    use handeye_core::setup::ViewSigma;
    let base = Noise::gaussian(0.02, 0.1);
    let NoiseModel {
        rotation_sigma_rad: base_rotation,
        translation_sigma_m: base_translation,
    } = base.model();
    let (mut flagged, mut views, mut unweighted_dropped) = (0, 0, 0);
    let (mut residuals_blamed, mut alike_blamed) = (0, 0);
    let mut default = vec![Vec::new(); 4];
    let mut reference = vec![Vec::new(); 4];
    let mut every_view_alike = vec![Vec::new(); 4];
    for seed in 900..900 + SEEDS {
        let mut rng = StdRng::seed_from_u64(seed ^ 0x71e3);
        let mut c = cell(seed);
        let noisy_share = rng.random_range(0.1..0.4);
        let factors: Vec<f64> = (0..SAMPLES)
            .map(|_| {
                if rng.random_bool(noisy_share) {
                    rng.random_range(0f64..8f64.ln()).exp()
                } else {
                    1.0
                }
            })
            .collect();
        for (i, (pair, &factor)) in c.pairs.iter_mut().zip(&factors).enumerate() {
            Noise::gaussian(0.02 * factor, 0.1 * factor)
                .apply(std::slice::from_mut(pair), seed * 100 + i as u64);
            let misestimate = rng.random_range(0.75..1.25);
            // The pose estimate's sigma is the root of its covariance's trace: √3 × per axis.
            pair.view_sigma = Some(ViewSigma {
                rotation_deg: (base_rotation * factor * misestimate * 3f64.sqrt()).to_degrees(),
                translation_mm: base_translation * factor * misestimate * 3f64.sqrt() * 1e3,
            });
        }
        let found = solve::solve(Setup::EyeInHand, &c.pairs, &SolveOptions::default()).unwrap();
        assert!(
            found.dropped.is_empty(),
            "seed {seed}: clean views dropped: {:?} (noise factors {factors:.1?})",
            found.dropped
        );
        flagged += found.outliers.len();
        views += SAMPLES;
        // Maximum likelihood with every view's true noise.
        let truth_weighted: Vec<PosePair> = c
            .pairs
            .iter()
            .zip(&factors)
            .map(|(p, f)| PosePair {
                weight: f.powi(-2),
                view_sigma: None,
                ..p.clone()
            })
            .collect();
        let ml =
            solve::solve(Setup::EyeInHand, &truth_weighted, &ml_options(base.model())).unwrap();
        push_errors(&mut default, &found, &c);
        push_errors(&mut reference, &ml, &c);
        // The old form, one key away (config `solver: {weigh_views: false}`).
        let every_alike = SolveOptions {
            weigh_views: false,
            ..SolveOptions::default()
        };
        let alike = solve::solve(Setup::EyeInHand, &c.pairs, &every_alike).unwrap();
        unweighted_dropped += alike.dropped.len();
        push_errors(&mut every_view_alike, &alike, &c);
        // Told the typical view's noise, the verdict finds the residuals as expected: the far
        // views' larger residuals are their own noise (each at its weight), not "robot poses
        // and frames not synchronised".
        let given = SolveOptions {
            noise: base.model(),
            estimate_noise: EstimateNoise::NONE,
            ..SolveOptions::default()
        };
        let answer = solve::solve(Setup::EyeInHand, &c.pairs, &given).unwrap();
        let verdict = verdict::assess_solved(&answer, &c.pairs, &given, Accuracy::default());
        residuals_blamed += usize::from(
            std::iter::once(verdict.basis)
                .chain(verdict.also.iter().map(|f| f.basis))
                .any(|b| b == Basis::Residuals),
        );
        // What the rule read before: every view's residual alike against the typical view's
        // noise (norms of 3-axis noise: √3 σ).
        let expected = |sigma: f64| verdict::RESIDUAL_FACTOR * sigma * 3f64.sqrt();
        alike_blamed += usize::from(
            answer.residuals.rotation_rms_deg > expected(base_rotation.to_degrees())
                || answer.residuals.translation_rms_mm > expected(base_translation * 1e3),
        );

        // A wrong robot pose at a random view, whatever its precision.
        let wrong = rng.random_range(0..SAMPLES);
        let angle = rng.random_range(1.5f64.to_radians()..3f64.to_radians());
        let shift = rng.random_range(0.01..0.02);
        let robot = c.pairs[wrong].base_from_flange;
        c.pairs[wrong].base_from_flange = Pose::from_parts(
            Translation3::from(robot.translation.vector + random_axis(&mut rng) * shift),
            UnitQuaternion::from_scaled_axis(random_axis(&mut rng) * angle) * robot.rotation,
        );
        let found = solve::solve(Setup::EyeInHand, &c.pairs, &SolveOptions::default()).unwrap();
        assert_eq!(
            found.dropped,
            vec![wrong],
            "seed {seed}: the wrong robot pose at a view {:.1}× the typical noise",
            factors[wrong]
        );
        assert!(
            found
                .notices
                .iter()
                .any(|n| n.kind == NoticeKind::DroppedOutliers
                    && n.message.contains(&format!("sample {wrong} "))),
            "seed {seed}: {:?}",
            found.notices
        );
    }
    eprintln!(
        "mixed precision: {flagged} of {views} clean views flagged; without the views' sigmas {unweighted_dropped} clean views dropped; told the typical view's noise, the verdict blames the residuals in {residuals_blamed} of {SEEDS} sets (every view's residual alike: {alike_blamed})"
    );
    assert_eq!(residuals_blamed, 0, "a clean set's residuals blamed");
    assert!(
        alike_blamed > 0,
        "no set whose residuals the old rule blames: the test lost its class"
    );
    assert!(
        flagged * 100 <= views,
        "{flagged} of {views} clean views flagged"
    );
    assert!(
        unweighted_dropped > 0,
        "the sets no longer hold views the unweighted rule drops: the test lost its class"
    );
    Comparison {
        default: medians(&default),
        reference: medians(&reference),
        fixed: Some(("every view alike", medians(&every_view_alike))),
    }
    .assert_within("mixed precision", 1.25);
}
