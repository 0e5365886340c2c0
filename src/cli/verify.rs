//! `handeye verify`: check a calibration against observations it was not solved from — a
//! holdout run on the cell (`--config` + `--result`) or leave-one-out on recorded data
//! (`--session` or `--dataset`).

use std::path::{Path, PathBuf};

use anyhow::{bail, Context};
use clap::Args;

use handeye_config::CellConfig;
use handeye_core::atomic_file::write_atomic;
use handeye_plan::GenerateSpec;
use handeye_records::dataset::Dataset;
use handeye_records::result::CellResult;
use handeye_records::{SessionFolder, SolveInputs, SolvedSession};
use handeye_session::cell::run::{RunObserver, RunRequest, SessionTarget};
use handeye_session::cell::{cameras, config_of_camera_folder, PreparedCell};
use handeye_session::verify;
use handeye_solve::verdict::{self, Accuracy};
use handeye_solve::SolveOptions;

/// Verify a calibration: holdout poses on the cell, or leave-one-out on recorded samples.
#[derive(Debug, Args)]
pub(super) struct VerifyArgs {
    /// The cell config: move the cell to fresh generated poses (needs --result).
    #[arg(long, requires = "result", conflicts_with_all = ["session", "dataset"])]
    config: Option<PathBuf>,
    /// The result.yaml to verify (with --config).
    #[arg(long)]
    result: Option<PathBuf>,
    /// Number of holdout poses.
    #[arg(long, default_value_t = 8)]
    poses: usize,
    /// Seed of the holdout views (default: the plan's seed + 1000, so they differ from the solve's).
    #[arg(long)]
    seed: Option<u64>,
    /// Where to record the holdout session (default: sessions/verify-YYYY-MM-DD_HH-MM-SS, UTC).
    #[arg(short = 'o', long = "output", alias = "out", value_name = "DIR")]
    out: Option<PathBuf>,
    /// Do not ask for confirmation before moving a real robot (holdout on a real cell).
    #[arg(long)]
    yes: bool,
    /// Leave-one-out cross-validation of a session folder's samples (a several-camera
    /// session's: each camera's).
    #[arg(long, conflicts_with = "dataset")]
    session: Option<PathBuf>,
    /// Leave-one-out cross-validation of a dataset file (its setup is in the file).
    #[arg(long)]
    dataset: Option<PathBuf>,
    /// With --session: check the samples as recorded (the robot poses as the controller
    /// reported them, the board poses as measured with the given files), not as the session's
    /// solve judged them (corrected by the arm's model it estimated, or measured again with its
    /// estimate of a file it found wrong): how far those corrections move them.
    #[arg(long, requires = "session")]
    as_recorded: bool,
}

/// Runs `handeye verify`.
pub(super) fn run(args: VerifyArgs) -> anyhow::Result<()> {
    if let Some(config) = &args.config {
        let result = args.result.as_ref().expect("clap requires --result");
        // A result of a session still being recorded: the run holds the arm, and the answer is
        // not its last.
        if let Some(folder) = result.parent() {
            handeye_records::refuse_live(
                folder,
                "verify its result on the cell when the run has ended: the arm is the run's until then",
            )?;
        }
        let cell_config = CellConfig::load(config).context("reading the cell config")?;
        // Each camera's transforms by its name in the config: one camera's result is the
        // config's one camera's; a several-camera result's joint answer names its cameras.
        let solved = CellResult::load(result)?;
        for camera in solved.cameras.iter().filter(|c| c.joint.is_none()) {
            outln!(
                "camera `{}`: not in the joint answer ({}): not checked",
                camera.name,
                camera.left_out.as_deref().unwrap_or("no mount")
            );
        }
        let mut mounts = solved.mounts();
        // A one-camera answer does not name its camera: it is the config's one camera.
        if solved.only_camera().is_some() {
            let one = cell_config
                .clone()
                .single_camera()
                .context("reading the cell config")?;
            mounts[0].0.clone_from(&one.camera().name);
        }
        verify::refuse_files_found_wrong(&solved, result, &mounts, &cell_config)?;
        let base = cell_config.plan.generate.unwrap_or(GenerateSpec {
            count: args.poses,
            distance: [0.4, 0.7],
            max_tilt_deg: 30.0,
            max_roll_deg: 20.0,
            seed: 0,
            image_spread: None,
        });
        let spec = GenerateSpec {
            count: args.poses,
            seed: args.seed.unwrap_or(base.seed + 1000),
            ..base
        };
        let out = args.out.clone().unwrap_or_else(|| {
            handeye_records::dated_session_path(
                Path::new("sessions"),
                "verify-",
                std::time::SystemTime::now(),
            )
        });
        let request = RunRequest {
            config: Some(config.clone()),
            target: SessionTarget::New(out.clone()),
            motion_confirmed: args.yes,
            accept_changed: false,
            stop: super::stop_on_ctrl_c(),
            jobs: None,
        };
        let arm_model = verify::arm_model_of(&solved, result, &cell_config);
        if let Some(file) = &arm_model {
            outln!(
                "the held-out robot poses are corrected by the arm's model in {} (its `kinematics:` section), as the answer's own were",
                file.display()
            );
        }
        let checked = verify::holdout(&request, &mounts, arm_model.as_deref(), &spec, &mut Asker)?;
        for (name, _) in mounts
            .iter()
            .filter(|(n, _)| !checked.iter().any(|(c, _)| c == n))
        {
            outln!(
                "camera `{name}`: saw its board at none of the held-out views: not checked — it was moved or covered since the calibration, or these views fall outside what it sees: look at its frames in {}",
                cameras::camera_folder(&out, name).join("frames").display()
            );
        }
        let accuracy = cell_config.verdict.accuracy();
        let text = if let ([_], [(_, v)]) = (mounts.as_slice(), checked.as_slice()) {
            outln!("{}", v.table());
            outln!("{}", v.verdict(&accuracy).1);
            serde_yaml_ng::to_string(v)?
        } else {
            for (name, v) in &checked {
                outln!("camera `{name}`: {}", v.table());
                outln!("{}", v.verdict(&accuracy).1);
            }
            // A several-camera check: each camera's errors under its name.
            serde_yaml_ng::to_string(
                &checked
                    .iter()
                    .cloned()
                    .collect::<std::collections::BTreeMap<_, _>>(),
            )?
        };
        write_atomic(&out.join("verify.yaml"), text.as_bytes())?;
        outln!("holdout session: {}", out.display());
        return Ok(());
    }
    leave_one_out(&args)
}

/// `verify --session DIR` or `--dataset FILE`: leave-one-out cross-validation of the samples,
/// judged with the session's solver options and accuracy when its config loads (the defaults
/// else).
fn leave_one_out(args: &VerifyArgs) -> anyhow::Result<()> {
    // A listed cell of one camera is its camera's session.
    let session = args.session.as_deref().map(cameras::session_to_read);
    if let Some(root) = session.as_deref().filter(|d| cameras::is_cameras_folder(d)) {
        return verify_cameras_session(root, args.as_recorded);
    }
    if let Some(dir) = &session {
        let folder = SessionFolder::open(dir)?;
        if let Some(run) = folder.live_run() {
            anyhow::ensure!(
                folder.samples_path().is_file(),
                "session folder {}: {run}; no pose has given a sample yet: verify it when the run has recorded some",
                dir.display()
            );
            outln!("provisional: {run}; this check is of the samples so far: verify again when the run has ended");
        }
        let config = judging_config(Some(&folder.read_manifest()?.config));
        let v = check_session(&folder, config.clone(), true, args.as_recorded)?;
        outln!("{}", v.table());
        outln!("{}", v.verdict(&judged_as(config.as_ref()).1).1);
        return Ok(());
    }
    let Some(file) = &args.dataset else {
        bail!("give --config and --result (holdout on the cell), or --session / --dataset (leave-one-out)");
    };
    let dataset = Dataset::load(file)?;
    let (options, accuracy) = judged_as(None);
    let v = verify::leave_one_out(dataset.setup, &dataset.pairs, &options)?;
    outln!("{}", v.table());
    outln!("{}", v.verdict(&accuracy).1);
    Ok(())
}

/// Leave-one-out of the one-camera session `folder` (one camera's folder of a several-camera
/// session too), with its `config`'s solver options: each sample predicted as the session's
/// solve judged them (one figure for one session): the robot poses corrected by the arm's own
/// model when the solve estimated one, each fold fitting it again without its sample; the board
/// poses measured again with the corrected files when the solve found a given one wrong (as
/// recorded they disagree by what the answer corrects). With `recorded_outliers`, the samples
/// the session's own `result.yaml` flags (after its pixel fit) are the ones left out of the RMS,
/// as its held-out figure leaves them out. `as_recorded`: the samples as recorded instead (no
/// solve).
fn check_session(
    folder: &SessionFolder,
    config: Option<CellConfig>,
    recorded_outliers: bool,
    as_recorded: bool,
) -> anyhow::Result<verify::Verification> {
    let dataset = Dataset::load(&folder.samples_path())?;
    let (options, _) = judged_as(config.as_ref());
    let solved = config
        .filter(|_| !as_recorded)
        .and_then(|config| as_solved(folder, config));
    let refit = solved.as_ref().and_then(|s| s.arm_refit.as_ref());
    let pairs = match &solved {
        Some(solved) => {
            if refit.is_some() {
                outln!("the robot poses as the session's solve corrected them with the arm's own model; each left-out sample's fold fits that model again without it");
            }
            if let Some(chosen) = solved.cell_model.as_ref().map(|m| m.summary.chosen) {
                if chosen != handeye_solve::cell_model::Explanation::AsGiven {
                    outln!("the board poses as the session's solve measured them again with its estimate ({}): a given file does not fit the corners; fix it as the session's verdict says (`handeye solve {}`)", chosen.label(), folder.root().display());
                }
            }
            &solved.judged
        }
        None => &dataset.pairs,
    };
    let fold_flanges = refit.map(|r| move |left_out: usize| r.flanges_without(left_out));
    let v = verify::leave_one_out_refitting(
        dataset.setup,
        pairs,
        &options,
        fold_flanges.as_ref().map(|f| f as verdict::FoldFlanges<'_>),
    )?;
    // Only a final answer of these very samples (not a run's earlier one, nor that of a
    // resumed session not solved since).
    if recorded_outliers && folder.live_run().is_none() {
        let recorded = CellResult::load(&folder.result_path()).ok();
        if let Some(result) = recorded.as_ref().and_then(CellResult::only_camera) {
            if result.residuals.samples.len() == dataset.pairs.len() {
                return Ok(v.with_outliers(result.outliers.clone()));
            }
        }
    }
    Ok(v)
}

/// The session's config (`config`, the file its manifest records; a dataset file has none),
/// when it loads. When it does not (moved, edited since) the defaults judge, and the reason is
/// said: a verdict against another accuracy than the cell's must not look like the cell's.
fn judging_config(config: Option<&Path>) -> Option<CellConfig> {
    match CellConfig::load(config?) {
        Ok(c) => Some(c),
        Err(e) => {
            let accuracy = Accuracy::default();
            eprintln!(
                "note: the config the session recorded does not load ({e}): judged with the default solver options and accuracy ({} mm, {}°), not the cell's",
                accuracy.translation_mm, accuracy.rotation_deg
            );
            None
        }
    }
}

/// The solver options and accuracy of the cell's config, whatever its number of cameras (both
/// are the cell's sections); the defaults without one.
fn judged_as(config: Option<&CellConfig>) -> (SolveOptions, Accuracy) {
    config.map_or_else(Default::default, |c| {
        (c.solver.to_options(), c.verdict.accuracy())
    })
}

/// The one-camera session `folder` solved as `handeye solve` solves it, writing nothing
/// (`solve_unwritten`): `None` when it cannot be (intrinsics to estimate, a file missing, a
/// solve that fails; said in a note), and the samples are checked as recorded.
fn as_solved(folder: &SessionFolder, config: CellConfig) -> Option<SolvedSession> {
    let solved = config_of_camera_folder(config, folder.root())
        .map_err(anyhow::Error::from)
        .and_then(|config| Ok(SolveInputs::load(config)?))
        .and_then(|inputs| {
            let space = inputs.config.solver.space;
            handeye_records::solve_unwritten(folder, &inputs, space)
                .transpose()
                .map_err(anyhow::Error::from)
        });
    match solved {
        Ok(solved) => solved.map(|(solved, _)| solved),
        Err(e) => {
            eprintln!(
                "note: the session's solve failed ({e:#}): its samples are checked as recorded"
            );
            None
        }
    }
}

/// `verify --session ROOT` of a several-camera session: each camera's samples by leave-one-out
/// as for one camera (a camera's folder is a one-camera session of the same poses), with the
/// cell's solver options and accuracy; a camera with too few samples is named and the others
/// checked.
fn verify_cameras_session(root: &Path, as_recorded: bool) -> anyhow::Result<()> {
    super::say_if_live(root)?;
    let manifest = cameras::read_manifest(root)?;
    let config = judging_config(Some(&manifest.config));
    let accuracy = judged_as(config.as_ref()).1;
    for camera in &manifest.cameras {
        let folder = SessionFolder::open(&cameras::camera_folder(root, &camera.name))?;
        if !folder.samples_path().is_file() {
            outln!("camera `{}`: no samples recorded", camera.name);
            continue;
        }
        // Its answer is the joint one: the outliers are those of the camera's own solve.
        match check_session(&folder, config.clone(), false, as_recorded) {
            Ok(v) => {
                outln!("camera `{}`: {}", camera.name, v.table());
                outln!("{}", v.verdict(&accuracy).1);
            }
            Err(e) => outln!("camera `{}`: {e}", camera.name),
        }
    }
    Ok(())
}

/// The holdout run's observer: it asks before a real arm moves and passes notes on; the poses
/// themselves are summarised in the table at the end.
struct Asker;

impl RunObserver for Asker {
    fn confirm_motion(
        &mut self,
        cell: &PreparedCell,
        poses: usize,
    ) -> Result<(), Box<dyn std::error::Error + Send + Sync>> {
        super::confirm_motion(cell, poses).map_err(Into::into)
    }

    fn note(&mut self, message: &str) {
        eprintln!("note: {message}");
    }
}
