//! `handeye replay <session>`: detect again in the saved frames, solve again, compare.

use std::path::PathBuf;

use anyhow::Context;
use clap::Args;

use handeye_core::camera_model::CameraModel;
use handeye_records::result::ResultFile;
use handeye_records::SessionFolder;
use handeye_report::session::{write_replay_report, Optics, REPLAY_REPORT_FILE};
use handeye_session::cell;
use handeye_session::replay;
use handeye_session::replay::{beside, REPLAY_ESTIMATES_FOLDER, REPLAY_RESULT_FILE};

/// Re-detect the board in a session's frames and solve again offline.
#[derive(Debug, Args)]
pub(super) struct ReplayArgs {
    /// The session folder.
    session: PathBuf,
    /// Use this cell config instead of the one the session was run with.
    #[arg(long)]
    config: Option<PathBuf>,
    /// Where to write the replayed result (default: <session>/replay-result.yaml); its report
    /// (replay-report.html) and the estimates of wrong files (replay-estimates/) go beside it.
    /// A replay never writes over what the run recorded.
    #[arg(short, long)]
    output: Option<PathBuf>,
}

/// The cell of `config_path` as the session `folder` recorded it: intrinsics a run read from
/// the camera driver's topic are the session's (no driver needed); the shipped placeholder lens
/// is refused.
fn prepare_for(
    folder: &SessionFolder,
    config_path: &std::path::Path,
) -> anyhow::Result<cell::PreparedCell> {
    let mut config = handeye_config::CellConfig::load(config_path).context("preparing the cell")?;
    let from_topic = folder.root().join(cell::INTRINSICS_FROM_TOPIC_FILE);
    if config.camera().intrinsics.is_none() && from_topic.is_file() {
        config.camera_mut().intrinsics = Some(from_topic);
    }
    let prepared = cell::prepare_config(config).context("preparing the cell")?;
    if let Some((file, name)) = prepared.placeholder_intrinsics() {
        anyhow::bail!(
            "{}: the intrinsics are the shipped placeholder (camera_name: {name}), not this camera's calibration; point `intrinsics:` in {} at the camera's calibration (or at {}/camera_info.yaml when a solve estimated them), or drop `intrinsics:`",
            file.display(),
            config_path.display(),
            folder.root().display()
        );
    }
    Ok(prepared)
}

/// Runs `handeye replay`.
pub(super) fn run(args: ReplayArgs) -> anyhow::Result<()> {
    // The run writes the files a replay writes (the report, the estimates of a blamed file).
    handeye_records::refuse_live(
        &args.session,
        &format!(
            "replay it when the run has ended (`handeye solve {}` gives a provisional answer meanwhile)",
            args.session.display()
        ),
    )?;
    if cell::rig::is_rig_folder(&args.session) {
        return super::rig::replay(
            &args.session,
            args.config.as_deref(),
            args.output.as_deref(),
        );
    }
    let folder = SessionFolder::open(&args.session)?;
    let manifest = folder.read_manifest()?;
    let config_path = args
        .config
        .clone()
        .unwrap_or_else(|| manifest.config.clone());
    let prepared = prepare_for(&folder, &config_path)?;
    // The frames were taken in the session's layout: solving them as the other one gives an
    // answer of the wrong unknowns (a camera "on the flange" metres away).
    anyhow::ensure!(
        prepared.config.camera().setup == manifest.setup,
        "session {} was recorded as {}, but {} describes a {} cell: replay it with the config it was recorded with",
        folder.root().display(),
        manifest.setup,
        config_path.display(),
        prepared.config.camera().setup
    );
    // A cell without configured intrinsics replays with the ones its run estimated.
    let camera_model = if prepared.camera().intrinsics_known {
        prepared.camera().camera_model
    } else {
        let file = folder.root().join(handeye_records::solve::CAMERA_INFO_FILE);
        CameraModel::load(&file).context(
            "the config has no intrinsics and the session has no estimated ones: solve the session first",
        )?
    };
    let (dataset, visits) = replay::redetect(
        &folder,
        &prepared.camera().board,
        &camera_model,
        prepared.detector_options(),
        prepared.config.session.max_reprojection_rms_px,
    )?;
    for v in &visits {
        match (&v.rejected, v.reprojection_rms_px) {
            (None, Some(rms)) => outln!(
                "pose {:>3}: {} tags, board RMS {rms:.3} px",
                v.plan_index,
                v.tags
            ),
            (Some(why), _) => outln!("pose {:>3}: skipped: {why}", v.plan_index),
            _ => {}
        }
    }
    // Solved and judged as a run's solve is: the checks of the given files included.
    let samples = if dataset.pairs.is_empty() {
        Err(handeye_records::solve::no_samples(&folder, &visits))
    } else {
        Ok(dataset)
    };
    let (mut solved, dataset) = handeye_records::solve::solve_records(
        &folder,
        &folder.read_manifest()?,
        samples,
        &visits,
        &visits,
        (&prepared.camera().board, &camera_model),
        prepared.config.solver.space,
        &prepared.config,
    )?;
    let output = args
        .output
        .unwrap_or_else(|| folder.root().join(REPLAY_RESULT_FILE));
    // `-o` into a folder that does not exist yet makes it, as a several-camera replay does.
    if let Some(parent) = output.parent().filter(|p| !p.as_os_str().is_empty()) {
        std::fs::create_dir_all(parent)
            .with_context(|| format!("{}: cannot make the folder", parent.display()))?;
    }
    // The estimates of a file the cell model blames, beside the replay's result (the run's own
    // stay as they were).
    let estimates = beside(&output, REPLAY_ESTIMATES_FOLDER);
    let written =
        handeye_records::solve::write_corrected_files(&estimates, &solved, &prepared.config)?;
    handeye_records::solve::record_written(&mut solved, &written);
    solved.name_replay(folder.root(), &estimates, &prepared.config);
    let calibration = &solved.calibration;
    solved
        .result_file(&dataset.pairs, &prepared.config)
        .save(&output)?;
    outln!("{}", solved.summary);
    print_difference_from_recorded(&folder, calibration)?;
    if let Some(truth) = &prepared.config.camera().simulation {
        outln!("{}", solved.compare_with_truth(truth));
    }
    outln!();
    outln!("result:  {}", output.display());
    let optics = Optics {
        board: &prepared.camera().board,
        camera: &camera_model,
    };
    let report = beside(&output, REPLAY_REPORT_FILE);
    match write_replay_report(
        &folder,
        &report,
        &solved,
        optics,
        Some(prepared.config.camera().nominal),
        prepared.config.robot.frames(),
    ) {
        Ok(report) => outln!("report:  {}", report.display()),
        // The result is saved; a report problem must not hide it.
        Err(e) => eprintln!(
            "warning: the report could not be written: {:#}",
            anyhow::Error::from(e)
        ),
    }
    outln!(
        "{}",
        super::run::next_step(
            solved.verdict.as_ref(),
            &output,
            super::run::Stack::of(&prepared.config.robot)
        )
    );
    Ok(())
}

/// How far the replayed answer is from the one the run recorded (when it recorded one).
fn print_difference_from_recorded(
    folder: &SessionFolder,
    calibration: &handeye_solve::Calibration,
) -> anyhow::Result<()> {
    if !folder.result_path().is_file() {
        return Ok(());
    }
    let recorded = ResultFile::load_mounts(&folder.result_path())?;
    let then = [recorded.camera_mount, recorded.target_mount];
    for ((key, now), then) in calibration.unknowns().iter().zip(then.iter()) {
        outln!(
            "{key}: replay differs from the recorded result by {:.4} mm, {:.5}°",
            (now.translation.vector - then.translation.vector).norm() * 1e3,
            now.rotation.angle_to(&then.rotation).to_degrees()
        );
    }
    Ok(())
}
