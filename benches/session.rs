//! Whole simulated calibrations: a 20-pose run with instant moves (criterion), a 20-pose run
//! with 2 s moves (is the vision and solver work hidden under motion?), the peak memory of a
//! 100-pose run (frames go to disk, not into memory), and arm time (issue 16): with real move
//! timing (trapezoidal moves at the configured limits, the arm ringing down after each move),
//! the time from the first move to the result of today's behaviour (the 20-pose generated plan
//! in its given order, a fixed 0.2 s settle) against the new default (adaptive, ordered for
//! travel, settled by measured joint speeds) at equal accuracy, over several seeds.
//!
//! `cargo bench --bench session` runs all four; `cargo bench --bench session -- armtime` only
//! the arm-time comparison. The memory figure is the process's peak RSS, measured first so
//! nothing else has raised it.

use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicBool;
use std::sync::Arc;
use std::time::{Duration, Instant};

use criterion::Criterion;
use handeye_records::dataset::Dataset;
use handeye_records::SessionFolder;
use handeye_session::cell;
use handeye_session::cell::run::{CellRun, RunObserver};

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
    folder.write_manifest(&prepared.manifest(0, &plan)).unwrap();
    let mut hardware = prepared.open_hardware().unwrap();
    let setup = prepared.session_setup(folder.clone(), plan, Arc::new(AtomicBool::new(false)));
    handeye_session::run_session(
        setup,
        hardware.robot.as_mut(),
        &mut [hardware.cameras[0].as_mut()],
        &mut |_| {},
    )
    .unwrap();
    handeye_records::solve_folder(&folder, &prepared.solve_inputs()).unwrap();
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

/// Notes when the session loop starts (the first move follows at once).
struct StartClock(Option<Instant>);

impl RunObserver for StartClock {
    fn confirm_motion(
        &mut self,
        _: &cell::PreparedCell,
        _: usize,
    ) -> Result<(), Box<dyn std::error::Error + Send + Sync>> {
        Ok(())
    }
    fn session_started(&mut self, _: usize) {
        self.0 = Some(Instant::now());
    }
}

/// `handeye run` of `config` into `out`: the run and the time from its first move to the
/// result, s.
fn timed_run(config: &Path, out: &Path) -> (CellRun, f64) {
    let mut clock = StartClock(None);
    let done = cell::run::run(
        &util::new_run(config, out),
        cell::run::Strategy::Planned,
        &mut clock,
    )
    .unwrap();
    let started = clock.0.expect("the session started");
    (done, started.elapsed().as_secs_f64())
}

/// Worst translation 1-sigma of the final answer, mm, and its true error against the
/// simulator, mm (worst of the two unknowns).
fn accuracy(done: &CellRun) -> (f64, f64) {
    let c = &done
        .solved
        .as_ref()
        .expect("one camera, solved alone")
        .calibration;
    let u = c.uncertainty.as_ref().expect("covariance");
    let truth = done.cell.config.camera().simulation.expect("sim truth");
    let error = |a: &handeye_core::geometry::Pose, b: &handeye_core::geometry::Pose| {
        (a.translation.vector - b.translation.vector).norm() * 1e3
    };
    (
        u.camera_mount
            .translation_mm
            .max(u.target_mount.translation_mm),
        error(&c.camera_mount, &truth.camera_mount)
            .max(error(&c.target_mount, &truth.target_mount)),
    )
}

/// The pose-space 1-sigma of a session's samples, mm: what the adaptive stop rule measures.
fn pose_space_sigma_mm(done: &CellRun) -> f64 {
    let samples = Dataset::load(&done.folder.samples_path()).unwrap();
    let c = handeye_solve::solve(
        samples.setup,
        &samples.pairs,
        &done.cell.config.solver.to_options(),
    )
    .unwrap();
    let u = c.uncertainty.expect("covariance");
    u.camera_mount
        .translation_mm
        .max(u.target_mount.translation_mm)
}

/// Today's behaviour against the new default, with real move timing, over `seeds`.
fn arm_time(dir: &Path, seeds: &[u64]) {
    let timed = "move_duration_s: 0.0\n  move_at_limits: true\n  ringing_deg: 0.05";
    let (mut today_sum, mut new_sum) = (0.0, 0.0);
    for &seed in seeds {
        let plan_seed = format!("seed: {seed}}}");
        let robot_seed = format!("seed: {}", 7 + seed);
        let common = [
            ("move_duration_s: 0.0", timed),
            ("seed: 1}", plan_seed.as_str()),
            ("seed: 7", robot_seed.as_str()),
        ];
        let mut today_edits = common.to_vec();
        today_edits.push(("plan:\n", "plan:\n  adaptive: false\n  reorder: false\n"));
        today_edits.push((
            "session: {settle_s: 0.0,",
            "session: {settle_s: 0.2, settle_speed_deg_s: 0,",
        ));
        let today = util::config_variant(
            dir,
            "sim-cell.yaml",
            &format!("today-{seed}.yaml"),
            &today_edits,
        );
        let (today_run, today_s) = timed_run(&today, &dir.join(format!("today-{seed}")));
        let (today_sigma, today_error) = accuracy(&today_run);
        // Equal accuracy: the new default stops at the 1-sigma today's 20 poses reach, in the
        // space its stop rule measures (pose space).
        let target = pose_space_sigma_mm(&today_run);
        let target_line = format!("plan:\n  target_uncertainty_mm: {target:.6}\n");
        let mut new_edits = common.to_vec();
        new_edits.push(("plan:\n", target_line.as_str()));
        let new = util::config_variant(
            dir,
            "sim-cell.yaml",
            &format!("new-{seed}.yaml"),
            &new_edits,
        );
        let (new_run, new_s) = timed_run(&new, &dir.join(format!("new-{seed}")));
        let (new_sigma, new_error) = accuracy(&new_run);
        let adaptive = new_run.adaptive.as_ref().expect("adaptive by default");
        println!(
            "armtime/seed {seed}: today {today_s:.1} s first move to result ({} poses, arm {:.1} s; 1-sigma {today_sigma:.3} mm, true error {today_error:.3} mm) | new default {new_s:.1} s ({} poses, arm {:.1} s; 1-sigma {new_sigma:.3} mm, true error {new_error:.3} mm; stop target {target:.3} mm pose-space, {}) | ratio {:.2}",
            today_run.arm_time.expect("a planned run keeps its arm time").poses,
            today_run.arm_time.expect("a planned run keeps its arm time").spent_s(),
            new_run.arm_time.expect("a planned run keeps its arm time").poses,
            new_run.arm_time.expect("a planned run keeps its arm time").spent_s(),
            if adaptive.reached { "reached" } else { "NOT reached" },
            new_s / today_s
        );
        today_sum += today_s;
        new_sum += new_s;
    }
    println!(
        "armtime/mean over {} seeds: today {:.1} s, new default {:.1} s: {:.2}x (goal <= 0.50x)",
        seeds.len(),
        today_sum / seeds.len() as f64,
        new_sum / seeds.len() as f64,
        new_sum / today_sum
    );
}

fn main() {
    let dir = tempfile::tempdir().unwrap();
    if std::env::args().any(|a| a == "armtime") {
        arm_time(dir.path(), &[1, 2, 3]);
        return;
    }

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

    arm_time(dir.path(), &[1, 2, 3]);
}
