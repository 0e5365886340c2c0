//! What the live console costs a run (issue #15: at most 5 %): the same 20-pose simulated
//! calibration (instant moves, so nothing hides the console's work), in-process as
//! `handeye run` does it, without the console and with it — started for the run, and a
//! WebSocket client (tokio-tungstenite, on its own thread) connected that reads every event and
//! frame until the console closes. The console's start-up, the run's events, the analysis
//! thread (coverage, running estimate, frames) and its flush at the end are all inside the
//! timed call.
//!
//! Then, because a shared machine's load drifts between criterion's groups, both variants again
//! in interleaved rounds (`HANDEYE_CONSOLE_ROUNDS`, default 10): the medians of wall time and of
//! the process's CPU time (user + system; the client's own thread subtracted: it stands in for a
//! browser, which is not ours).
//!
//! `cargo bench --bench console -- --warm-up-time 1 --measurement-time 3`

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use criterion::Criterion;
use handeye_console::{Console, ConsoleObserver, ConsoleOptions};
use handeye_session::cell;
use rustix::time::{clock_gettime, ClockId};

#[path = "../tests/util/mod.rs"]
mod util;

/// CPU time (user + system) of this process (`ClockId::ProcessCPUTime`) or of the calling
/// thread (`ClockId::ThreadCPUTime`), s.
fn cpu_s(clock: ClockId) -> f64 {
    let t = clock_gettime(clock);
    t.tv_sec as f64 + t.tv_nsec as f64 * 1e-9
}

/// A page that reads everything until the console closes; returns its messages and adds its
/// thread's CPU time (µs) to `client_cpu_us`.
fn client(url: String, client_cpu_us: Arc<AtomicU64>) -> std::thread::JoinHandle<usize> {
    std::thread::spawn(move || {
        use futures_util::StreamExt;
        let runtime = tokio::runtime::Builder::new_current_thread()
            .enable_all()
            .build()
            .unwrap();
        let messages = runtime.block_on(async {
            let (mut ws, _) = tokio_tungstenite::connect_async(util::console_socket(&url))
                .await
                .unwrap();
            let mut n = 0;
            while let Some(Ok(_)) = ws.next().await {
                n += 1;
            }
            n
        });
        let cpu = cpu_s(ClockId::ThreadCPUTime);
        client_cpu_us.fetch_add((cpu * 1e6) as u64, Ordering::Relaxed);
        messages
    })
}

/// One run without the console.
fn plain(config: &Path, out: PathBuf) {
    util::run_cell(config, &out);
}

/// One run with the console and a connected client, as `handeye run --console` does it.
fn with_console(config: &Path, out: PathBuf, client_cpu_us: &Arc<AtomicU64>) -> usize {
    let request = util::new_run(config, &out);
    let console = Console::start(
        &ConsoleOptions {
            addr: "127.0.0.1:0".parse().unwrap(),
            allow_remote: false,
        },
        request.stop.clone(),
    )
    .unwrap();
    let page = client(console.url(), client_cpu_us.clone());
    assert!(console.wait_for_client(Duration::from_secs(10)));
    let mut quiet = util::QuietObserver;
    let mut observer = ConsoleObserver::new(&mut quiet, &console);
    cell::run::run(&request, cell::run::Strategy::Planned, &mut observer).unwrap();
    observer.flush();
    drop(observer);

    // As the CLI does at the end: the page gets the last events, then the server goes.
    console.close(Duration::from_secs(1));
    drop(console);
    page.join().unwrap()
}

fn main() {
    let dir = tempfile::tempdir().unwrap();
    // A fixed plan: all 20 poses are visited (an adaptive one may stop earlier).
    let config = util::config_variant(
        dir.path(),
        "sim-cell.yaml",
        "cell.yaml",
        &[("plan:\n", "plan:\n  adaptive: false\n")],
    );
    let runs = AtomicU64::new(0);
    let next_out = || {
        dir.path()
            .join(format!("s{}", runs.fetch_add(1, Ordering::Relaxed)))
    };

    let client_cpu_us = Arc::new(AtomicU64::new(0));
    let mut criterion = Criterion::default().sample_size(10).configure_from_args();
    let mut group = criterion.benchmark_group("console");
    // Whole runs of about two seconds: the same number of runs in every sample.
    group.sampling_mode(criterion::SamplingMode::Flat);
    group.bench_function("run_20_poses", |b| b.iter(|| plain(&config, next_out())));
    group.bench_function("run_20_poses_console_client", |b| {
        b.iter(|| with_console(&config, next_out(), &client_cpu_us))
    });
    group.finish();
    criterion.final_summary();

    // The two one after the other, round by round, so a change of the machine's load (other
    // builds on it) weighs on both alike; wall and CPU time per run, medians.
    let rounds: usize = std::env::var("HANDEYE_CONSOLE_ROUNDS")
        .ok()
        .and_then(|r| r.parse().ok())
        .unwrap_or(10);
    let (mut without, mut with, mut messages) = (Vec::new(), Vec::new(), 0);
    for _ in 0..rounds {
        let (c0, t0) = (cpu_s(ClockId::ProcessCPUTime), Instant::now());
        plain(&config, next_out());
        without.push((
            t0.elapsed().as_secs_f64(),
            cpu_s(ClockId::ProcessCPUTime) - c0,
        ));
        let client0 = client_cpu_us.load(Ordering::Relaxed);
        let (c0, t0) = (cpu_s(ClockId::ProcessCPUTime), Instant::now());
        messages = with_console(&config, next_out(), &client_cpu_us);
        let wall = t0.elapsed().as_secs_f64();
        let client_s = (client_cpu_us.load(Ordering::Relaxed) - client0) as f64 * 1e-6;
        with.push((wall, cpu_s(ClockId::ProcessCPUTime) - c0 - client_s));
    }
    let median = |runs: &[(f64, f64)], pick: fn(&(f64, f64)) -> f64| {
        let mut v: Vec<f64> = runs.iter().map(pick).collect();
        v.sort_by(f64::total_cmp);
        v[v.len() / 2]
    };
    let load = std::fs::read_to_string("/proc/loadavg").unwrap_or_default();
    for (what, pick) in [
        ("wall", (|r: &(f64, f64)| r.0) as fn(&(f64, f64)) -> f64),
        ("cpu", |r: &(f64, f64)| r.1),
    ] {
        let (a, b) = (median(&without, pick), median(&with, pick));
        println!(
            "console/{what} per run, medians of {rounds} interleaved rounds: without {a:.3} s, with console + client {b:.3} s: {:+.1} %",
            100.0 * (b - a) / a
        );
    }
    println!(
        "console/{messages} messages per run reached the client (its own CPU excluded); load average at the end: {}",
        load.split_whitespace().take(3).collect::<Vec<_>>().join(" ")
    );
}
