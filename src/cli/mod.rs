//! Subcommands. Each file turns its arguments into library configuration, then calls the library.

mod detect;
mod target;

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
    /// Detect the board in images and estimate T_camera_target.
    Detect(detect::DetectArgs),
    /// Board utilities (printable boards).
    Target(target::TargetArgs),
}

/// Runs one parsed command line.
pub fn run(cli: Cli) -> anyhow::Result<()> {
    match cli.command {
        Command::Detect(args) => detect::run(args),
        Command::Target(args) => target::run(args),
    }
}
