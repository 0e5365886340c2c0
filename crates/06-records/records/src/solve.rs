//! Solving a session folder: `samples.yaml` and the recorded corners (`poses/NNN.yaml`) in,
//! `result.yaml` out (and `reprojection.yaml`, `camera_info.yaml` when they apply): the pose-space
//! solve, the reprojection-space refinement over the recorded corners, and the intrinsics
//! estimated from scratch when the config has none.
//!
//! The summary for people (both answers side by side, the ground-truth check in the simulated
//! cell) and the `reprojection.yaml` shape live in `summary`, re-exported here. Depends on
//! `solve`, `config`, `dataset`, `result`, `vision` and the ground floor; the folder's reading
//! and writing go through `SessionFolder`.

mod arm;
mod driver_calibration;
mod intrinsics_check;
mod summary;

pub use arm::{
    dh_chain, estimate_arm, given_arm_model, plan_observability, ArmChoice, ArmEstimate, Corrected,
};
pub use driver_calibration::{
    driver_calibration_notice, with_driver_calibration, DRIVER_CALIBRATION_FILE,
};
pub use intrinsics_check::{check_intrinsics, WrongIntrinsics};

pub use summary::{FrameRms, ReprojectionSummary};

use crate::dataset::Dataset;
use crate::result::ResultFile;
use handeye_config::{CellConfig, KinematicsChoice, SolveSpace};
use handeye_core::camera_model::CameraModel;
use handeye_core::notice::{Notice, NoticeKind};
use handeye_core::setup::{PosePair, Setup};
use handeye_solve::cell_model::{self, fit_cell_model, CellModel, Explanation};
use handeye_solve::verdict::{self, FoldFlanges, Verdict};
use handeye_solve::{
    self as solve, refine_reprojection, reprojection_errors, ArmOffsetsFree, Calibration, Corner,
    Frame, ReprojectionCalibration, ReprojectionErrors, ReprojectionOptions, RobotPrior,
    SolveOptions,
};
use handeye_vision::Target;

use super::{PoseVisit, SessionError, SessionFolder};

/// A solved session.
pub struct SolvedSession {
    /// The final calibration (the reprojection-space answer when it was computed).
    pub calibration: Calibration,
    /// The pose-space answer (also the start of the reprojection refinement).
    pub pose_space: Calibration,
    /// The reprojection-space answer, when the space is `reprojection` and frames had corners.
    pub reprojection: Option<ReprojectionCalibration>,
    /// The pose-space answer's reprojection errors on the same frames (same order as
    /// `reprojection.errors`), for the side-by-side comparison.
    pub pose_space_errors: Option<ReprojectionErrors>,
    /// Ids (`pose-NNN`) of the frames the reprojection refinement used, in its order.
    pub frame_ids: Vec<String>,
    /// The intrinsics estimated from the run (config without `intrinsics`), also written to the
    /// session's `camera_info.yaml`.
    pub estimated_camera: Option<CameraModel>,
    /// A short human summary.
    pub summary: String,
    /// GOOD / CHECK / REDO and why, from the same figures the result file and report show.
    pub verdict: Option<Verdict>,
    /// The cell model's choice between the files as given and a wrong intrinsics or board file
    /// (when the corners were fitted): the answer uses its estimates, and
    /// [`write_corrected_files`] writes them into the session.
    pub cell_model: Option<CellModel>,
    /// What it was solved from, as read once: the report renders these, it reads nothing again.
    pub evidence: Evidence,
    /// The arm's own model estimated with the transforms (`solver.kinematics: joint_offsets`):
    /// the samples and visits above are corrected by it.
    pub arm: Option<ArmEstimate>,
    /// The pose pairs the verdict judged (its held-out check predicts each from the others):
    /// the samples as solved (robot poses corrected by `arm`), with the board poses measured
    /// again with the corrected files when the cell model found a given one wrong. A check of
    /// the session (`verify --session`) predicts these, so that its figure is the verdict's.
    pub judged: Vec<PosePair>,
    /// The arm's model fit as made, to be made again without one sample: the verdict's held-out
    /// folds refit it (fitted to the left-out sample too, the model would predict it partly
    /// from itself), and so does a check of the session. `None` when the robot poses are the
    /// arm's own, or corrected by a model given as a file (nothing refitted).
    pub arm_refit: Option<handeye_solve::kinematics::ArmRefit>,
}

/// What a session was solved from: its samples (`samples.yaml`) and its pose records
/// (`poses/NNN.yaml`, with the corners and frames), as the solve read them.
#[derive(Debug, Clone, Default)]
pub struct Evidence {
    /// The pose pairs solved, ids `pose-NNN`.
    pub pairs: Vec<PosePair>,
    /// Every visited pose's record.
    pub visits: Vec<PoseVisit>,
}

/// What solving a session needs besides its folder: the board and the intrinsics, loaded once
/// (by the prepared cell, see `cell::PreparedCell::solve_inputs`, or by [`SolveInputs::load`]),
/// and the config's solver settings.
#[derive(Debug, Clone)]
pub struct SolveInputs {
    /// The cell config: solver settings and the robot's repeatability.
    pub config: CellConfig,
    /// The board the frames show.
    pub board: Target,
    /// The intrinsics; `None` when the config has none and they are estimated from the corners.
    pub camera: Option<CameraModel>,
}

impl SolveInputs {
    /// Loads the board and the intrinsics (when the config names them) of `config`.
    pub fn load(config: CellConfig) -> Result<SolveInputs, SessionError> {
        let board =
            Target::load(&config.camera().target).map_err(|source| SessionError::Board {
                file: config.camera().target.clone(),
                source: Box::new(source),
            })?;
        let camera = match &config.camera().intrinsics {
            Some(file) => {
                Some(
                    CameraModel::load(file).map_err(|source| SessionError::Intrinsics {
                        file: file.clone(),
                        source: Box::new(source),
                    })?,
                )
            }
            None => None,
        };
        Ok(SolveInputs {
            config,
            board,
            camera,
        })
    }
}

impl SolvedSession {
    /// The answer of `pose_space` alone, before the rest of a solve fills in what it computes.
    fn of_pose_space(pose_space: Calibration) -> SolvedSession {
        SolvedSession {
            calibration: pose_space.clone(),
            pose_space,
            reprojection: None,
            pose_space_errors: None,
            frame_ids: Vec::new(),
            estimated_camera: None,
            summary: String::new(),
            verdict: None,
            cell_model: None,
            evidence: Evidence::default(),
            arm: None,
            judged: Vec::new(),
            arm_refit: None,
        }
    }

    /// Names the session folder, the cell config, its board and intrinsics files in the
    /// verdict's advice and the summary (the verdict's rules know none of them: see
    /// `verdict::SessionFiles`), for a replay of `session` whose estimates of wrong files went
    /// into `estimates` (beside its output: a replay writes nothing into the session).
    pub fn name_replay(
        &mut self,
        session: &std::path::Path,
        estimates: &std::path::Path,
        config: &CellConfig,
    ) {
        self.name_files([session, estimates], config, &|path| path.to_path_buf());
    }

    /// The files named as in [`SolvedSession::name_replay`] for a run's session in `folder`
    /// (its estimates written into it), naming it and the files in it where a person will
    /// find them ([`SessionFolder::shown`]).
    pub fn name_session_in(&mut self, folder: &SessionFolder, config: &CellConfig) {
        let shown = folder.shown_root();
        self.name_files([shown, shown], config, &|path| folder.shown(path));
    }

    fn name_files(
        &mut self,
        [session, estimates]: [&std::path::Path; 2],
        config: &CellConfig,
        shown: &dyn Fn(&std::path::Path) -> std::path::PathBuf,
    ) {
        let name = |path: &std::path::Path| shown(path).display().to_string();
        let files = verdict::SessionFiles {
            session: session.display().to_string(),
            estimates: estimates.display().to_string(),
            config: name(&config.file),
            board: name(&config.camera().target),
            intrinsics: config
                .camera()
                .intrinsics
                .as_deref()
                .map(name)
                .unwrap_or_default(),
        };
        if let Some(verdict) = &mut self.verdict {
            verdict.name_session(&files);
        }
        self.summary = files.fill(&self.summary);
    }

    /// The result file of this answer (`pairs`: the samples it was solved from, for their ids),
    /// with its verdict first and the frames `config`'s arm reports its poses in.
    pub fn result_file(&self, pairs: &[PosePair], config: &CellConfig) -> ResultFile {
        let mut file = ResultFile::from_calibration(&self.calibration, pairs)
            .with_robot_frames(config.robot.frames());
        if let Some(arm) = &self.arm {
            file = file.with_kinematics(arm.result_section());
        }
        match &self.verdict {
            Some(verdict) => file.with_verdict(verdict.clone()),
            None => file,
        }
    }
}

/// The samples `pairs` of the session `folder`, each robot pose corrected by the arm's model the
/// result file `file` holds (its `kinematics:` section, applied as `solver.arm_model` applies
/// it to a session it solves): what a held-out check of that result predicts, since the answer
/// was solved with the arm where that model puts it, not where its published model does.
pub fn corrected_by_arm_model(
    file: &std::path::Path,
    config: &CellConfig,
    folder: &SessionFolder,
    pairs: &[PosePair],
) -> Result<Vec<PosePair>, SessionError> {
    let plan = folder.read_manifest()?.plan;
    let visits = folder.read_visits()?;
    let (corrected, _, _) = arm::apply_given_model(file, config, &plan, pairs, &visits)?;
    Ok(corrected)
}

/// Solves the folder with the config's solver settings (`solver.space`) and writes `result.yaml`.
pub fn solve_folder(
    folder: &SessionFolder,
    inputs: &SolveInputs,
) -> Result<SolvedSession, SessionError> {
    solve_folder_in(folder, inputs, inputs.config.solver.space)
}

/// Solves the folder in the given space and writes `result.yaml`.
pub fn solve_folder_in(
    folder: &SessionFolder,
    inputs: &SolveInputs,
    space: SolveSpace,
) -> Result<SolvedSession, SessionError> {
    let (solved, dataset) = load_and_solve(folder, inputs, space)?;
    solved
        .result_file(&dataset.pairs, &inputs.config)
        .save(&folder.result_path())?;
    if let Some(summary) = solved.reprojection_summary() {
        handeye_core::yaml_file::write_yaml(&summary, &folder.root().join(REPROJECTION_FILE))?;
    }
    Ok(solved)
}

/// Reads the folder's samples and visits and solves (in the reprojection space with the inputs'
/// board and intrinsics); writes nothing, except `camera_info.yaml` and `samples.yaml` (the board
/// poses by PnP with those intrinsics) when the intrinsics are estimated. Returns the dataset the
/// answer was solved from.
///
/// When the config has no intrinsics they are estimated from the recorded corners (whatever
/// `space` says: without intrinsics there are no board poses to solve in pose space alone).
pub fn load_and_solve(
    folder: &SessionFolder,
    inputs: &SolveInputs,
    space: SolveSpace,
) -> Result<(SolvedSession, Dataset), SessionError> {
    let (mut solved, dataset) = solve_loaded(folder, inputs, space)?;
    solved.name_session_in(folder, &inputs.config);
    if let Some(run) = folder.live_run() {
        solved
            .calibration
            .notices
            .insert(0, provisional_notice(run));
    }
    Ok((solved, dataset))
}

/// What a solve of a session a run is still recording says first (and its result file holds).
pub fn provisional_notice(run: &super::LiveRun) -> Notice {
    Notice::warning(
        NoticeKind::Provisional,
        format!(
            "provisional: {run}; this answer is of the samples recorded when it was solved: solve again when the run has ended"
        ),
    )
}

fn solve_loaded(
    folder: &SessionFolder,
    inputs: &SolveInputs,
    space: SolveSpace,
) -> Result<(SolvedSession, Dataset), SessionError> {
    let Some(camera) = &inputs.camera else {
        // Every visit with corners goes through `frames_from_visits`, which checks them.
        return solve_from_scratch(folder, &inputs.config, &inputs.board);
    };
    let (mut solved, dataset) = solve_with_lens(folder, inputs, camera, space)?;
    let written = write_corrected_files(folder.root(), &solved, &inputs.config)?;
    // Named where a person finds them (an import's staging folder is renamed into place).
    let shown: Vec<_> = written.iter().map(|p| folder.shown(p)).collect();
    record_written(&mut solved, &shown);
    Ok((solved, dataset))
}

/// The session solved and judged as [`load_and_solve`] solves it when its intrinsics are given,
/// writing nothing into it (the estimates of files it finds wrong stay in the answer): what a
/// check of a session reads, `verify --session` (its samples as the solve saw them: corrected by
/// the arm's own model when the solve estimated one, [`SolvedSession::arm_refit`]). `None`
/// without intrinsics: they would be estimated, and that solve writes its board poses.
pub fn solve_unwritten(
    folder: &SessionFolder,
    inputs: &SolveInputs,
    space: SolveSpace,
) -> Option<Result<(SolvedSession, Dataset), SessionError>> {
    let camera = inputs.camera.as_ref()?;
    Some(solve_with_lens(folder, inputs, camera, space))
}

fn solve_with_lens(
    folder: &SessionFolder,
    inputs: &SolveInputs,
    camera: &CameraModel,
    space: SolveSpace,
) -> Result<(SolvedSession, Dataset), SessionError> {
    let config = &inputs.config;
    let visits = folder.read_visits()?;
    // Checked here too: the pose-space space uses no corners, but the report draws them.
    for visit in &visits {
        visit.check_corners_on_board(&folder.visit_path(visit.plan_index), &inputs.board)?;
    }
    let manifest = folder.read_manifest()?;
    // With the rejected records an adaptive or hand-guided plan kept aside (their index reused).
    let mut seen = visits.clone();
    seen.extend(folder.read_rejected_visits()?);
    let samples = committed_samples(folder, &visits);
    solve_records(
        folder,
        &manifest,
        samples,
        &visits,
        &seen,
        (&inputs.board, camera),
        space,
        config,
    )
}

/// A session's records solved and judged with the checks of its given files, as every solve of
/// a session makes them — a run's (its committed records) and a replay's (its frames detected
/// again): intrinsics that do not fit the frames `seen` are named (their estimate written into
/// the session), also when they rejected every pose (`samples` is then the error saying so) or
/// let too few through to solve; the camera driver's calibration a ROS 2 run kept is compared
/// with the intrinsics file; then [`solve_with_arm`].
#[allow(clippy::too_many_arguments)]
pub fn solve_records(
    folder: &SessionFolder,
    manifest: &super::SessionManifest,
    samples: Result<Dataset, SessionError>,
    visits: &[PoseVisit],
    seen: &[PoseVisit],
    (board, camera): (&Target, &CameraModel),
    space: SolveSpace,
    config: &CellConfig,
) -> Result<(SolvedSession, Dataset), SessionError> {
    let wrong = check_intrinsics(folder, manifest.setup, seen, board, camera, config)?;
    let intrinsics_file = folder.shown(&config.camera().intrinsics.clone().unwrap_or_default());
    let config_file = folder.shown(&config.file);
    // A ROS 2 driver's own calibration, kept by the run, against the config's file: a finding
    // of the verdict, so it goes in before the solve judges.
    let driver = driver_calibration_notice(folder, config, camera, seen, board);
    let dataset = match (samples, &wrong) {
        (
            Err(SessionError::NoSamples {
                folder: root,
                visited,
                reasons,
            }),
            Some(w),
        ) => {
            let (reason, next) = with_driver_calibration(
                w.reason(&intrinsics_file),
                w.next_action(&root, &config_file),
                driver.as_ref(),
            );
            return Err(SessionError::WrongIntrinsics {
                visited: visited.max(seen.len()),
                first: reasons.split("; ").next().unwrap_or_default().to_string(),
                reason,
                next,
                folder: root,
            });
        }
        (samples, _) => samples?,
    };
    let vision = (space == SolveSpace::Reprojection).then_some((board, camera));
    let notices = wrong
        .iter()
        .map(|w| w.notice(&intrinsics_file, folder.shown_root(), &config_file))
        .chain(driver.clone())
        .collect();
    let solved = solve_with_arm(&dataset, visits, &manifest.plan, vision, config, notices);
    let solved = match (solved, &wrong) {
        // The few poses the intrinsics let through could not be solved: the intrinsics are
        // the cause to name (an adaptive plan that kept 2 of 60 poses).
        (Err(SessionError::Solve { source, .. }), Some(w)) => {
            return Err(w.few_samples_error(
                folder.shown_root(),
                &intrinsics_file,
                &config_file,
                dataset.pairs.len(),
                seen.len(),
                source.to_string(),
                driver.as_ref(),
            ));
        }
        (solved, _) => solved?,
    };
    // What the input said about itself (a bag's tolerated lies): beside the solver's notices in
    // every solve of the session, after the verdict (they describe the input, not the answer).
    let mut solved = solved;
    solved.calibration.notices.extend(folder.input_notices()?);
    Ok((solved, dataset))
}

/// The error of `folder`'s `visits` none of which gave a sample, with the first rejections.
pub fn no_samples(folder: &SessionFolder, visits: &[PoseVisit]) -> SessionError {
    let reasons = visits
        .iter()
        .take(3)
        .map(|v| {
            format!(
                "pose {}: {}",
                v.plan_index,
                v.rejected.as_deref().unwrap_or("no board pose")
            )
        })
        .chain((visits.len() > 3).then(|| "...".to_string()))
        .collect::<Vec<_>>()
        .join("; ");
    SessionError::NoSamples {
        folder: folder.root().to_path_buf(),
        visited: visits.len(),
        reasons: if reasons.is_empty() {
            "no pose was visited".into()
        } else {
            reasons
        },
    }
}

/// `dataset` (its `visits`, taken at the poses of `plan`) solved with the arm's own model as
/// `config` asks (`solver.kinematics`, [`estimate_arm`]: the rest of the solve then sees the
/// corrected robot poses, and the choice is a notice) and judged; a run's solve and a replay
/// both solve through it.
///
/// With `auto` a cell whose data choose the arm's model is solved both ways, and the arm's
/// answer is kept unless its verdict contradicts a given file or convention: a board printed
/// at 105 % or a lens file off leaves systematic
/// residuals that joint offsets partly absorb (the file is then the cause to name, and its fix
/// comes first), while an arm's own errors can look like a wrong lens to the corners until the
/// robot poses are corrected.
pub fn solve_with_arm(
    dataset: &Dataset,
    visits: &[PoseVisit],
    plan: &[super::PlannedPose],
    vision: Option<(&Target, &CameraModel)>,
    config: &CellConfig,
    mut notices: Vec<Notice>,
) -> Result<SolvedSession, SessionError> {
    let solve = |pairs: &[PosePair],
                 visits: &[PoseVisit],
                 notices: Vec<Notice>,
                 arm: Option<(FoldFlanges<'_>, &ArmOffsetsFree)>| {
        solve_session_with(dataset.setup, pairs, visits, vision, config, notices, arm)
    };
    // An arm model an earlier session estimated: applied as it is, nothing estimated again.
    if let Some(file) = &config.solver.arm_model {
        let (pairs, visits, notice) =
            arm::apply_given_model(file, config, plan, &dataset.pairs, visits)?;
        notices.push(notice);
        return solve(&pairs, &visits, notices, None);
    }
    let ArmChoice {
        corrected,
        notice: arm_choice,
        links,
    } = estimate_arm(dataset.setup, config, plan, &dataset.pairs, visits)?;
    let Some(mut corrected) = corrected else {
        notices.extend(arm_choice);
        return solve(&dataset.pairs, visits, notices, None);
    };
    let published = match config.solver.kinematics() {
        KinematicsChoice::Auto => Some(solve(&dataset.pairs, visits, notices.clone(), None)?),
        _ => None,
    };
    // The held-out folds refit the arm without their sample: fitted to it too, the arm would
    // predict it partly from itself.
    let folds = &corrected.folds;
    let free = corrected.free_in_reprojection();
    let mut with_arm = solve(
        &corrected.pairs,
        &corrected.visits,
        notices.iter().cloned().chain(arm_choice.clone()).collect(),
        Some((&|left_out| folds.flanges_without(left_out), &free)),
    )?;
    if let (Some(mut published), Some(after)) = (published, contradicted_files(&with_arm)) {
        published.calibration.notices.push(Notice::info(
            NoticeKind::Other,
            format!(
                "the arm's published model is kept: its own model would lower the residuals, but with it the verdict names {after}; fix that first and replay (`solver.kinematics: joint_offsets` keeps the arm's model regardless)"
            ),
        ));
        return Ok(published);
    }
    // The DH link corrections the data choose beside the offsets are kept unless with them the
    // verdict names a file: link lengths can take up a board printed at the wrong size (eye to
    // hand: 2.5 % and GOOD 32 mm off), which the offsets' solve above still names.
    if let Some((links, links_notice)) = links {
        let folds = &links.folds;
        let free = links.free_in_reprojection();
        let with_links = solve(
            &links.pairs,
            &links.visits,
            notices.iter().cloned().chain([links_notice]).collect(),
            Some((&|left_out| folds.flanges_without(left_out), &free)),
        )?;
        match contradicted_files(&with_links) {
            None => (with_arm, corrected) = (with_links, links),
            Some(after) => with_arm.calibration.notices.push(Notice::info(
                NoticeKind::Other,
                format!("the arm's DH link corrections are left out: the data choose them beside the offsets, but with them the verdict names {after}"),
            )),
        }
    }
    // In reprojection space the offsets were refined with the transforms over every corner.
    if let Some(refined) = &with_arm.reprojection {
        corrected.arm.refine_offsets(&refined.arm_offsets);
    }
    with_arm.summary = format!(
        "{}\n{}",
        with_arm.summary,
        corrected.arm.describe().join("\n")
    );
    with_arm.arm_refit = Some(corrected.folds);
    with_arm.arm = Some(corrected.arm);
    Ok(with_arm)
}

/// What of the given files or conventions `solved` finds contradicted (a lens, a board's size,
/// both, a convention), in words: the cell model's choice (also where its correction is
/// immaterial at the accuracy asked), the verdict's leading finding, its further ones; `None`
/// when nothing is.
fn contradicted_files(solved: &SolvedSession) -> Option<&'static str> {
    use handeye_solve::verdict::{Basis, Level};
    let from_corners = solved
        .cell_model
        .as_ref()
        .and_then(|m| match m.summary.chosen {
            Explanation::AsGiven => None,
            Explanation::Intrinsics => Some(Basis::Intrinsics),
            Explanation::BoardScale => Some(Basis::BoardScale),
            Explanation::IntrinsicsAndBoard => Some(Basis::IntrinsicsAndBoard),
        });
    let verdict = solved.verdict.as_ref();
    let lead = verdict.filter(|v| v.level > Level::Good).map(|v| v.basis);
    let also = verdict
        .into_iter()
        .flat_map(|v| v.also.iter().map(|f| f.basis));
    from_corners
        .into_iter()
        .chain(lead)
        .chain(also)
        .find_map(|basis| match basis {
            Basis::Intrinsics => Some("the intrinsics"),
            Basis::BoardScale => Some("the board's size"),
            Basis::IntrinsicsAndBoard => Some("the intrinsics and the board"),
            Basis::ConventionError => Some("the poses' convention"),
            _ => None,
        })
}

/// The folder's `samples.yaml`, checked against the committed records: it must hold exactly the
/// accepted poses (the pose-space answer and the pixel fit then use the same frames). No accepted
/// pose at all is its own error, with the rejections.
fn committed_samples(
    folder: &SessionFolder,
    visits: &[PoseVisit],
) -> Result<Dataset, SessionError> {
    let accepted: Vec<String> = visits
        .iter()
        .filter(|v| v.camera_from_target.is_some())
        .map(PoseVisit::sample_id)
        .collect();
    if let (true, Some(run)) = (accepted.is_empty(), folder.live_run()) {
        return Err(SessionError::Recording {
            run: run.clone(),
            next: "no pose has given a sample yet: solve it again when the run has recorded some"
                .to_string(),
        });
    }
    if accepted.is_empty() {
        return Err(no_samples(folder, visits));
    }
    let path = folder.samples_path();
    if folder.live_run().is_some() {
        // A run is recording: samples.yaml is rewritten after each record, so it may lag the
        // records by a pose. The records are the log; take the samples from them.
        return Ok(Dataset {
            setup: folder.read_manifest()?.setup,
            pairs: visits.iter().filter_map(PoseVisit::sample).collect(),
        });
    }
    let dataset = if path.is_file() {
        Dataset::load(&path)?
    } else {
        Dataset {
            setup: folder.read_manifest()?.setup,
            pairs: Vec::new(),
        }
    };
    let ids: Vec<String> = dataset
        .pairs
        .iter()
        .map(|p| p.id.clone().unwrap_or_default())
        .collect();
    let missing: Vec<String> = accepted
        .iter()
        .filter(|id| !ids.contains(id))
        .cloned()
        .collect();
    let mut extra: Vec<String> = ids
        .iter()
        .filter(|id| !accepted.contains(id))
        .cloned()
        .collect();
    let mut seen = std::collections::BTreeSet::new();
    extra.extend(
        ids.iter()
            .filter(|id| !seen.insert(*id))
            .map(|id| format!("{id} (twice)")),
    );
    if !missing.is_empty() || !extra.is_empty() {
        return Err(SessionError::SamplesDisagree {
            file: path,
            folder: folder.root().to_path_buf(),
            missing,
            extra,
        });
    }
    Ok(dataset)
}

/// File the estimated intrinsics are written to, in the session folder.
pub const CAMERA_INFO_FILE: &str = "camera_info.yaml";
/// File with both answers' reprojection errors per frame, in the session folder.
pub const REPROJECTION_FILE: &str = "reprojection.yaml";

/// The reprojection-space solve's options of a cell: its corner noise, whether to estimate it,
/// and the arm's repeatability as a prior when the config asks for robot corrections.
pub fn reprojection_options(config: &CellConfig) -> ReprojectionOptions {
    ReprojectionOptions {
        pixel_sigma_px: config.solver.pixel_sigma_px,
        estimate_noise: config.solver.estimate_noise,
        robot_prior: config.solver.robot_corrections.then(|| {
            let (translation_sigma_m, rotation_sigma_rad) = config.robot_repeatability();
            RobotPrior {
                translation_sigma_m,
                rotation_sigma_rad,
            }
        }),
        ..ReprojectionOptions::default()
    }
}

/// No intrinsics in the config: Zhang's closed form from the recorded corners, then the joint
/// refinement; writes `camera_info.yaml` and the samples it solved from (`samples.yaml`) into the
/// session.
fn solve_from_scratch(
    folder: &SessionFolder,
    config: &CellConfig,
    board: &Target,
) -> Result<(SolvedSession, Dataset), SessionError> {
    let manifest = folder.read_manifest()?;
    let visits = folder.read_visits()?;
    let (ids, frames): (Vec<String>, Vec<Frame>) = frames_from_visits(&visits, board, false)?
        .into_iter()
        .unzip();
    let first = visits
        .iter()
        .find(|v| !v.corners_px.is_empty())
        .ok_or_else(|| SessionError::NoBoardSeen {
            folder: folder.root().to_path_buf(),
        })?;
    let frame_path = folder.root().join(&first.frame);
    let (width, height) =
        image::image_dimensions(&frame_path).map_err(|source| SessionError::Frame {
            path: frame_path.clone(),
            source: Box::new(source),
        })?;
    let options = config.solver.to_options();
    let scratch = handeye_solve::intrinsics::calibrate_from_scratch(
        manifest.setup,
        &frames,
        width,
        height,
        &options,
        &reprojection_options(config),
    )
    .map_err(|source| SessionError::Solve {
        stage: "estimating the intrinsics",
        source: Box::new(source),
    })?;
    let camera_info = folder.root().join(CAMERA_INFO_FILE);
    scratch
        .joint
        .camera
        .save_camera_info(&camera_info)
        .map_err(|source| SessionError::Intrinsics {
            file: camera_info.clone(),
            source: Box::new(source),
        })?;
    // The fair comparison: board poses again by PnP with the estimated intrinsics, the pose-space
    // solve on those, and the reprojection answer's residuals against the same poses.
    let camera = scratch.joint.camera;
    let mut pairs = Vec::with_capacity(frames.len());
    for (id, frame) in ids.iter().zip(&frames) {
        let correspondences: Vec<_> = frame
            .corners
            .iter()
            .map(|c| (c.point_in_target, c.pixel))
            .collect();
        let tags = correspondences.len() / 4;
        if let Ok(pose) =
            handeye_vision::pnp::estimate_pose_from_points(&camera, &correspondences, tags.max(2))
        {
            pairs.push(PosePair {
                id: Some(id.clone()),
                view_sigma: pose.view_sigma(),
                ..PosePair::new(frame.base_from_flange, pose.camera_from_target)
            });
        }
    }
    let pose_space =
        solve::solve(manifest.setup, &pairs, &options).map_err(|source| SessionError::Solve {
            stage: "pose space with the estimated intrinsics",
            source: Box::new(source),
        })?;
    let pose_space_errors = reprojection_errors(
        manifest.setup,
        &frames,
        &camera,
        &pose_space.camera_mount,
        &pose_space.target_mount,
    );
    let calibration = scratch
        .joint
        .to_calibration(&pose_space, &pairs, &options.noise);
    let mut solved = SolvedSession {
        calibration,
        reprojection: Some(scratch.joint.clone()),
        pose_space_errors: Some(pose_space_errors),
        frame_ids: ids,
        estimated_camera: Some(camera),
        ..SolvedSession::of_pose_space(pose_space)
    };
    let c = &scratch.joint.camera;
    let i = &scratch.initial;
    let mut notes = vec![format!(
        "intrinsics estimated from {} frames (Zhang's closed form fx {:.2} fy {:.2} cx {:.2} cy {:.2} px, no distortion; then jointly refined; the pose-space column uses the refined ones): fx {:.2} fy {:.2} cx {:.2} cy {:.2} px, {} {:?}; written to {}",
        frames.len(),
        i.fx, i.fy, i.cx, i.cy,
        c.fx, c.fy, c.cx, c.cy,
        "plumb_bob", c.distortion_coefficients(),
        folder.shown_root().join(CAMERA_INFO_FILE).display()
    )];
    if let Some(sigma) = scratch.joint.intrinsics_sigma_px {
        notes.push(format!(
            "intrinsics 1-sigma: fx {:.3} fy {:.3} cx {:.3} cy {:.3} px",
            sigma[0], sigma[1], sigma[2], sigma[3]
        ));
    }
    conclude(
        &mut solved,
        &pairs,
        &options,
        config,
        &notes,
        Vec::new(),
        None,
    );
    // The board poses just estimated are this session's samples: `samples.yaml` (which the
    // report, `verify` and `solve <session>` read) holds them, consistent with
    // `camera_info.yaml`. The run records none without intrinsics.
    let dataset = Dataset {
        setup: manifest.setup,
        pairs,
    };
    dataset.save(&folder.samples_path())?;
    solved.evidence = Evidence {
        pairs: dataset.pairs.clone(),
        visits,
    };
    Ok((solved, dataset))
}

/// The reprojection refinement's frames from recorded visits: every accepted visit (one with a
/// board pose, or any visit with corners when `require_pose` is false) with its corners mapped to
/// board points; corners of tags not on the board are skipped. Ids are `pose-NNN` like the
/// samples'.
pub fn frames_from_visits<'a>(
    visits: impl IntoIterator<Item = &'a PoseVisit>,
    board: &Target,
    require_pose: bool,
) -> Result<Vec<(String, Frame)>, SessionError> {
    let mut frames = Vec::new();
    for visit in visits {
        let accepted = visit.camera_from_target.is_some() || !require_pose;
        if !accepted || visit.corners_px.is_empty() {
            continue;
        }
        let record = SessionFolder::visit_name(visit.plan_index);
        let base_from_flange = visit.base_from_flange;
        // Corners were checked when the record was read (no point twice); a point the board
        // does not have is refused, never skipped.
        visit.check_corners_on_board(&record, board)?;
        let corners = visit
            .corners_px
            .iter()
            .filter_map(|c| {
                Some(Corner {
                    point_in_target: board.observation_point(c)?,
                    pixel: c.pixel,
                })
            })
            .collect();
        let id = visit.sample_id();
        frames.push((
            id.clone(),
            Frame {
                base_from_flange,
                corners,
                id: Some(id),
            },
        ));
    }
    Ok(frames)
}

/// The last step of both solve paths: the check against the config's nominal transforms (an
/// answer far from them — swapped unknowns, say — is flagged where the result file, the report
/// and the verdict all see it), the verdict, and the summary that opens with it.
fn conclude(
    solved: &mut SolvedSession,
    pairs: &[PosePair],
    options: &SolveOptions,
    config: &CellConfig,
    notes: &[String],
    findings: Vec<Notice>,
    refit: Option<FoldFlanges<'_>>,
) {
    solved.judged = pairs.to_vec();
    solved.calibration.notices.extend(findings);
    // Swapped unknowns first (their own cause); else an answer simply far from the nominal —
    // unless the nominal is a recorded cell's, which its importer wrote (the identity, or the
    // data's own answer), not a person's drawing or tape measure.
    let measured_nominal = config.robot.backend().moves();
    let nominal = solve::diagnostics::check_against_nominal(
        &solved.calibration,
        &config.camera().nominal,
        solve::diagnostics::NOMINAL_TOLERANCE_M,
    )
    .or_else(|| {
        measured_nominal
            .then(|| {
                solve::diagnostics::check_far_from_nominal(
                    &solved.calibration,
                    &config.camera().nominal,
                )
            })
            .flatten()
    });
    solved.calibration.notices.extend(nominal);
    let verdict = verdict::assess_modelled(
        &solved.calibration,
        pairs,
        options,
        config.verdict.accuracy(),
        solved.cell_model.as_ref().map(|m| &m.summary),
        refit,
    );
    solved.summary = format!("{}\n{}", verdict.terminal_lines(), solved.describe(notes));
    solved.verdict = Some(verdict);
}

/// Solves pose pairs and, when `vision` (board and intrinsics) is given and the config's space is
/// reprojection, refines over the visits' corners; no I/O.
pub fn solve_session(
    setup: Setup,
    pairs: &[PosePair],
    visits: &[PoseVisit],
    vision: Option<(&Target, &CameraModel)>,
    config: &CellConfig,
) -> Result<SolvedSession, SessionError> {
    solve_session_with(setup, pairs, visits, vision, config, Vec::new(), None)
}

/// [`solve_session`] with `findings` of the session layer's own checks (wrong intrinsics) added
/// to the answer's notices before the verdict judges them, and with `arm` when the robot poses
/// were corrected by the arm's own model: the verdict's held-out folds refit it, and in
/// reprojection space its free joint offsets are refined with the transforms.
pub fn solve_session_with(
    setup: Setup,
    pairs: &[PosePair],
    visits: &[PoseVisit],
    vision: Option<(&Target, &CameraModel)>,
    config: &CellConfig,
    findings: Vec<Notice>,
    arm: Option<(FoldFlanges<'_>, &ArmOffsetsFree)>,
) -> Result<SolvedSession, SessionError> {
    let (refit, arm) = arm.unzip();
    let options = config.solver.to_options();
    let pose_space =
        solve::solve(setup, pairs, &options).map_err(|source| SessionError::Solve {
            stage: "pose space",
            source: Box::new(source),
        })?;
    let mut solved = SolvedSession {
        // What it was solved from, for the report.
        evidence: Evidence {
            pairs: pairs.to_vec(),
            visits: visits.to_vec(),
        },
        ..SolvedSession::of_pose_space(pose_space)
    };
    let mut notes = Vec::new();
    let mut corrected = Vec::new();
    if let Some((board, camera)) = vision {
        // Frames the pose-space solve dropped as outliers stay out of the fits; each is checked
        // against the pixel answer afterwards.
        let dropped: Vec<&str> = solved
            .pose_space
            .dropped
            .iter()
            .filter_map(|&i| pairs.get(i).and_then(|p| p.id.as_deref()))
            .collect();
        let all = frames_from_visits(visits, board, true)?;
        let (mut ids, mut frames): (Vec<String>, Vec<Frame>) = all
            .iter()
            .filter(|(id, _)| !dropped.contains(&id.as_str()))
            .cloned()
            .unzip();
        if frames.iter().filter(|f| !f.corners.is_empty()).count() >= 3 {
            let mut ropts = reprojection_options(config);
            ropts.arm = arm.cloned();
            let p = &solved.pose_space;
            // Which given file the corners contradict, if any (issue #38); the answer is then
            // refined with the chosen explanation's estimates free.
            let model = fit_cell_model(
                setup,
                &frames,
                camera,
                &p.camera_mount,
                &p.target_mount,
                &ropts,
                config.verdict.accuracy(),
            )
            .map_err(|source| SessionError::Solve {
                stage: "cell model",
                source: Box::new(source),
            })?;
            let chosen = model.summary.chosen;
            let final_options = ReprojectionOptions {
                refine_intrinsics: chosen.intrinsics_wrong(),
                refine_distortion: chosen.intrinsics_wrong(),
                refine_board_scale: chosen.board_wrong(),
                board_scale: model.board_scale(),
                ..ropts
            };
            let refine = |frames: &[Frame], start: &ReprojectionCalibration| {
                refine_reprojection(
                    setup,
                    frames,
                    &start.camera,
                    &start.camera_mount,
                    &start.target_mount,
                    &ReprojectionOptions {
                        board_scale: start.board_scale,
                        ..final_options.clone()
                    },
                )
                .map_err(|source| SessionError::Solve {
                    stage: "reprojection refinement",
                    source: Box::new(source),
                })
            };
            let mut reprojection = refine(&frames, &model.fit)?;
            // Pose-space outlier flags the corners do not confirm (the pose-space noise model is
            // isotropic, a PnP pose's error is not): those frames are kept.
            let flagged: Vec<&str> = p
                .outliers
                .iter()
                .filter_map(|&i| pairs.get(i).and_then(|p| p.id.as_deref()))
                .collect();
            let kept = pixel_consistent(setup, &all, &flagged, &reprojection, &final_options);
            if kept.iter().any(|(id, _)| dropped.contains(&id.as_str())) {
                for (id, frame) in &all {
                    if dropped.contains(&id.as_str()) && kept.iter().any(|(k, _)| k == id) {
                        ids.push(id.clone());
                        frames.push(frame.clone());
                    }
                }
                reprojection = refine(&frames, &reprojection)?;
            }
            for (id, rms) in &kept {
                notes.push(format!(
                    "{id}: flagged in pose space, but its corners fit the pixel answer ({rms:.2} px RMS): kept"
                ));
            }
            solved.pose_space_errors = Some(reprojection_errors(
                setup,
                &frames,
                camera,
                &p.camera_mount,
                &p.target_mount,
            ));
            if chosen == Explanation::AsGiven {
                solved.calibration = reprojection.to_calibration(p, pairs, &options.noise);
            } else {
                // The board poses again with the corrected files: the verdict's held-out error
                // and residuals judge the answer, not the wrong file.
                corrected = corrected_pairs(pairs, &frames, &reprojection);
                let start = solve::solve(setup, &corrected, &options).unwrap_or_else(|_| p.clone());
                solved.calibration =
                    reprojection.to_calibration(&start, &corrected, &options.noise);
                notes.push(format!(
                    "the cell model chose \"{}\": the answer uses the estimate (camera fx {:.2} fy {:.2} cx {:.2} cy {:.2} px, board scale {:.4})",
                    chosen.label(),
                    reprojection.camera.fx,
                    reprojection.camera.fy,
                    reprojection.camera.cx,
                    reprojection.camera.cy,
                    reprojection.board_scale
                ));
            }
            unflag(&mut solved.calibration, pairs, &kept);
            solved.reprojection = Some(reprojection);
            solved.cell_model = Some(model);
            solved.frame_ids = ids;
        } else {
            notes.push(
                "fewer than 3 frames with recorded corners: pose-space answer only".to_string(),
            );
        }
    }
    let judged = if corrected.is_empty() {
        pairs
    } else {
        &corrected
    };
    conclude(
        &mut solved,
        judged,
        &options,
        config,
        &notes,
        findings,
        refit,
    );
    Ok(solved)
}

/// Of the frames `flagged` as outliers in pose space, those whose corners fit `fit` (robot pose
/// as recorded, board scale and camera of the fit) within the reprojection's own frame-outlier
/// rule (`median + factor · 1.4826 · MAD` of the fitted frames' RMS, at least the floor): their
/// ids with their RMS, px.
fn pixel_consistent(
    setup: Setup,
    all: &[(String, Frame)],
    flagged: &[&str],
    fit: &ReprojectionCalibration,
    options: &ReprojectionOptions,
) -> Vec<(String, f64)> {
    let rms: Vec<f64> = fit
        .recorded_pose_errors
        .frame_rms_px
        .iter()
        .copied()
        .filter(|v| v.is_finite())
        .collect();
    if rms.is_empty() {
        return Vec::new();
    }
    let threshold = solve::diagnostics::outlier_threshold(
        &rms,
        options.outlier_mad_factor,
        options.outlier_floor_px,
    );
    all.iter()
        .filter(|(id, _)| flagged.contains(&id.as_str()))
        .filter_map(|(id, frame)| {
            let mut scaled = frame.clone();
            for c in &mut scaled.corners {
                c.point_in_target.coords *= fit.board_scale;
            }
            let e = reprojection_errors(
                setup,
                std::slice::from_ref(&scaled),
                &fit.camera,
                &fit.camera_mount,
                &fit.target_mount,
            );
            (e.rms_px.is_finite() && e.rms_px <= threshold).then(|| (id.clone(), e.rms_px))
        })
        .collect()
}

/// Clears the outlier flags (and the notices naming them) of the samples `kept`.
fn unflag(calibration: &mut Calibration, pairs: &[PosePair], kept: &[(String, f64)]) {
    let is_kept = |i: &usize| {
        pairs
            .get(*i)
            .and_then(|p| p.id.as_deref())
            .is_some_and(|id| kept.iter().any(|(k, _)| k == id))
    };
    calibration.outliers.retain(|i| !is_kept(i));
    calibration.dropped.retain(|i| !is_kept(i));
    calibration.notices.retain(|n| {
        !(matches!(n.kind, NoticeKind::Outliers | NoticeKind::DroppedOutliers)
            && kept
                .iter()
                .any(|(id, _)| n.message.contains(&format!("({id})"))))
    });
}

/// `pairs` with each board pose estimated again (PnP over the frame's corners) with the camera
/// and board scale of `fit`; a pair without a frame, or whose PnP fails, keeps its pose.
fn corrected_pairs(
    pairs: &[PosePair],
    frames: &[Frame],
    fit: &ReprojectionCalibration,
) -> Vec<PosePair> {
    pairs
        .iter()
        .map(|pair| {
            let mut out = pair.clone();
            let frame = frames.iter().find(|f| f.id.is_some() && f.id == pair.id);
            let correspondences = frame.map(|frame| {
                frame
                    .corners
                    .iter()
                    .map(|c| (c.point_in_target * fit.board_scale, c.pixel))
                    .collect::<Vec<_>>()
            });
            if let Some(pose) = correspondences.and_then(|c| board_pose(&fit.camera, &c)) {
                out.camera_from_target = pose;
            }
            out
        })
        .collect()
}

/// `T_camera_target` by PnP over a frame's (board point, pixel) pairs through `camera`: the board
/// pose again with corrected files (a lens estimated, board points scaled); `None` when PnP fails.
pub fn board_pose(
    camera: &CameraModel,
    correspondences: &[(nalgebra::Point3<f64>, nalgebra::Point2<f64>)],
) -> Option<handeye_core::geometry::Pose> {
    board_fit(camera, correspondences).map(|p| p.camera_from_target)
}

/// [`board_pose`] with its fit (the corners' reprojection RMS).
pub(crate) fn board_fit(
    camera: &CameraModel,
    correspondences: &[(nalgebra::Point3<f64>, nalgebra::Point2<f64>)],
) -> Option<handeye_vision::pnp::BoardPose> {
    // More than one tag: a board, never the lone-tag ambiguity check (four corners a tag).
    let tags = (correspondences.len() / 4).max(2);
    handeye_vision::pnp::estimate_pose_from_points(camera, correspondences, tags).ok()
}

/// Writes the estimates of the files the cell model blames into the session folder `root`
/// (`camera_info.yaml` with the estimated intrinsics, `board.yaml`: the config's board file with
/// its size scaled), when the chosen explanation is determined. Returns the files written.
pub fn write_corrected_files(
    root: &std::path::Path,
    solved: &SolvedSession,
    config: &CellConfig,
) -> Result<Vec<std::path::PathBuf>, SessionError> {
    let (Some(model), Some(fit)) = (&solved.cell_model, &solved.reprojection) else {
        return Ok(Vec::new());
    };
    write_estimates(root, &model.summary, fit, &config.camera().target)
}

/// Records the corrected files `written` in the cell model's summary and the verdict's figures
/// (the result file and the report show them).
pub fn record_written(solved: &mut SolvedSession, written: &[std::path::PathBuf]) {
    let names: Vec<String> = written.iter().map(|p| p.display().to_string()).collect();
    if let Some(model) = &mut solved.cell_model {
        model.summary.written.clone_from(&names);
    }
    if let Some(model) = solved
        .verdict
        .as_mut()
        .and_then(|v| v.figures.cell_model.as_mut())
    {
        model.written = names;
    }
}

/// Writes the estimates of `fit` (its camera, its board scale) for the files `summary` blames
/// into the folder `root` (`camera_info.yaml`; `board.yaml`: the board file `target` with its
/// size scaled), when the chosen explanation is determined and unambiguous. Returns the files
/// written.
pub fn write_estimates(
    root: &std::path::Path,
    summary: &cell_model::CellModelSummary,
    fit: &ReprojectionCalibration,
    target: &std::path::Path,
) -> Result<Vec<std::path::PathBuf>, SessionError> {
    if !summary.corrects() {
        return Ok(Vec::new());
    }
    // A replay's estimates folder is made on first use.
    crate::create_dir(root)?;
    let mut written = Vec::new();
    if summary.chosen.intrinsics_wrong() {
        let path = root.join(cell_model::CORRECTED_INTRINSICS_FILE);
        fit.camera
            .save_camera_info(&path)
            .map_err(|source| SessionError::Intrinsics {
                file: path.clone(),
                source: Box::new(source),
            })?;
        written.push(path);
    }
    if summary.chosen.board_wrong() {
        let path = root.join(cell_model::CORRECTED_BOARD_FILE);
        written.push(write_scaled_board(target, fit.board_scale, &path)?);
    }
    Ok(written)
}

/// The board file `target` with every size times `scale` (the sizes the board file's kind
/// has: `tagSize`, `squareLength` and `markerLength`, the spacings of a chessboard), every other
/// line kept, written whole or not at all to `path`.
fn write_scaled_board(
    target: &std::path::Path,
    scale: f64,
    path: &std::path::Path,
) -> Result<std::path::PathBuf, SessionError> {
    let board_error = |source| SessionError::Board {
        file: target.to_path_buf(),
        source: Box::new(source),
    };
    let text = std::fs::read_to_string(target).map_err(|source| SessionError::Io {
        path: target.to_path_buf(),
        source,
    })?;
    let board = Target::from_yaml_str(&text, target).map_err(board_error)?;
    let scaled = handeye_vision::print::scaled(&board, scale).map_err(board_error)?;
    let how = format!(
        "The board as this session measured it: {scale:.5} × the sizes of {} (handeye's cell model)",
        target.display()
    );
    let yaml = handeye_vision::print::resized_board_yaml(&text, target, &scaled, &how)
        .map_err(board_error)?;
    handeye_core::atomic_file::write_atomic(path, yaml.as_bytes()).map_err(|source| {
        SessionError::Io {
            path: path.to_path_buf(),
            source,
        }
    })?;
    Ok(path.to_path_buf())
}

#[cfg(test)]
mod tests {
    use super::*;
    use handeye_vision::print::size_keys;

    /// A board measured at another scale is written back with every size of its kind scaled
    /// (an aprilgrid's `tagSize`, a ChArUco board's square and marker lengths, a chessboard's
    /// spacings), and reads back as the same board at that size.
    #[test]
    fn a_scaled_board_of_every_kind_reads_back_at_its_measured_size() {
        let targets =
            std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../configs/targets");
        let dir = tempfile::tempdir().unwrap();
        for name in [
            "aprilgrid-6x6.yaml",
            "charuco-9x6-5x5.yaml",
            "checkerboard-10x7.yaml",
        ] {
            let given = targets.join(name);
            let out = dir.path().join(name);
            let written = write_scaled_board(&given, 0.952, &out).unwrap();
            let before = size_keys(&Target::load(&given).unwrap());
            let after = size_keys(&Target::load(&written).unwrap());
            assert_eq!(before.len(), after.len(), "{name}");
            for ((key, b), (key_after, a)) in before.iter().zip(&after) {
                assert_eq!(key, key_after);
                assert!((a / b - 0.952).abs() < 1e-9, "{name} {key}: {b} -> {a}");
            }
        }
    }
}
