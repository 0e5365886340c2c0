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
use handeye_solve::cameras::{
    solve_cameras, solve_cameras_pixels, CamerasData, CamerasFrame, CamerasObservation,
    CamerasOptions, CamerasStart,
};
use handeye_vision::Target;
use rand::rngs::StdRng;
use rand::SeedableRng;
use rand_distr::{Distribution, Normal};

#[path = "../tests/util/mod.rs"]
mod util;

use util::cameras::{board_pose_noise, cameras_data, jitter, nominal_start, wrist_views};

/// The pose-space problem, the lenses, every camera's corners, the robot's repeatability.
type Problem = (
    CamerasData,
    CamerasStart,
    Vec<CameraModel>,
    Vec<CamerasFrame>,
    (f64, f64),
);

fn problem() -> Problem {
    let cell = util::cameras::three_cameras();
    let mut rng = StdRng::seed_from_u64(27);
    let unit = Normal::new(0.0, 1.0).expect("unit normal");
    let flanges = wrist_views(&mut rng, 20);
    let models: Vec<CameraModel> = cell
        .cameras
        .iter()
        .map(|c| CameraModel::load(c.intrinsics.as_ref().expect("intrinsics")).expect("lens"))
        .collect();
    let mut observations = Vec::new();
    let mut frames = Vec::new();
    for (i, flange) in flanges.iter().enumerate() {
        for (c, camera) in cell.cameras.iter().enumerate() {
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
            observations.push(CamerasObservation {
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
            frames.push(CamerasFrame {
                camera: c,
                pose: i,
                corners,
            });
        }
    }
    let data = cameras_data(&cell, flanges, observations);
    let start = nominal_start(&cell);
    let robot = cell.robot_repeatability();
    (data, start, models, frames, robot)
}

fn joint_solve(c: &mut Criterion) {
    let (data, start, models, frames, robot) = problem();
    c.bench_function("cell/joint_solve_3_cameras_20_poses", |b| {
        b.iter(|| {
            solve_cameras(
                black_box(&data),
                black_box(&start),
                &CamerasOptions::default(),
            )
            .expect("solves")
        })
    });
    let pose_space = solve_cameras(&data, &start, &CamerasOptions::default()).expect("solves");
    let options = CamerasOptions {
        robot_sigma: Some(robot),
        ..CamerasOptions::default()
    };
    c.bench_function("cell/joint_pixel_solve_3_cameras_20_poses", |b| {
        b.iter(|| {
            let frames = black_box(&frames);
            solve_cameras_pixels(&data, &models, frames, &pose_space, &options).expect("solves")
        })
    });
}

criterion_group! {
    name = benches;
    config = Criterion::default().sample_size(20);
    targets = joint_solve
}
criterion_main!(benches);
