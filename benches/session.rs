//! Whole simulated calibrations: a 20-pose run with instant moves (criterion), a 20-pose run
//! with 2 s moves (is the vision and solver work hidden under motion?), and the peak memory of a
//! 100-pose run (frames go to disk, not into memory).
//!
//! `cargo bench --bench session` runs all three; the memory figure is the process's peak RSS,
//! measured first so nothing else has raised it.

use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicBool;
use std::sync::Arc;
use std::time::{Duration, Instant};

use criterion::Criterion;
use handeye::cell;
use handeye::session::{self, SessionFolder};

#[path = "../tests/util/mod.rs"]
mod util;

fn config(dir: &Path, count: usize, move_duration_s: f64) -> PathBuf {
    let (count_line, duration) = (
        format!("count: {count}"),
        format!("move_duration_s: {move_duration_s}"),
    );
    util::config_variant(
        dir,
        "sim-cell.yaml",
        &format!("cell-{count}-{move_duration_s}.yaml"),
        &[
            ("count: 20", &count_line),
            ("move_duration_s: 0.0", &duration),
        ],
    )
}

/// One whole calibration, as `handeye run` does it: prepare, run, solve.
fn calibrate(config: &Path, out: &Path) {
    let prepared = cell::prepare(config).unwrap();
    let plan = prepared.report.validated().expect("valid plan");
    let folder = SessionFolder::create(out).unwrap();
    folder.write_manifest(&prepared.manifest(&plan)).unwrap();
    let mut hardware = prepared.open_hardware().unwrap();
    let setup = prepared.session_setup(folder.clone(), plan, Arc::new(AtomicBool::new(false)));
    session::run_session(
        setup,
        hardware.robot.as_mut(),
        hardware.camera.as_mut(),
        &mut |_| {},
    )
    .unwrap();
    session::solve_folder(&folder, &prepared.solve_inputs()).unwrap();
}

fn peak_rss_mb() -> f64 {
    let status = std::fs::read_to_string("/proc/self/status").unwrap_or_default();
    status
        .lines()
        .find_map(|l| l.strip_prefix("VmHWM:"))
        .and_then(|v| v.trim().trim_end_matches("kB").trim().parse::<f64>().ok())
        .map(|kb| kb / 1024.0)
        .unwrap_or(f64::NAN)
}

fn main() {
    let dir = tempfile::tempdir().unwrap();

    let started = Instant::now();
    calibrate(&config(dir.path(), 100, 0.0), &dir.path().join("run-100"));
    println!(
        "session/100 poses, instant moves: {:.1} s wall, peak RSS {:.0} MB (floor 300 MB)",
        started.elapsed().as_secs_f64(),
        peak_rss_mb()
    );

    let move_s = 2.0;
    let started = Instant::now();
    calibrate(
        &config(dir.path(), 20, move_s),
        &dir.path().join("run-slow"),
    );
    let wall = started.elapsed();
    let floor = Duration::from_secs_f64(20.0 * move_s + 1.0);
    println!(
        "session/20 poses, {move_s} s moves, settle 0: {:.2} s wall (floor {:.0} s = 20 × 2 s + 1 s)",
        wall.as_secs_f64(),
        floor.as_secs_f64()
    );

    let mut criterion = Criterion::default().configure_from_args().sample_size(10);
    let fast = config(dir.path(), 20, 0.0);
    let mut run = 0;
    criterion.bench_function("session/20 poses, instant moves", |b| {
        b.iter(|| {
            run += 1;
            calibrate(&fast, &dir.path().join(format!("run-fast-{run}")));
        })
    });
    criterion.final_summary();
}
