//! Subcommands. Each file turns its arguments into library configuration, then calls the library.

#[macro_use]
pub(crate) mod out;

mod camera;
mod camera_link;
mod cameras;
mod console;
mod detect;
mod export;
mod frames;
mod import;
mod plan;
mod publish;
mod replay;
mod report;
mod run;
mod shell;
mod solve;
mod target;
mod verify;

use clap::{Parser, Subcommand};

/// Hand-eye and base-world calibration for robot cells.
#[derive(Debug, Parser)]
#[command(name = "handeye", version, about, long_about = None)]
pub(crate) struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Calibrate a cell: move through the plan, record, solve.
    Run(run::RunArgs),
    /// Generate or check pose plans (nothing moves).
    Plan(plan::PlanArgs),
    /// Solve a dataset file for both unknowns and write the result YAML.
    Solve(solve::SolveArgs),
    /// Re-detect and re-solve a recorded session offline.
    Replay(replay::ReplayArgs),
    /// Detect the board in images and estimate T_camera_target.
    Detect(detect::DetectArgs),
    /// Board utilities (printable boards).
    Target(target::TargetArgs),
    /// Import ViSP, MoveIt Calibration or CSV data as a dataset file.
    Import(import::ImportArgs),
    /// Export a result as ROS 2, URDF, UR, JSON or OpenCV text, or its arm model (ur-calibration, dh-table, arm-urdf).
    Export(export::ExportArgs),
    /// Publish a result's two transforms on ROS 2 /tf_static, latched (needs the `ros2` build feature).
    Publish(publish::PublishArgs),
    /// USB/UVC cameras: list them, snap a frame (needs the `uvc` build feature).
    Camera(camera::CameraArgs),
    /// Write the HTML calibration report of a solved session.
    Report(report::ReportArgs),
    /// Verify a calibration: holdout poses on the cell, or leave-one-out on recorded samples.
    Verify(verify::VerifyArgs),
    /// Capture by hand on the live browser console (freedrive, suggested views), then solve.
    Console(console::ConsoleArgs),
    /// Print shell completions for bash, zsh, fish, elvish or PowerShell.
    Completions(shell::CompletionsArgs),
    /// Write the man pages (handeye.1 and one per subcommand).
    Man(shell::ManArgs),
}

/// A command ran correctly but found nothing to work with (no board in any image): `main` exits
/// with code 2 for it, so scripts can tell "nothing found" from a failure (1).
#[derive(Debug, thiserror::Error)]
#[error("{0}")]
pub(crate) struct NothingFound(pub String);

impl NothingFound {
    /// The process exit code for it.
    pub(crate) const EXIT_CODE: u8 = 2;
}

/// Runs one parsed command line.
pub(crate) fn run(cli: Cli) -> anyhow::Result<()> {
    match cli.command {
        Command::Run(args) => run::run(args),
        Command::Plan(args) => plan::run(args),
        Command::Solve(args) => solve::run(args),
        Command::Replay(args) => replay::run(args),
        Command::Detect(args) => detect::run(args),
        Command::Target(args) => target::run(args),
        Command::Import(args) => import::run(args),
        Command::Export(args) => export::run(args),
        Command::Publish(args) => publish::run(args),
        Command::Camera(args) => camera::run(args),
        Command::Report(args) => report::run(args),
        Command::Verify(args) => verify::run(args),
        Command::Console(args) => console::run(args),
        Command::Completions(args) => shell::completions(args),
        Command::Man(args) => shell::man(args),
    }
}

/// The run recording the session folder `root`, if one does, said on stderr: what the command
/// reads of the folder is the poses so far (`solve`, `report`, `verify` go on; `replay` and
/// `run --resume` refuse instead).
fn say_if_live(root: &std::path::Path) -> anyhow::Result<Option<handeye_records::LiveRun>> {
    let live = handeye_records::live_run(root)?;
    if let Some(run) = &live {
        eprintln!(
            "provisional: {run}; what is read here is those poses: run this again when the run has ended"
        );
    }
    Ok(live)
}

/// Asks on the terminal before a real robot moves through `poses` poses; refuses when no one
/// can answer (no terminal: `--yes` is the explicit way to run unattended).
fn confirm_motion(
    prepared: &handeye_session::cell::PreparedCell,
    poses: usize,
) -> anyhow::Result<()> {
    use std::io::{BufRead, IsTerminal};
    if !std::io::stdin().is_terminal() {
        anyhow::bail!(
            "a real robot is about to move and no one can confirm: pass --yes to run unattended"
        );
    }
    out!(
        "About to move the real robot through {poses} poses at up to {:.2} m/s and {:.0} °/s. Type `yes` to start: ",
        prepared.config.limits.linear_speed,
        prepared.config.limits.joint_speed.to_degrees()
    );
    out::flush();
    let mut line = String::new();
    std::io::stdin().lock().read_line(&mut line)?;
    if line.trim() != "yes" {
        anyhow::bail!("not confirmed; nothing was moved");
    }
    Ok(())
}

/// A stop flag set by Ctrl-C, SIGTERM or SIGHUP, for the session loop.
fn stop_on_ctrl_c() -> std::sync::Arc<std::sync::atomic::AtomicBool> {
    let stop = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
    stop_on_signals(stop.clone());
    stop
}

/// Makes Ctrl-C, SIGTERM and SIGHUP set `stop`: the first one stops the arm where it is (a move
/// in progress decelerates) and ends the run cleanly with every sample kept; a second one,
/// should that hang, exits at once. (A service manager's SIGTERM and a closed terminal's SIGHUP
/// take the same path as Ctrl-C: killing the process mid-move would leave the arm moving.)
fn stop_on_signals(stop: std::sync::Arc<std::sync::atomic::AtomicBool>) {
    use std::sync::atomic::Ordering;
    let _ = ctrlc::set_handler(move || {
        if stop.swap(true, Ordering::SeqCst) {
            std::process::exit(130);
        }
        eprintln!("\nstopping the arm now; every recorded sample is kept");
    });
}
