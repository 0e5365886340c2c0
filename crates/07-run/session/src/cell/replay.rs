//! A session replayed (`handeye replay DIR`), one camera or several: its frames detected again
//! and solved as the run's solve is (the checks of the given files included), the answer
//! written beside the session's own files — `replay-result.yaml` in the session folder, or
//! where `output` says — with the estimates of a blamed file beside it. A replay never writes
//! over what the run recorded. Printing and the report are the caller's (`handeye replay`).

use std::path::{Path, PathBuf};

use anyhow::Context;

use handeye_config::CellConfig;
use handeye_core::camera_model::CameraModel;
use handeye_records::dataset::Dataset;
use handeye_records::result::CellResult;
use handeye_records::{PoseVisit, SessionError, SessionFolder, SolvedSession};
use handeye_vision::{DetectorOptions, Target, TargetDetector};

use super::cameras;
use super::{PreparedCamera, PreparedCell};
use crate::driver::measure;

/// A replay's result file in the session folder when no other is asked for.
pub const REPLAY_RESULT_FILE: &str = "replay-result.yaml";
/// The folder beside a replay's result that holds its estimates of wrong files.
pub const REPLAY_ESTIMATES_FOLDER: &str = "replay-estimates";

/// `name` in the folder of the file `file` (the working folder for a bare file name).
pub fn beside(file: &Path, name: &str) -> PathBuf {
    match file.parent() {
        Some(dir) if !dir.as_os_str().is_empty() => dir.join(name),
        _ => PathBuf::from(name),
    }
}

/// Where a solve writes its answer: the result file, and the folder the estimates of wrong
/// files go into (one folder per camera for a cell of several).
#[derive(Debug, Clone)]
pub struct AnswerOutput {
    /// The result file.
    pub result: PathBuf,
    /// The estimates' folder.
    pub estimates: PathBuf,
}

impl AnswerOutput {
    /// A several-camera run's own: `<root>/result.yaml`, each camera's estimates in
    /// `<root>/cameras/<name>`.
    pub fn run(root: &Path) -> AnswerOutput {
        AnswerOutput {
            result: root.join("result.yaml"),
            estimates: root.join("cameras"),
        }
    }

    /// A replay's, of one camera or several: `result` (default `<session>/replay-result.yaml`),
    /// the estimates in `replay-estimates` beside it. Nothing a run recorded is written over.
    pub fn replay(session: &Path, result: Option<&Path>) -> AnswerOutput {
        let result = result.map_or_else(|| session.join(REPLAY_RESULT_FILE), Path::to_path_buf);
        let estimates = beside(&result, REPLAY_ESTIMATES_FOLDER);
        AnswerOutput { result, estimates }
    }

    /// Camera `camera`'s estimates' folder in a cell of several.
    pub fn estimates_of(&self, camera: &str) -> PathBuf {
        self.estimates.join(camera)
    }

    /// Makes the result's folder when it does not exist yet (`-o` into a new folder).
    pub fn create_folder(&self) -> Result<(), SessionError> {
        handeye_records::create_parent_dir(&self.result)
    }
}

/// Re-detects every saved frame of `folder` and returns the dataset the frames give now, with the
/// visits as re-measured (in plan order).
pub fn redetect(
    folder: &SessionFolder,
    board: &Target,
    camera_model: &CameraModel,
    detector: DetectorOptions,
    max_rms: f64,
) -> Result<(Dataset, Vec<PoseVisit>), SessionError> {
    let manifest = folder.read_manifest()?;
    let detector =
        TargetDetector::spawn(board, detector).map_err(|e| SessionError::Detector(Box::new(e)))?;
    let mut samples = Vec::new();
    let mut visits = Vec::new();
    for recorded in folder.read_visits()? {
        let frame_path = folder.root().join(&recorded.frame);
        let image = image::open(&frame_path)
            .map_err(|source| SessionError::Frame {
                path: frame_path.clone(),
                source: Box::new(source),
            })?
            .into_luma8();
        let visit = measure(
            &detector,
            board,
            Some(camera_model),
            &image,
            max_rms,
            PoseVisit::new(
                recorded.plan_index,
                &recorded.base_from_flange,
                recorded.frame.clone(),
            ),
        )?;
        samples.extend(visit.sample());
        visits.push(visit);
    }
    Ok((
        Dataset {
            setup: manifest.setup,
            pairs: samples,
        },
        visits,
    ))
}

/// What to replay.
#[derive(Debug, Clone, Copy)]
pub struct ReplayRequest<'a> {
    /// The session folder (one camera's, or the root of several cameras').
    pub session: &'a Path,
    /// A cell config to use instead of the one the session was run with.
    pub config: Option<&'a Path>,
    /// Where to write the replayed result (default `<session>/replay-result.yaml`).
    pub output: Option<&'a Path>,
}

/// A replayed session, one camera or several, in the shape of a run's answer
/// ([`super::run::CellRun`]): the cell's answer whatever its number of cameras, and a one-camera
/// session's own solve beside it.
pub struct Replayed {
    /// The session folder (for several cameras the folder holding `rig.yaml`).
    pub root: PathBuf,
    /// The cell as the session recorded it (its boards, the lenses the frames were measured with).
    pub cell: PreparedCell,
    /// The answer as written to `output.result`, whatever the number of cameras.
    pub result: CellResult,
    /// A one-camera session's solve (its verdict and evidence, what its page draws); `None` for a
    /// cell of listed cameras, whose answer is the joint one ([`Self::result`]).
    pub camera: Option<Box<CameraReplay>>,
    /// Where the answer and the estimates were written.
    pub output: AnswerOutput,
}

/// A one-camera session's frames measured again and solved.
pub struct CameraReplay {
    /// Its session folder.
    pub folder: SessionFolder,
    /// The lens the frames were measured with (the config's, else the one the run estimated).
    pub camera_model: CameraModel,
    /// Every saved frame as measured again, plan order.
    pub visits: Vec<PoseVisit>,
    /// The answer, its verdict and evidence.
    pub solved: SolvedSession,
    /// The samples it was solved from.
    pub dataset: Dataset,
}

/// Replays the session of `request`: every camera's saved frames measured again with its board
/// and lens, then solved as the run's solve is — one camera's by its session solve (the checks
/// of the given files included), listed cameras' jointly. `measured` is told each camera's
/// frames as measured again (with the camera's name in a cell of listed cameras), before the
/// solve, so a solve that fails still leaves what each frame gave on the screen.
pub fn replay_session(
    request: ReplayRequest<'_>,
    measured: &mut dyn FnMut(Option<&str>, &[PoseVisit]),
) -> anyhow::Result<Replayed> {
    let root = request.session;
    // A listed cell of one camera is its camera's session; its replay's answer goes beside the
    // root all the same.
    let session = cameras::session_to_read(root);
    let listed = cameras::is_cameras_folder(&session);
    let (cell, mut folders) = if listed {
        let recorded = cameras::read_manifest(root)?.config;
        let config = super::session_config(request.config, &recorded)?;
        let cell = super::prepare_config(config).context("preparing the cell")?;
        let folders = (cell.config.cameras.iter())
            .map(|c| SessionFolder::open(&cameras::camera_folder(root, &c.name)))
            .collect::<Result<Vec<_>, _>>()?;
        (cell, folders)
    } else {
        let folder = SessionFolder::open(&session)?;
        let cell = one_camera_cell(&folder, request.config)?;
        (cell, vec![folder])
    };
    // Every camera's frames measured again with its board and lens, config order.
    let mut visits: Vec<Vec<PoseVisit>> = Vec::new();
    let mut lenses = Vec::new();
    for ((camera, config), folder) in cell.cameras.iter().zip(&cell.config.cameras).zip(&folders) {
        let lens = replay_lens(folder, camera)?;
        let (_, measured_now) = redetect(
            folder,
            &camera.board,
            &lens,
            cell.detector_options(),
            cell.config.session.max_reprojection_rms_px,
        )?;
        measured(listed.then_some(config.name.as_str()), &measured_now);
        visits.push(measured_now);
        lenses.push(lens);
    }
    let output = AnswerOutput::replay(root, request.output);
    let (result, camera) = if listed {
        let result = cameras::solve_cameras_folder(root, &cell.config, visits, &output)?;
        (result, None)
    } else {
        // A one-camera session: one folder, its camera's measurements and lens.
        let (folder, visits) = (folders.swap_remove(0), visits.swap_remove(0));
        let (replay, result) = solve_camera(folder, &cell, lenses[0], visits, &output)?;
        (result, Some(Box::new(replay)))
    };
    Ok(Replayed {
        root: root.to_path_buf(),
        cell,
        result,
        camera,
        output,
    })
}

/// The lens `camera`'s frames in `folder` are measured again with: the config's, else (a cell
/// without configured intrinsics) the one its run estimated.
fn replay_lens(folder: &SessionFolder, camera: &PreparedCamera) -> anyhow::Result<CameraModel> {
    if camera.intrinsics_known {
        return Ok(camera.camera_model);
    }
    let file = folder.root().join(handeye_records::solve::CAMERA_INFO_FILE);
    CameraModel::load(&file).with_context(|| {
        format!(
            "the config has no intrinsics and {} holds no estimated ones: solve the session first",
            folder.root().display()
        )
    })
}

/// The cell of a one-camera session `folder` (its recorded config, or `config`), checked to be
/// the cell its frames were taken in.
fn one_camera_cell(folder: &SessionFolder, config: Option<&Path>) -> anyhow::Result<PreparedCell> {
    let manifest = folder.read_manifest()?;
    let config = super::config_of_camera_folder(
        super::session_config(config, &manifest.config)?,
        folder.root(),
    )
    .context("reading the cell config")?;
    let cell = prepare_for(folder, config)?;
    // The frames were taken in the session's layout: solving them as the other one gives an
    // answer of the wrong unknowns (a camera "on the flange" metres away).
    anyhow::ensure!(
        cell.config.camera().setup == manifest.setup,
        "session {} was recorded as {}, but {} describes a {} cell: replay it with the config it was recorded with",
        folder.root().display(),
        manifest.setup,
        cell.config.file.display(),
        cell.config.camera().setup
    );
    Ok(cell)
}

/// A one-camera session's frames as measured again (`visits`, through `camera_model`), solved
/// and judged as a run's solve is (the checks of the given files included); the answer written
/// to `output.result` and the estimates of a file the cell model blames beside it (the run's
/// own stay as they were); with that answer as the cell's result.
fn solve_camera(
    folder: SessionFolder,
    cell: &PreparedCell,
    camera_model: CameraModel,
    visits: Vec<PoseVisit>,
    output: &AnswerOutput,
) -> anyhow::Result<(CameraReplay, CellResult)> {
    let manifest = folder.read_manifest()?;
    let dataset = Dataset {
        setup: manifest.setup,
        pairs: visits.iter().filter_map(PoseVisit::sample).collect(),
    };
    let samples = if dataset.pairs.is_empty() {
        Err(handeye_records::solve::no_samples(&folder, &visits))
    } else {
        Ok(dataset)
    };
    let (mut solved, dataset) = handeye_records::solve::solve_records(
        &folder,
        &manifest,
        samples,
        &visits,
        &visits,
        (&cell.camera().board, &camera_model),
        cell.config.solver.space,
        &cell.config,
    )?;
    output.create_folder()?;
    let written =
        handeye_records::solve::write_corrected_files(&output.estimates, &solved, &cell.config)?;
    handeye_records::solve::record_written(&mut solved, &written);
    solved.name_replay(folder.root(), &output.estimates, &cell.config);
    let file = solved.result_file(&dataset.pairs, &cell.config);
    file.save(&output.result)?;
    let result = CellResult::of_one_camera(file, &output.result)?;
    let replay = CameraReplay {
        folder,
        camera_model,
        visits,
        solved,
        dataset,
    };
    Ok((replay, result))
}

/// The cell of `config` as the session `folder` recorded it: intrinsics a run read from
/// the camera driver's topic are the session's (no driver needed); the shipped placeholder lens
/// is refused.
fn prepare_for(folder: &SessionFolder, mut config: CellConfig) -> anyhow::Result<PreparedCell> {
    let from_topic = folder.root().join(super::INTRINSICS_FROM_TOPIC_FILE);
    if config.camera().intrinsics.is_none() && from_topic.is_file() {
        config.camera_mut().intrinsics = Some(from_topic);
    }
    let prepared = super::prepare_config(config).context("preparing the cell")?;
    if let Some((file, name)) = prepared.placeholder_intrinsics() {
        anyhow::bail!(
            "{}: the intrinsics are the shipped placeholder (camera_name: {name}), not this camera's calibration; point `intrinsics:` in {} at the camera's calibration (or at {}/camera_info.yaml when a solve estimated them), or drop `intrinsics:`",
            file.display(),
            prepared.config.file.display(),
            folder.root().display()
        );
    }
    Ok(prepared)
}
