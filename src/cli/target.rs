//! `handeye target render`: writes a printable board (PNG at a given dpi, or SVG in mm) at
//! true scale with a scale bar and its parameters in the margin.

use std::path::PathBuf;

use anyhow::{bail, Context};
use clap::{Args, Subcommand};

use handeye::atomic_file::write_atomic;
use handeye::vision::print::{board_png, board_svg};
use handeye::vision::Board;

/// Board utilities.
#[derive(Debug, Args)]
pub struct TargetArgs {
    #[command(subcommand)]
    command: TargetCommand,
}

#[derive(Debug, Subcommand)]
enum TargetCommand {
    /// Write a printable board (.png or .svg) at true scale.
    Render {
        /// Board YAML (Kalibr aprilgrid form).
        #[arg(long)]
        target: PathBuf,
        /// Output file; the extension (.png or .svg) picks the format.
        #[arg(short = 'o', long)]
        output: PathBuf,
        /// Resolution of a PNG, dots per inch.
        #[arg(long, default_value_t = 300.0)]
        dpi: f64,
        /// Overlay the board frame (axes, ids, corner order) for documentation; not for printing.
        #[arg(long)]
        show_frame: bool,
    },
}

/// Runs `handeye target ...`.
pub fn run(args: TargetArgs) -> anyhow::Result<()> {
    match args.command {
        TargetCommand::Render {
            target,
            output,
            dpi,
            show_frame,
        } => {
            let board = Board::load(&target)?;
            let extension = output
                .extension()
                .map(|e| e.to_string_lossy().to_ascii_lowercase())
                .unwrap_or_default();
            let bytes = match extension.as_str() {
                "png" => board_png(&board, dpi, show_frame)?,
                "svg" => {
                    if show_frame {
                        bail!("--show-frame is only available for PNG output");
                    }
                    board_svg(&board).into_bytes()
                }
                _ => bail!(
                    "output {} must end in .png or .svg, found extension `{extension}`",
                    output.display()
                ),
            };
            write_atomic(&output, &bytes)
                .with_context(|| format!("writing {}", output.display()))?;
            outln!("wrote {}", output.display());
            Ok(())
        }
    }
}
