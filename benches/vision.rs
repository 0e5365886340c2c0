//! Speed of the vision chain, release build: rendering, detection and PnP separately on
//! 1280x720 and 1920x1080 rendered frames of the 6x6 board, printed as Kalibr prints it (corner
//! squares: tone-remapped quad search and X-corner refinement), detection + PnP of the same
//! board without the squares, and of a 9x6-square ChArUco board and a 10x7-square chessboard.
//! Floors on the 2-core machine: PnP with refinement for a 6x6 board ≤ 1 ms; detection + PnP
//! at 1280x720 ≤ 15 ms for every board (issue #18; measured on a quiet machine: Kalibr grid
//! 9.0 ms, without squares 4.9 ms, ChArUco 5.8 ms, chessboard 7.0 ms); rendering a 1280x720
//! frame ≤ 150 ms.
//! For repeatable before/after figures under load, count instructions with
//! `valgrind --tool=callgrind` on a binary that runs one detection.

use std::hint::black_box;
use std::path::Path;
use std::time::Duration;

use criterion::{criterion_group, criterion_main, Criterion};
use handeye_camera::render::{render, RenderOptions};
use handeye_core::camera_model::{CameraModel, Distortion};
use handeye_core::geometry::Pose;
use handeye_vision::{estimate_board_pose, DetectorOptions, Target, TargetDetector};
use nalgebra::{Translation3, UnitQuaternion, Vector3};
use rand::SeedableRng;

fn camera(width: u32, height: u32) -> CameraModel {
    let f = 0.71 * width as f64;
    CameraModel {
        width,
        height,
        fx: f,
        fy: f,
        cx: (width as f64 - 1.0) / 2.0 + 1.3,
        cy: (height as f64 - 1.0) / 2.0 - 0.8,
        distortion: Distortion::RadTan {
            k1: -0.12,
            k2: 0.08,
            p1: 0.0006,
            p2: -0.0004,
            k3: -0.02,
        },
    }
}

/// The board centred 0.6 m in front, tilted 30°.
fn view(board: &Target) -> Pose {
    let e = board.extent();
    let centre = Vector3::new((e.min.x + e.max.x) / 2.0, (e.min.y + e.max.y) / 2.0, 0.0);
    let rotation = UnitQuaternion::from_axis_angle(&Vector3::x_axis(), std::f64::consts::PI)
        * UnitQuaternion::from_scaled_axis(Vector3::new(0.6, 0.8, 0.0) * 30f64.to_radians());
    Pose::from_parts(
        Translation3::from(Vector3::new(0.02, -0.01, 0.6) - rotation * centre),
        rotation,
    )
}

fn bench(c: &mut Criterion) {
    let board = Target::load(
        &Path::new(env!("CARGO_MANIFEST_DIR")).join("configs/targets/aprilgrid-6x6.yaml"),
    )
    .unwrap();
    let detector = TargetDetector::spawn(&board, DetectorOptions::default()).unwrap();
    let pose = view(&board);
    let options = RenderOptions {
        blur_sigma_px: 0.6,
        ..RenderOptions::default()
    };
    let mut group = c.benchmark_group("vision");
    group
        .sample_size(10)
        .measurement_time(Duration::from_secs(4));
    for (width, height) in [(1280, 720), (1920, 1080)] {
        let camera = camera(width, height);
        let mut rng = rand::rngs::StdRng::seed_from_u64(1);
        group.bench_function(format!("render_{width}x{height}"), |b| {
            b.iter(|| render(&board, &camera, black_box(&pose), &options, &mut rng))
        });
        let image = render(&board, &camera, &pose, &options, &mut rng);
        let detection = detector.detect(&image).unwrap();
        assert_eq!(detection.tags.len(), 36, "bench frame must show every tag");
        group.bench_function(format!("detect_{width}x{height}"), |b| {
            b.iter(|| detector.detect(black_box(&image)).unwrap())
        });
        group.bench_function(format!("pnp_6x6_{width}x{height}"), |b| {
            b.iter(|| estimate_board_pose(&board, &camera, black_box(&detection)).unwrap())
        });
        group.bench_function(format!("detect_and_pnp_{width}x{height}"), |b| {
            b.iter(|| {
                let detection = detector.detect(black_box(&image)).unwrap();
                estimate_board_pose(&board, &camera, &detection).unwrap()
            })
        });
    }
    for (name, file, count) in [
        ("charuco_9x6", "configs/targets/charuco-9x6-5x5.yaml", 40),
        (
            "checkerboard_10x7",
            "configs/targets/checkerboard-10x7.yaml",
            54,
        ),
    ] {
        let board = Target::load(&Path::new(env!("CARGO_MANIFEST_DIR")).join(file)).unwrap();
        let detector = TargetDetector::spawn(&board, DetectorOptions::default()).unwrap();
        let camera = camera(1280, 720);
        let mut rng = rand::rngs::StdRng::seed_from_u64(2);
        let image = render(&board, &camera, &view(&board), &options, &mut rng);
        let detection = detector.detect(&image).unwrap();
        assert_eq!(
            detection.points.len(),
            count,
            "bench frame must show every corner"
        );
        group.bench_function(format!("detect_and_pnp_{name}_1280x720"), |b| {
            b.iter(|| {
                let detection = detector.detect(black_box(&image)).unwrap();
                estimate_board_pose(&board, &camera, &detection).unwrap()
            })
        });
    }
    // The same board without Kalibr's corner squares: the plain AprilTag path.
    let Target::Aprilgrid(kalibr_board) = &board else {
        panic!("the bench board is an aprilgrid")
    };
    let plain = Target::Aprilgrid(kalibr_board.clone().with_corner_squares(false).unwrap());
    let plain_detector = TargetDetector::spawn(&plain, DetectorOptions::default()).unwrap();
    let camera = camera(1280, 720);
    let mut rng = rand::rngs::StdRng::seed_from_u64(1);
    let image = render(&plain, &camera, &pose, &options, &mut rng);
    assert_eq!(plain_detector.detect(&image).unwrap().tags.len(), 36);
    group.bench_function("detect_and_pnp_no_corner_squares_1280x720", |b| {
        b.iter(|| {
            let detection = plain_detector.detect(black_box(&image)).unwrap();
            estimate_board_pose(&plain, &camera, &detection).unwrap()
        })
    });
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
