//! `handeye replay <session>`: detect again in the saved frames, solve again, compare.

use std::path::PathBuf;

use anyhow::Context;
use clap::Args;

use handeye::report::session::{write_replay_report, Optics, REPLAY_REPORT_FILE};
use handeye_core::camera_model::CameraModel;
use handeye_session::cell;
use handeye_session::config::SolveSpace;
use handeye_session::result::ResultFile;
use handeye_session::session::replay::{beside, REPLAY_ESTIMATES_FOLDER, REPLAY_RESULT_FILE};
use handeye_session::session::{self, replay, SessionFolder};

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
    let mut config =
        handeye_session::config::CellConfig::load(config_path).context("preparing the cell")?;
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
    session::refuse_live(
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
        let file = folder.root().join(session::solve::CAMERA_INFO_FILE);
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
    let mut solved = solve_replayed(
        &folder,
        &prepared,
        &config_path,
        &camera_model,
        &dataset,
        &visits,
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
    let written = session::solve::write_corrected_files(&estimates, &solved, &prepared.config)?;
    session::solve::record_written(&mut solved, &written);
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

/// The replayed dataset solved and judged as a run's solve does: intrinsics that do not fit the
/// frames named (their estimate written into the session), also when they let too few poses
/// through, and the camera driver's calibration a ROS 2 run kept compared with the file.
fn solve_replayed(
    folder: &SessionFolder,
    prepared: &cell::PreparedCell,
    config_path: &std::path::Path,
    camera_model: &CameraModel,
    dataset: &handeye_session::dataset::Dataset,
    visits: &[session::PoseVisit],
) -> anyhow::Result<session::solve::SolvedSession> {
    // Both answers (pose space and, by default, reprojection space) side by side.
    let vision = (prepared.config.solver.space == SolveSpace::Reprojection)
        .then_some((&prepared.camera().board, camera_model));
    // Intrinsics that do not fit the frames are named here as in a run (the estimate written
    // into the session), also when they made every pose fail.
    let wrong = if prepared.camera().intrinsics_known {
        session::solve::check_intrinsics(
            folder,
            dataset.setup,
            visits,
            &prepared.camera().board,
            camera_model,
            &prepared.config,
        )?
    } else {
        None
    };
    let intrinsics_file = prepared
        .config
        .camera()
        .intrinsics
        .clone()
        .unwrap_or_default();
    // The camera driver's own calibration a ROS 2 run kept, against the config's file.
    let driver = session::solve::driver_calibration_notice(
        folder,
        &prepared.config,
        camera_model,
        visits,
        &prepared.camera().board,
    );
    if let (Some(w), true) = (&wrong, dataset.pairs.is_empty()) {
        let (reason, next) = session::solve::with_driver_calibration(
            w.reason(&intrinsics_file),
            w.next_action(folder.root(), config_path),
            driver.as_ref(),
        );
        anyhow::bail!(
            "every pose of {} was rejected: {reason}\nnext: {next}",
            folder.root().display(),
        );
    }
    let notices = wrong
        .iter()
        .map(|w| w.notice(&intrinsics_file, folder.root(), config_path))
        .chain(driver.clone())
        .collect();
    let solved = session::solve::solve_with_arm(
        dataset,
        visits,
        &folder.read_manifest()?.plan,
        vision,
        &prepared.config,
        notices,
    );
    let solved = match (solved, &wrong) {
        // The few poses the intrinsics let through could not be solved: the intrinsics are the
        // cause to name, as a run's solve does.
        (Err(session::SessionError::Solve { source, .. }), Some(w)) => {
            return Err(w
                .few_samples_error(
                    folder.root(),
                    &intrinsics_file,
                    config_path,
                    dataset.pairs.len(),
                    visits.len(),
                    source.to_string(),
                    driver.as_ref(),
                )
                .into())
        }
        (solved, _) => solved?,
    };
    Ok(solved)
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
