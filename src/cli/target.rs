//! `handeye target render`: writes a printable board (PNG at a given dpi, SVG in mm, or a vector
//! PDF) at true scale with a scale bar and its parameters in the margin; `--paper` fits the
//! tags to a sheet first and says the tag size to enter in the board file.

use std::path::PathBuf;

use anyhow::{bail, Context};
use clap::{Args, Subcommand, ValueEnum};

use handeye_core::atomic_file::write_atomic;
use handeye_vision::print::{
    board_pdf, board_png, board_svg, fit_to_paper, resized_board_yaml, size_keys, Paper,
};
use handeye_vision::Target;

/// `--paper` values.
#[derive(Debug, Clone, Copy, ValueEnum)]
enum PaperArg {
    /// ISO A4, 210 x 297 mm.
    A4,
    /// US Letter, 8.5 x 11 in.
    Letter,
    /// ISO A3, 297 x 420 mm.
    A3,
}

impl From<PaperArg> for Paper {
    fn from(p: PaperArg) -> Paper {
        match p {
            PaperArg::A4 => Paper::A4,
            PaperArg::Letter => Paper::Letter,
            PaperArg::A3 => Paper::A3,
        }
    }
}

/// Board utilities.
#[derive(Debug, Args)]
pub(super) struct TargetArgs {
    #[command(subcommand)]
    command: TargetCommand,
}

#[derive(Debug, Subcommand)]
enum TargetCommand {
    /// Write a printable board (.pdf, .png or .svg) at true scale.
    Render {
        /// Board YAML: aprilgrid (Kalibr), charuco (OpenCV) or checkerboard.
        #[arg(long = "board", alias = "target")]
        target: PathBuf,
        /// Output file; the extension (.pdf, .png or .svg) picks the format.
        #[arg(short = 'o', long)]
        output: PathBuf,
        /// Scale the board to fill this sheet and print the sizes to enter in the board file
        /// (`tagSize`; `squareLength`/`markerLength`; the spacings) (PDF output: the page is
        /// the sheet).
        #[arg(long, value_enum)]
        paper: Option<PaperArg>,
        /// Blank margin the printer leaves on every side of the sheet, mm (with --paper).
        #[arg(long, default_value_t = 10.0, requires = "paper")]
        margin_mm: f64,
        /// With --paper: also write the board file with the fitted sizes here (use it as the
        /// config's `target`).
        #[arg(long, requires = "paper")]
        board_out: Option<PathBuf>,
        /// Resolution of a PNG, dots per inch.
        #[arg(long, default_value_t = 300.0)]
        dpi: f64,
        /// Overlay the board frame (axes, ids, corner order) for documentation; not for printing.
        #[arg(long)]
        show_frame: bool,
        /// Leave out Kalibr's corner squares (drawn by default, as `kalibr_create_target_pdf`
        /// draws them: a black square of side tagSpacing·tagSize at every tag corner).
        #[arg(long)]
        no_corner_squares: bool,
    },
}

/// Runs `handeye target ...`.
pub(super) fn run(args: TargetArgs) -> anyhow::Result<()> {
    match args.command {
        TargetCommand::Render {
            target,
            output,
            paper,
            margin_mm,
            board_out,
            dpi,
            show_frame,
            no_corner_squares,
        } => {
            let extension = output
                .extension()
                .map(|e| e.to_string_lossy().to_ascii_lowercase())
                .unwrap_or_default();
            if !matches!(extension.as_str(), "pdf" | "png" | "svg") {
                bail!(
                    "output {} must end in .pdf, .png or .svg, found extension `{extension}`",
                    output.display()
                );
            }
            if paper.is_some() && extension != "pdf" {
                // The PDF's page is the sheet; a PNG or SVG page is the board with a caption
                // that may be wider than the sheet.
                bail!(
                    "--paper writes the sheet as a PDF page: use -o {}.pdf",
                    output.with_extension("").display()
                );
            }
            if show_frame && extension != "png" {
                bail!("--show-frame is only available for PNG output");
            }
            let original = match Target::load(&target)? {
                Target::Aprilgrid(board) if no_corner_squares => {
                    Target::Aprilgrid(board.with_corner_squares(false)?)
                }
                other if no_corner_squares => bail!(
                    "--no-corner-squares is for aprilgrids (Kalibr's corner squares); {} is a {}",
                    target.display(),
                    other.describe()
                ),
                other => other,
            };
            let fitted = match paper {
                Some(paper) => Some(fit_to_paper(&original, paper.into(), margin_mm / 1000.0)?),
                None => None,
            };
            let board = fitted.as_ref().map_or(&original, |f| &f.board);
            let bytes = match extension.as_str() {
                "png" => board_png(board, dpi, show_frame)?,
                "svg" => board_svg(board).into_bytes(),
                _ => board_pdf(board, fitted.as_ref().map(|f| &f.sheet))?,
            };
            if let (Some(fitted), Some(board_out)) = (&fitted, &board_out) {
                let text = std::fs::read_to_string(&target)
                    .with_context(|| format!("reading {}", target.display()))?;
                let mut yaml = resized_board_yaml(
                    &text,
                    &target,
                    &fitted.board,
                    "Fitted to the paper by `handeye target render --paper`",
                )?;
                if no_corner_squares && !yaml.lines().any(|l| l.starts_with("corner_squares:")) {
                    yaml.push_str("corner_squares: false # printed with --no-corner-squares\n");
                }
                write_atomic(board_out, yaml.as_bytes())
                    .with_context(|| format!("writing {}", board_out.display()))?;
            }
            write_atomic(&output, &bytes)
                .with_context(|| format!("writing {}", output.display()))?;
            outln!("wrote {}", output.display());
            if let Some(fitted) = &fitted {
                let (w, h) = fitted.sheet.size_m();
                let extent = fitted.board.extent();
                outln!(
                    "fitted to {} {} ({:.0} x {:.0} mm, {} mm margins): board {:.1} x {:.1} mm",
                    fitted.sheet.paper.name(),
                    if fitted.sheet.landscape {
                        "landscape"
                    } else {
                        "portrait"
                    },
                    w * 1000.0,
                    h * 1000.0,
                    margin_mm,
                    (extent.max.x - extent.min.x) * 1000.0,
                    (extent.max.y - extent.min.y) * 1000.0,
                );
                // `tagSize: 0.0265 m` (fitted) / `0.04 m` (the file) / `` `tagSize: 0.0265` ``.
                let (now, was) = (size_keys(&fitted.board), size_keys(&original));
                let join = |sizes: &[(&str, f64)], form: fn(&str, f64) -> String| {
                    let parts: Vec<String> = sizes.iter().map(|&(k, v)| form(k, v)).collect();
                    parts.join(", ")
                };
                let fitted_sizes = join(&now, |k, v| format!("{k}: {v} m"));
                let file_sizes = join(&was, |_, v| format!("{v} m"));
                let to_enter = join(&now, |k, v| format!("`{k}: {v}`"));
                match &board_out {
                    Some(board_out) => outln!(
                        "{fitted_sizes} (the board file says {file_sizes}): wrote {} with it; use it as the config's `target`",
                        board_out.display()
                    ),
                    None => outln!(
                        "{fitted_sizes} (the board file says {file_sizes}): enter {to_enter} in {}",
                        target.display()
                    ),
                }
                outln!(
                    "print at actual size (100 %, not 'fit to page'), then measure the scale bar"
                );
            }
            Ok(())
        }
    }
}
