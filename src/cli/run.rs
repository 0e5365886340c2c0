//! `handeye run`: validate the plan, drive the cell, record, solve, report.

use std::io::{BufRead, IsTerminal, Write};
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

use anyhow::{bail, Context};
use clap::Args;
use indicatif::{ProgressBar, ProgressStyle};

use handeye::cell::{self, PreparedCell};
use handeye::session::{self, SessionEvent, SessionFolder, SessionSetup};

/// Calibrate a cell: move through the plan, record every frame and pose, solve.
#[derive(Debug, Args)]
pub struct RunArgs {
    /// The cell config (robot, camera, board, plan, limits).
    #[arg(long, required_unless_present = "resume")]
    config: Option<PathBuf>,
    /// Where to write the session folder (default: sessions/<date-time>).
    #[arg(long, conflicts_with = "resume")]
    out: Option<PathBuf>,
    /// Continue an interrupted session in this folder.
    #[arg(long)]
    resume: Option<PathBuf>,
    /// Do not ask for confirmation before moving a real robot.
    #[arg(long)]
    yes: bool,
}

/// Runs `handeye run`.
pub fn run(args: RunArgs) -> anyhow::Result<()> {
    let (folder, config_path) = match &args.resume {
        Some(dir) => {
            let folder = SessionFolder::open(dir)?;
            let manifest = folder.read_manifest()?;
            let config = args.config.clone().unwrap_or(manifest.config);
            (Some(folder), config)
        }
        None => (None, args.config.clone().expect("clap requires --config")),
    };
    let prepared = cell::prepare(&config_path)
        .with_context(|| format!("preparing the cell from {}", config_path.display()))?;
    println!("{}", prepared.report);
    let Some(plan) = prepared.report.validated() else {
        bail!("the plan failed its checks (see the table above); nothing was moved");
    };
    if !prepared.is_simulated() && !args.yes {
        confirm(&prepared, plan.len())?;
    }

    let folder = match folder {
        Some(folder) => folder,
        None => {
            let out = args.out.clone().unwrap_or_else(default_session_dir);
            let folder = SessionFolder::create(&out)?;
            folder.write_manifest(&prepared.manifest(&plan))?;
            folder
        }
    };
    let stop = Arc::new(AtomicBool::new(false));
    {
        let stop = stop.clone();
        // A second Ctrl-C while the arm is finishing its move leaves the default behaviour to the OS.
        let _ = ctrlc::set_handler(move || {
            if stop.swap(true, Ordering::SeqCst) {
                std::process::exit(130);
            }
            eprintln!("\nstopping after the current move; every recorded sample is kept");
        });
    }

    let mut hardware = prepared
        .open_hardware()
        .context("opening the robot and camera")?;
    let setup = SessionSetup {
        folder: folder.clone(),
        setup: prepared.config.setup,
        plan: plan.clone(),
        limits: prepared.config.limits,
        settle: prepared.config.settle(),
        max_reprojection_rms_px: prepared.config.session.max_reprojection_rms_px,
        board: prepared.board.clone(),
        detector: prepared.detector_options(),
        stop,
        estimate_intrinsics: !prepared.intrinsics_known,
    };
    let bar = progress_bar(plan.len() as u64);
    let mut on_event = |event: SessionEvent| match event {
        SessionEvent::Moving { plan_index } => {
            bar.set_message(format!("moving to pose {plan_index}"))
        }
        SessionEvent::Recorded {
            plan_index,
            reprojection_rms_px,
            tags,
            rejected,
            will_retry,
        } => {
            let line = match (&rejected, reprojection_rms_px) {
                (None, Some(rms)) => {
                    format!("pose {plan_index:>3}: ok, {tags} tags, board RMS {rms:.3} px")
                }
                (Some(why), _) if will_retry => {
                    format!("pose {plan_index:>3}: {why}; will retry once")
                }
                (Some(why), _) => format!("pose {plan_index:>3}: skipped: {why}"),
                (None, None) => format!("pose {plan_index:>3}: ok"),
            };
            bar.println(line);
            if !will_retry {
                bar.inc(1);
            }
        }
    };
    let outcome = session::run_session(
        setup,
        hardware.robot.as_mut(),
        hardware.camera.as_mut(),
        &mut on_event,
    );
    bar.finish_and_clear();
    let outcome = outcome?;
    if !outcome.skipped.is_empty() {
        println!(
            "skipped poses: {}",
            outcome
                .skipped
                .iter()
                .map(|(i, why)| format!("{i} ({why})"))
                .collect::<Vec<_>>()
                .join(", ")
        );
    }
    let result = session::solve_folder(&folder, &prepared.config)?;
    println!("{}", result.summary);
    if let Some(truth) = &prepared.config.simulation {
        println!("{}", result.compare_with_truth(truth));
    }
    println!("session folder: {}", folder.root().display());
    Ok(())
}

fn default_session_dir() -> PathBuf {
    let now = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|d| d.as_secs())
        .unwrap_or(0);
    PathBuf::from(format!("sessions/session-{now}"))
}

fn confirm(prepared: &PreparedCell, poses: usize) -> anyhow::Result<()> {
    if !std::io::stdin().is_terminal() {
        bail!("a real robot is about to move and no one can confirm: pass --yes to run unattended");
    }
    print!(
        "About to move the real robot through {poses} poses at up to {:.2} m/s and {:.0} °/s. Type `yes` to start: ",
        prepared.config.limits.linear_speed,
        prepared.config.limits.joint_speed.to_degrees()
    );
    std::io::stdout().flush()?;
    let mut line = String::new();
    std::io::stdin().lock().read_line(&mut line)?;
    if line.trim() != "yes" {
        bail!("not confirmed; nothing was moved");
    }
    Ok(())
}

fn progress_bar(len: u64) -> ProgressBar {
    let bar = ProgressBar::new(len);
    bar.set_style(
        ProgressStyle::with_template("{bar:30} {pos}/{len} poses  ETA {eta}  {msg}")
            .expect("valid template"),
    );
    bar
}
