//! Speed of the reprojection-space refinement at the floor: 20 frames of the 6x6
//! AprilGrid (144 corners each, 2880 in all), eye-in-hand, intrinsics and distortion free, started
//! from a pose-space-like answer (1 mm / 0.1° off) and intrinsics 1 % off. Target: ≤ 200 ms.
//! Also the same with intrinsics fixed, with per-pose robot corrections on, and with the noise
//! estimated from the residuals as well (what a run without intrinsics does by default). The
//! corners carry 0.2 px noise, the robot poses the demo cell's repeatability.
//!
//! And a long recording's session: 200 frames, the lens given, corrections and noise estimated.
//! With per-pose corrections `JᵀJ` is an arrowhead (12 + 6·200 columns) solved by its Schur
//! complement (`handeye_solve`'s `arrow.rs`; issue #43). Release, 2 cores, load 1.3–3 (2026-12-05),
//! medians: 200 frames 6.85 s with one dense Cholesky (and inverse) of the whole matrix → 0.357 s;
//! 20 frames with corrections and the noise estimated 71.2 → 63.5 ms. Then the matrix kept as the
//! arrowhead's parts, never whole (its memory linear in the frames; 1,000 frames: about 1 MB
//! where the whole was 289 MB): release, 2 cores, the machine quiet (load 0.1–0.5, 2026-12-06),
//! medians 196 ms at 200 frames, 1.08 s at 1,000.

use std::hint::black_box;

use criterion::{criterion_group, criterion_main, Criterion};
use nalgebra::{Matrix3, Point2, Rotation3, Translation3, UnitQuaternion, Vector3};
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};
use rand_distr::{Distribution, Normal};

use handeye_core::camera_model::CameraModel;
use handeye_core::geometry::{pose_from_rotvec, Pose};
use handeye_core::setup::Setup;
use handeye_solve::{refine_reprojection, Corner, Frame, ReprojectionOptions, RobotPrior};
use handeye_vision::Board;

#[path = "../tests/util/mod.rs"]
mod util;
use util::repo;

fn frames(
    camera: &CameraModel,
    flange_from_camera: &Pose,
    base_from_target: &Pose,
    count: usize,
) -> Vec<Frame> {
    let board = Board::load(&repo().join("configs/targets/aprilgrid-6x6.yaml")).unwrap();
    let mut rng = StdRng::seed_from_u64(3);
    let noise = Normal::new(0.0, 0.2).unwrap();
    let robot_noise = Normal::new(0.0, 1.0).unwrap();
    let centre = Vector3::new(0.145, 0.145, 0.0);
    (0..count)
        .map(|_| {
            let tilt = rng.random_range(0.1..0.5f64);
            let azimuth = rng.random_range(0.0..std::f64::consts::TAU);
            let distance = rng.random_range(0.55..0.7);
            let position = centre
                + Vector3::new(
                    tilt.sin() * azimuth.cos(),
                    tilt.sin() * azimuth.sin(),
                    tilt.cos(),
                ) * distance;
            let z = (centre - position).normalize();
            let x = (Vector3::x() - z * z.x).normalize();
            let rotation =
                Rotation3::from_matrix_unchecked(Matrix3::from_columns(&[x, z.cross(&x), z]));
            let target_from_camera = Pose::from_parts(
                Translation3::from(position),
                UnitQuaternion::from_rotation_matrix(&rotation),
            );
            let camera_from_target = target_from_camera.inverse();
            let corners = board
                .tags()
                .iter()
                .flat_map(|t| board.tag_corners_in_target(t.id).unwrap())
                .map(|p| {
                    let px = camera.project(&(camera_from_target * p)).unwrap();
                    Corner {
                        point_in_target: p,
                        pixel: Point2::new(
                            px.x + noise.sample(&mut rng),
                            px.y + noise.sample(&mut rng),
                        ),
                    }
                })
                .collect();
            // The arm reports its pose with the demo cell's repeatability (0.02 mm, 0.002°).
            let mut jitter = || Vector3::from_fn(|_, _| robot_noise.sample(&mut rng));
            let reported_error =
                pose_from_rotvec(jitter() * 0.02e-3, jitter() * 0.002f64.to_radians());
            Frame {
                base_from_flange: base_from_target
                    * target_from_camera
                    * flange_from_camera.inverse()
                    * reported_error,
                corners,
                id: None,
            }
        })
        .collect()
}

fn reprojection(c: &mut Criterion) {
    let camera = CameraModel::load(&repo().join("configs/cameras/sim-1280x720.yaml")).unwrap();
    let flange_from_camera = pose_from_rotvec(
        Vector3::new(0.0312, -0.0694, 0.0447),
        Vector3::new(0.021, -0.016, 1.561),
    );
    let base_from_target = pose_from_rotvec(
        Vector3::new(0.5034, -0.1467, 0.0021),
        Vector3::new(0.012, -0.018, 0.297),
    );
    let many = frames(&camera, &flange_from_camera, &base_from_target, 200);
    let most = frames(&camera, &flange_from_camera, &base_from_target, 1000);
    let frames = frames(&camera, &flange_from_camera, &base_from_target, 20);
    assert_eq!(
        frames.iter().map(|f| f.corners.len()).sum::<usize>(),
        20 * 144
    );
    let off = pose_from_rotvec(
        Vector3::new(0.001, -0.0005, 0.0005),
        Vector3::new(0.0017, 0.0, -0.001),
    );
    let start_camera = flange_from_camera * off;
    let start_target = base_from_target * off;
    let mut start_model = camera;
    start_model.fx *= 1.01;
    start_model.fy *= 0.99;
    start_model.cx += 3.0;
    start_model.cy -= 3.0;
    let free = ReprojectionOptions {
        refine_intrinsics: true,
        refine_distortion: true,
        ..ReprojectionOptions::default()
    };
    // The demo cell's arm repeatability (0.02 mm, 0.002°), the prior of the robot corrections.
    let repeatability = RobotPrior {
        translation_sigma_m: 2e-5,
        rotation_sigma_rad: 0.002f64.to_radians(),
    };
    let mut group = c.benchmark_group("reprojection");
    group.sample_size(20);
    group.bench_function("20 frames 6x6, intrinsics + distortion free", |b| {
        b.iter(|| {
            refine_reprojection(
                Setup::EyeInHand,
                black_box(&frames),
                &start_model,
                &start_camera,
                &start_target,
                &free,
            )
            .unwrap()
        })
    });
    group.bench_function("20 frames 6x6, intrinsics fixed", |b| {
        b.iter(|| {
            refine_reprojection(
                Setup::EyeInHand,
                black_box(&frames),
                &camera,
                &start_camera,
                &start_target,
                &ReprojectionOptions::default(),
            )
            .unwrap()
        })
    });
    group.bench_function("20 frames 6x6, intrinsics free + robot corrections", |b| {
        b.iter(|| {
            refine_reprojection(
                Setup::EyeInHand,
                black_box(&frames),
                &start_model,
                &start_camera,
                &start_target,
                &ReprojectionOptions {
                    robot_prior: Some(repeatability),
                    ..free.clone()
                },
            )
            .unwrap()
        })
    });
    // What a run without intrinsics does by default: corrections and the noise estimated.
    group.bench_function(
        "20 frames 6x6, intrinsics free + robot corrections + noise estimated",
        |b| {
            b.iter(|| {
                refine_reprojection(
                    Setup::EyeInHand,
                    black_box(&frames),
                    &start_model,
                    &start_camera,
                    &start_target,
                    &ReprojectionOptions {
                        robot_prior: Some(repeatability),
                        estimate_noise: true,
                        ..free.clone()
                    },
                )
                .unwrap()
            })
        },
    );
    // A long recording's session (issue #43: 200 samples, the lens given, the default solve's
    // corrections and noise estimate): with per-pose corrections `JᵀJ` has 12 + 6·200 columns,
    // solved by its Schur complement (`arrow.rs`).
    group.sample_size(10);
    // And 1,000 (a 10-minute recording of 1,000 stops): `JᵀJ` is kept as the arrowhead's parts
    // (`arrow::Arrowhead`), so memory and time stay linear in the frames.
    for (name, frames) in [
        (
            "200 frames 6x6, intrinsics fixed + robot corrections + noise estimated",
            &many,
        ),
        (
            "1000 frames 6x6, intrinsics fixed + robot corrections + noise estimated",
            &most,
        ),
    ] {
        group.bench_function(name, |b| {
            b.iter(|| {
                refine_reprojection(
                    Setup::EyeInHand,
                    black_box(frames),
                    &camera,
                    &start_camera,
                    &start_target,
                    &ReprojectionOptions {
                        robot_prior: Some(repeatability),
                        estimate_noise: true,
                        ..ReprojectionOptions::default()
                    },
                )
                .unwrap()
            })
        });
    }
    group.finish();
}

criterion_group!(benches, reprojection);
criterion_main!(benches);
