//! `handeye report`: the HTML report of a solved session (`<session>/report.html`).

use std::path::PathBuf;

use anyhow::Context;
use clap::Args;

use handeye_config::CellConfig;
use handeye_records::result::ResultFile;
use handeye_records::SessionFolder;
use handeye_report::session::write_folder_report;
use handeye_solve::verdict::Verdict;

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
    if handeye_session::cell::cameras::is_cameras_folder(&args.session) {
        super::say_if_live(&args.session)?;
        let path = handeye_report::cameras::write_cameras_folder_report(&args.session)?;
        outln!("report: {}", path.display());
        return Ok(());
    }
    let (path, _) = write(&args.session, args.config)?;
    outln!("report: {}", path.display());
    Ok(())
}

/// Writes the report of the solved session folder `dir` with the board and lens of `config`
/// (default: the one the session was recorded with); returns its path and the verdict
/// `result.yaml` holds. What the page lacks and why is printed as a warning.
pub(super) fn write(
    dir: &std::path::Path,
    config: Option<PathBuf>,
) -> anyhow::Result<(PathBuf, Option<Verdict>)> {
    let folder = SessionFolder::open(dir)?;
    let live = folder.live_run().cloned();
    if let Some(run) = &live {
        // Without a result there is nothing to report yet; the run writes both when it ends.
        anyhow::ensure!(
            folder.result_path().is_file(),
            "session folder {}: {run}; it writes result.yaml and report.html when it ends (`handeye solve {}` gives a provisional answer now)",
            dir.display(),
            dir.display()
        );
        eprintln!(
            "provisional: {run}; this report is of result.yaml as an earlier part of the session wrote it: run `handeye report` again when the run has ended"
        );
    }
    let manifest = folder.read_manifest()?;
    let config_path = config.unwrap_or(manifest.config);
    let config = match CellConfig::load(&config_path).and_then(CellConfig::single_camera) {
        Ok(config) => Some(config),
        Err(e) => {
            eprintln!("warning: {e}; the report will have no thumbnails or reprojection errors");
            None
        }
    };
    let result_path = folder.result_path();
    let result = ResultFile::load(&result_path)
        .context("no usable result (solve the session first: `handeye replay`)")?;
    let mut calibration = result
        .to_calibration(&result_path)
        .context("no usable result (solve the session first: `handeye replay`)")?;
    if let Some(run) = &live {
        // The page's findings say it too.
        calibration
            .notices
            .insert(0, handeye_records::solve::provisional_notice(run));
    }
    // The verdict the solve recorded (a result written before verdicts has none: no card).
    let (path, lacking) = write_folder_report(
        &folder,
        config.as_ref(),
        calibration,
        result.verdict.clone(),
        result.robot_frames.clone().unwrap_or_default(),
        result.kinematics.clone(),
    )?;
    for why in lacking {
        eprintln!("warning: {why}");
    }
    Ok((path, result.verdict))
}
