//! Speed of the UR kinematics that plan checking and the simulated arm call per pose:
//! forward kinematics, all inverse solutions, and the nearest solution to a seed; the inverse of
//! a calibrated model too (`solver.arm_model`: closed form, then Newton steps). Medians of one
//! release run: forward 0.29 µs, inverse (all 8) 4.9 µs, calibrated inverse 101 µs (eight
//! branches of two or three Newton steps, each with a six-column Jacobian): 3 ms for a 30-pose
//! plan check.
//!
//! And of the arm fit (issue #41, `handeye_solve::kinematics::fit_arm`: the two transforms with
//! the joint zero offsets, or with every DH link parameter, the noise re-estimated with them)
//! at N = 20 / 50 / 200 samples of an eye-in-hand UR10e cell (joints drawn in ±1.5 rad, offsets
//! of 0.03°, the rendered cell's board noise and the arm's repeatability), started from the
//! pose-space answer without the arm's model (computed outside the timing, as `solve_with_arm`
//! has it). Medians of one release run (2 shared cores, other builds running; 10 samples each):
//! joint offsets 1.68 / 3.80 / 11.9 ms, dh 6.21 / 13.6 / 37.7 ms.

use std::hint::black_box;

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion};
use nalgebra::Vector3;
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};
use rand_distr::{Distribution, Normal};

use handeye_core::geometry::pose_from_rotvec;
use handeye_core::setup::{PosePair, Setup};
use handeye_robot::arm_errors::{ArmErrorSigmas, ArmErrors};
use handeye_robot::kinematics::UrModel;
use handeye_robot::Joints;
use handeye_solve::kinematics::{fit_arm, ArmModel, ArmRefit, ArmSample, DhChain};
use handeye_solve::SolveOptions;

fn kinematics(c: &mut Criterion) {
    let model = UrModel::ur5e();
    let q = Joints::from([0.3, -1.2, 1.4, -0.8, 1.1, 0.4]);
    let pose = model.forward(&q);
    c.bench_function("ur5e forward", |b| b.iter(|| model.forward(black_box(&q))));
    c.bench_function("ur5e inverse (all 8)", |b| {
        b.iter(|| model.inverse(black_box(&pose)))
    });
    c.bench_function("ur5e inverse_nearest", |b| {
        b.iter(|| model.inverse_nearest(black_box(&pose), black_box(&q)))
    });
    // A calibrated model (`solver.arm_model`: joint offsets and link corrections): the closed
    // form of its structure finished by Newton steps on its own kinematics.
    let calibrated = ArmErrors::draw(
        41,
        &ArmErrorSigmas {
            joint_offset_rad: 0.05f64.to_radians(),
            length_m: 3e-4,
            twist_rad: 0.02f64.to_radians(),
        },
    )
    .true_arm(&model);
    let pose = calibrated.forward(&q);
    c.bench_function("ur5e calibrated inverse (all 8)", |b| {
        b.iter(|| calibrated.inverse(black_box(&pose)))
    });
    c.bench_function("ur5e calibrated inverse_nearest", |b| {
        b.iter(|| calibrated.inverse_nearest(black_box(&pose), black_box(&q)))
    });
}

/// `n` samples of the eye-in-hand cell described in the module docs.
fn arm_samples(n: usize) -> Vec<ArmSample> {
    let model = UrModel::ur10e();
    let offsets = [0.0, 0.03, -0.04, 0.05, -0.02, 0.0].map(f64::to_radians);
    let mut rng = StdRng::seed_from_u64(41);
    let x = pose_from_rotvec(
        Vector3::new(0.03, -0.07, 0.04),
        Vector3::new(0.0, 0.0, 1.57),
    );
    let y = pose_from_rotvec(Vector3::new(0.5, -0.15, 0.0), Vector3::new(0.0, 0.0, 0.3));
    let (board_t, board_r) = (
        Normal::new(0.0, 0.02e-3).unwrap(),
        Normal::new(0.0, 0.005f64.to_radians()).unwrap(),
    );
    let (arm_t, arm_r) = (
        Normal::new(0.0, 0.02e-3).unwrap(),
        Normal::new(0.0, 0.002f64.to_radians()).unwrap(),
    );
    (0..n)
        .map(|_| {
            let q: Vec<f64> = (0..6).map(|_| rng.random_range(-1.5..1.5)).collect();
            let reported = model.forward(&Joints::from_fn(6, |k| q[k]))
                * pose_from_rotvec(
                    Vector3::from_fn(|_, _| arm_t.sample(&mut rng)),
                    Vector3::from_fn(|_, _| arm_r.sample(&mut rng)),
                );
            let flange = model.forward(&Joints::from_fn(6, |k| q[k] + offsets[k]));
            let seen = x.inverse()
                * flange.inverse()
                * y
                * pose_from_rotvec(
                    Vector3::from_fn(|_, _| board_t.sample(&mut rng)),
                    Vector3::from_fn(|_, _| board_r.sample(&mut rng)),
                );
            ArmSample {
                pair: PosePair::new(reported, seen),
                joints: q,
            }
        })
        .collect()
}

fn arm_fit(c: &mut Criterion) {
    let model = UrModel::ur10e();
    let chain = DhChain {
        d: model.d.to_vec(),
        a: model.a.to_vec(),
        alpha: model.alpha.to_vec(),
    };
    let options = SolveOptions::default();
    for (model, name) in [
        (
            ArmModel::JointOffsets,
            "arm fit (joint offsets, eye-in-hand UR10e)",
        ),
        (ArmModel::Dh, "arm fit (dh, eye-in-hand UR10e)"),
    ] {
        arm_fit_group(c, name, model, &chain, &options);
    }
    // What `solver.kinematics: auto` adds once the offsets are chosen: the DH fit and the
    // offsets' refit under its noise (`ArmRefit::links_choice`).
    let mut group = c.benchmark_group("auto's link choice (eye-in-hand UR10e)");
    group.sample_size(10);
    for n in [20, 50, 200] {
        let samples = arm_samples(n);
        let pairs: Vec<PosePair> = samples.iter().map(|s| s.pair.clone()).collect();
        let start = handeye_solve::solve(Setup::EyeInHand, &pairs, &options).unwrap();
        let refit = ArmRefit {
            setup: Setup::EyeInHand,
            model: ArmModel::JointOffsets,
            chain: chain.clone(),
            samples,
            dropped: start.dropped.clone(),
            start: (start.camera_mount, start.target_mount),
            noise: start.noise.map_or(options.noise, |n| n.model()),
            options: options.clone(),
        };
        let offsets = refit.fit_without(None).unwrap();
        group.bench_with_input(BenchmarkId::from_parameter(n), &refit, |b, refit| {
            b.iter(|| refit.links_choice(black_box(&offsets)).unwrap())
        });
    }
    group.finish();
}

/// One group of [`arm_fit`]: `model` at each N.
fn arm_fit_group(
    c: &mut Criterion,
    name: &str,
    model: ArmModel,
    chain: &DhChain,
    options: &SolveOptions,
) {
    let mut group = c.benchmark_group(name);
    group.sample_size(10);
    for n in [20, 50, 200] {
        let samples = arm_samples(n);
        let pairs: Vec<PosePair> = samples.iter().map(|s| s.pair.clone()).collect();
        let start = handeye_solve::solve(Setup::EyeInHand, &pairs, options).unwrap();
        let noise = start.noise.map_or(options.noise, |n| n.model());
        group.bench_with_input(BenchmarkId::from_parameter(n), &samples, |b, samples| {
            b.iter(|| {
                fit_arm(
                    model,
                    Setup::EyeInHand,
                    chain,
                    black_box(samples),
                    (&start.camera_mount, &start.target_mount),
                    noise,
                    options,
                )
                .unwrap()
            })
        });
    }
    group.finish();
}

criterion_group!(benches, kinematics, arm_fit);
criterion_main!(benches);
