//! Speed of the joint solve of a cell with several cameras (issue #27): 3 cameras (one on the
//! wrist, two fixed) × 20 poses, every camera seeing its board at every pose (60 board poses),
//! noisy (0.03–0.04°, 0.15–0.35 mm), from the config's nominal mounts: the joint solve with the
//! per-camera noise estimated (4 rounds) and its covariance, as `handeye run` of
//! `configs/sim-cell-three-cameras.yaml` calls it after each camera's own solve; and the
//! pixel-space stage that follows it in a run (every board corner, 0.1 px noise, every flange
//! pose estimated with the sim arm's repeatability; 3 rounds of corner-noise estimation).
//! Measured (release, shared 2-core machine, a clippy build running beside it): pose space
//! 5.8 ms, pixel space 88 ms per solve.
//!
//! The pixel-space stage also at 200 poses (a long recording, issue #43: 600 board poses,
//! 1,230 parameters), where its normal equations are kept as an arrowhead (`arrow.rs`).
//! Measured on a quiet machine (load 1.3): pose space 2.3 ms, pixel space 34 ms at 20 poses and
//! 0.31 s at 200 (2.72 s when it built the whole `JᵀJ`); 1.58 s at 1,000.
//! `CAMERAS_BENCH_POSES=N` adds a case of N poses (e.g. 1,000: run it alone, with
//! `/usr/bin/time`, to see the peak memory).

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

fn problem(poses: usize) -> Problem {
    let cell = util::cameras::three_cameras();
    let mut rng = StdRng::seed_from_u64(27);
    let unit = Normal::new(0.0, 1.0).expect("unit normal");
    let flanges = wrist_views(&mut rng, poses);
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
                weight: 1.0,
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
                weight: 1.0,
            });
        }
    }
    let data = cameras_data(&cell, flanges, observations);
    let start = nominal_start(&cell);
    let robot = cell.robot_repeatability();
    (data, start, models, frames, robot)
}

fn joint_solve(c: &mut Criterion) {
    let (data, start, _, _, _) = problem(20);
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
}

fn joint_pixel_solve(c: &mut Criterion) {
    let extra = std::env::var("CAMERAS_BENCH_POSES")
        .ok()
        .and_then(|n| n.parse::<usize>().ok());
    let mut group = c.benchmark_group("cell");
    group.sample_size(10);
    for poses in [20, 200].into_iter().chain(extra) {
        let (data, start, models, frames, robot) = problem(poses);
        let pose_space = solve_cameras(&data, &start, &CamerasOptions::default()).expect("solves");
        let options = CamerasOptions {
            robot_sigma: Some(robot),
            ..CamerasOptions::default()
        };
        group.bench_function(format!("joint_pixel_solve_3_cameras_{poses}_poses"), |b| {
            b.iter(|| {
                let frames = black_box(&frames);
                solve_cameras_pixels(&data, &models, frames, &pose_space, &options).expect("solves")
            })
        });
    }
    group.finish();
}

criterion_group! {
    name = benches;
    config = Criterion::default().sample_size(20);
    targets = joint_solve, joint_pixel_solve
}
criterion_main!(benches);
