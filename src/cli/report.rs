//! `handeye report`: the HTML report of a solved session (`<session>/report.html`).

use std::path::PathBuf;

use clap::Args;

use handeye_report::session::write_folder_report;

/// Write the calibration report of a solved session folder.
#[derive(Debug, Args)]
pub(super) struct ReportArgs {
    /// The session folder (with result.yaml).
    session: PathBuf,
    /// The cell config (default: the one the session was recorded with), for the board and
    /// intrinsics that draw the thumbnails.
    #[arg(long)]
    config: Option<PathBuf>,
}

/// Runs `handeye report`.
pub(super) fn run(args: ReportArgs) -> anyhow::Result<()> {
    let written = write_folder_report(&args.session, args.config.as_deref())?;
    if let Some(run) = &written.provisional {
        eprintln!(
            "provisional: {run}; this report is of result.yaml as an earlier part of the session wrote it: run `handeye report` again when the run has ended"
        );
    }
    for why in &written.lacking {
        eprintln!("warning: {why}");
    }
    outln!("report: {}", written.path.display());
    Ok(())
}
