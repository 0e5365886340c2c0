//! Speed of the joint solve of a cell with several cameras (issue #27): 3 cameras (one on the
//! wrist, two fixed) × 20 poses, every camera seeing its board at every pose (60 board poses),
//! noisy (0.03–0.04°, 0.15–0.35 mm), from the config's nominal mounts: the joint solve with the
//! per-camera noise estimated (4 rounds) and its covariance, as `handeye run` of
//! `configs/sim-cell-three-cameras.yaml` calls it after each camera's own solve; and the
//! pixel-space stage that follows it in a run (every board corner, 0.1 px noise, every flange
//! pose estimated with the sim arm's repeatability; 3 rounds of corner-noise estimation).
//! Measured (release, shared 2-core machine, a clippy build running beside it): pose space
//! 5.8 ms, pixel space 88 ms per solve.

use std::hint::black_box;

use criterion::{criterion_group, criterion_main, Criterion};
use handeye_core::camera_model::CameraModel;
use handeye_core::setup::predict;
use handeye_solve::rig::{
    solve_rig, solve_rig_pixels, RigData, RigFrame, RigObservation, RigOptions, RigStart,
};
use handeye_vision::Target;
use rand::rngs::StdRng;
use rand::SeedableRng;
use rand_distr::{Distribution, Normal};

#[path = "../tests/util/mod.rs"]
mod util;

use util::rig::{board_pose_noise, jitter, nominal_start, rig_data, wrist_views};

/// The pose-space problem, the lenses, every camera's corners, the robot's repeatability.
type Problem = (
    RigData,
    RigStart,
    Vec<CameraModel>,
    Vec<RigFrame>,
    (f64, f64),
);

fn problem() -> Problem {
    let rig = util::rig::three_cameras();
    let mut rng = StdRng::seed_from_u64(27);
    let unit = Normal::new(0.0, 1.0).expect("unit normal");
    let flanges = wrist_views(&mut rng, 20);
    let models: Vec<CameraModel> = rig
        .cameras
        .iter()
        .map(|c| CameraModel::load(c.intrinsics.as_ref().expect("intrinsics")).expect("lens"))
        .collect();
    let mut observations = Vec::new();
    let mut frames = Vec::new();
    for (i, flange) in flanges.iter().enumerate() {
        for (c, camera) in rig.cameras.iter().enumerate() {
            let board = Target::load(&camera.target).expect("board");
            let truth = camera.simulation.expect("a simulated cell");
            let (sr, st) = board_pose_noise(truth.setup);
            let noise = jitter(&mut rng, sr, st);
            let exact = predict(
                truth.setup,
                &truth.camera_mount,
                &truth.target_mount,
                flange,
            );
            observations.push(RigObservation {
                camera: c,
                pose: i,
                camera_from_target: exact * noise,
            });
            let corners = board
                .points()
                .into_iter()
                .filter_map(|(_, _, p)| {
                    let pixel = models[c].project(&(exact * p))?;
                    let n = nalgebra::Vector2::new(unit.sample(&mut rng), unit.sample(&mut rng));
                    Some((p, pixel + n * 0.1))
                })
                .collect();
            frames.push(RigFrame {
                camera: c,
                pose: i,
                corners,
            });
        }
    }
    let data = rig_data(&rig, flanges, observations);
    let start = nominal_start(&rig);
    let robot = rig.robot_repeatability();
    (data, start, models, frames, robot)
}

fn joint_solve(c: &mut Criterion) {
    let (data, start, models, frames, robot) = problem();
    c.bench_function("rig/joint_solve_3_cameras_20_poses", |b| {
        b.iter(|| {
            solve_rig(black_box(&data), black_box(&start), &RigOptions::default()).expect("solves")
        })
    });
    let pose_space = solve_rig(&data, &start, &RigOptions::default()).expect("solves");
    let options = RigOptions {
        robot_sigma: Some(robot),
        ..RigOptions::default()
    };
    c.bench_function("rig/joint_pixel_solve_3_cameras_20_poses", |b| {
        b.iter(|| {
            let frames = black_box(&frames);
            solve_rig_pixels(&data, &models, frames, &pose_space, &options).expect("solves")
        })
    });
}

criterion_group! {
    name = benches;
    config = Criterion::default().sample_size(20);
    targets = joint_solve
}
criterion_main!(benches);
