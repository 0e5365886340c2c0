//! `handeye replay <session>`: detect again in the saved frames, solve again, compare.

use std::path::PathBuf;

use clap::Args;

use handeye_records::result::ResultFile;
use handeye_records::{PoseVisit, SessionFolder};
use handeye_report::session::{write_replay_report, REPLAY_REPORT_FILE};
use handeye_session::cell::replay::{
    beside, replay_session, CameraReplay, ReplayRequest, Replayed,
};

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
    let request = ReplayRequest {
        session: &args.session,
        config: args.config.as_deref(),
        output: args.output.as_deref(),
    };
    let replay = replay_session(request, &mut print_visits)?;
    match &replay.camera {
        Some(camera) => print_camera(&replay, camera)?,
        None => super::cameras::print_result(&replay.result, &replay.output.result),
    }
    // The result is saved; a report problem must not hide it.
    let report = beside(&replay.output.result, REPLAY_REPORT_FILE);
    match write_replay_report(&replay, &report) {
        Ok(report) => outln!("report:  {}", report.display()),
        Err(e) => eprintln!(
            "warning: the report could not be written: {:#}",
            anyhow::Error::from(e)
        ),
    }
    if let Some(camera) = &replay.camera {
        outln!(
            "{}",
            super::run::next_step(
                camera.solved.verdict.as_ref(),
                &replay.output.result,
                super::run::Stack::of(&replay.cell.config.robot)
            )
        );
    }
    Ok(())
}

/// What a one-camera replay prints before its report: the answer, how far it is from the one
/// the run recorded, from the simulator's truth (a simulated cell), and where it was written.
fn print_camera(replay: &Replayed, camera: &CameraReplay) -> anyhow::Result<()> {
    outln!("{}", camera.solved.summary);
    print_difference_from_recorded(&camera.folder, &camera.solved.calibration)?;
    if let Some(truth) = &replay.cell.config.camera().simulation {
        outln!("{}", camera.solved.compare_with_truth(truth));
    }
    outln!();
    outln!("result:  {}", replay.output.result.display());
    Ok(())
}

/// What each saved frame gives when measured again.
fn print_visits(camera: Option<&str>, visits: &[PoseVisit]) {
    if let Some(name) = camera {
        outln!("camera `{name}`:");
    }
    for v in visits {
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
