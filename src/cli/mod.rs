//! Subcommands. Each file turns its arguments into library configuration, then calls the library.

mod camera;
mod detect;
mod export;
mod import;
mod plan;
mod replay;
mod report;
mod run;
mod solve;
mod target;
mod verify;

use clap::{Parser, Subcommand};

/// Hand-eye and base-world calibration for robot cells.
#[derive(Debug, Parser)]
#[command(name = "handeye", version, about, long_about = None)]
pub struct Cli {
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
    /// Export a result as ROS 2, URDF, UR, JSON or OpenCV text.
    Export(export::ExportArgs),
    /// USB/UVC cameras: list them, snap a frame (needs the `uvc` build feature).
    Camera(camera::CameraArgs),
    /// Write the HTML calibration report of a solved session.
    Report(report::ReportArgs),
    /// Verify a calibration: holdout poses on the cell, or leave-one-out on recorded samples.
    Verify(verify::VerifyArgs),
}

/// Runs one parsed command line.
pub fn run(cli: Cli) -> anyhow::Result<()> {
    match cli.command {
        Command::Run(args) => run::run(args),
        Command::Plan(args) => plan::run(args),
        Command::Solve(args) => solve::run(args),
        Command::Replay(args) => replay::run(args),
        Command::Detect(args) => detect::run(args),
        Command::Target(args) => target::run(args),
        Command::Import(args) => import::run(args),
        Command::Export(args) => export::run(args),
        Command::Camera(args) => camera::run(args),
        Command::Report(args) => report::run(args),
        Command::Verify(args) => verify::run(args),
    }
}
