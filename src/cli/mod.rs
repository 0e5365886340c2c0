//! Subcommands. Each file turns its arguments into library configuration, then calls the library.

mod solve;

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
    /// Solve a dataset file for both unknowns and write the result YAML.
    Solve(solve::SolveArgs),
}

/// Runs one parsed command line.
pub fn run(cli: Cli) -> anyhow::Result<()> {
    match cli.command {
        Command::Solve(args) => solve::run(args),
    }
}
