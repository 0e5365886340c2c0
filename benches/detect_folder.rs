//! `handeye detect` on a folder of 50 rendered 1280x720 frames of the 6x6 board (each from its
//! own view), the whole command: on all cores under criterion, and printed once before criterion's
//! rounds on all cores and pinned to one (`taskset -c 0`), the same binary. Issue #29's floor:
//! ≥ 1.7× faster wall time on 2 cores than on 1 (one detector per worker; images are the unit).
//!
//! `cargo bench --bench detect_folder -- --warm-up-time 1 --measurement-time 5`

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

use criterion::Criterion;
use nalgebra::{Translation3, UnitQuaternion, Vector3};
use rand::{Rng, SeedableRng};

use handeye_camera::render::{render, RenderOptions};
use handeye_core::camera_model::CameraModel;
use handeye_core::geometry::Pose;
use handeye_vision::Target;

#[path = "../tests/util/mod.rs"]
mod util;

const FRAMES: usize = 50;

/// The board's centre 0.45–0.75 m in front, tilted up to 35° about a random axis in its plane.
fn random_view(board: &Target, rng: &mut impl Rng) -> Pose {
    let e = board.extent();
    let centre = Vector3::new((e.min.x + e.max.x) / 2.0, (e.min.y + e.max.y) / 2.0, 0.0);
    let axis = rng.random_range(0.0..std::f64::consts::TAU);
    let tilt = rng.random_range(0.0..35f64).to_radians();
    let rotation = UnitQuaternion::from_axis_angle(&Vector3::x_axis(), std::f64::consts::PI)
        * UnitQuaternion::from_scaled_axis(Vector3::new(axis.cos(), axis.sin(), 0.0) * tilt);
    let at = Vector3::new(
        rng.random_range(-0.05..0.05),
        rng.random_range(-0.03..0.03),
        rng.random_range(0.45..0.75),
    );
    Pose::from_parts(Translation3::from(at - rotation * centre), rotation)
}

fn detect_command(board: &Path, intrinsics: &Path, frames: &[PathBuf]) -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_handeye"));
    c.arg("detect")
        .arg("--board")
        .arg(board)
        .arg("--intrinsics")
        .arg(intrinsics)
        .args(frames);
    c
}

/// Wall time of one run of `command` (which must succeed).
fn timed(mut command: Command) -> f64 {
    let started = Instant::now();
    let out = command.output().unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    started.elapsed().as_secs_f64()
}

fn main() {
    let repo = util::repo();
    let board_file = repo.join("configs/targets/aprilgrid-6x6.yaml");
    let intrinsics = repo.join("configs/cameras/sim-1280x720.yaml");
    let board = Target::load(&board_file).unwrap();
    let camera = CameraModel::load(&intrinsics).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let mut rng = rand::rngs::StdRng::seed_from_u64(29);
    let options = RenderOptions {
        blur_sigma_px: 0.6,
        ..RenderOptions::default()
    };
    let frames: Vec<PathBuf> = (0..FRAMES)
        .map(|i| {
            let image = render(
                &board,
                &camera,
                &random_view(&board, &mut rng),
                &options,
                &mut rng,
            );
            let file = dir.path().join(format!("{i:03}.png"));
            image.save(&file).unwrap();
            file
        })
        .collect();
    // Interleaved, so a change in the machine's load touches both alike.
    if Path::new("/usr/bin/taskset").exists() {
        let (mut one, mut all) = (Vec::new(), Vec::new());
        for _ in 0..3 {
            let inner = detect_command(&board_file, &intrinsics, &frames);
            let mut pinned = Command::new("/usr/bin/taskset");
            pinned
                .args(["-c", "0"])
                .arg(inner.get_program())
                .args(inner.get_args());
            one.push(timed(pinned));
            all.push(timed(detect_command(&board_file, &intrinsics, &frames)));
        }
        let (one, all) = (util::median(one), util::median(all));
        println!(
            "detect on {FRAMES} frames, median of 3: one core (taskset -c 0) {one:.2} s, all cores {all:.2} s: {:.2}x",
            one / all
        );
    }
    let mut criterion = Criterion::default().configure_from_args().sample_size(10);
    criterion.bench_function("detect: 50 frames 1280x720, whole command", |b| {
        b.iter(|| {
            let out = detect_command(&board_file, &intrinsics, &frames)
                .output()
                .unwrap();
            assert!(out.status.success());
        })
    });
    criterion.final_summary();
}
