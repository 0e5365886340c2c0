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
use super::PreparedCell;
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

/// A replayed session.
pub enum Replayed {
    /// One camera's.
    OneCamera(Box<OneCameraReplay>),
    /// Several cameras'.
    Cameras(Box<CamerasReplay>),
}

/// A several-camera session replayed: the joint answer, written to `output.result`.
pub struct CamerasReplay {
    /// The session folder.
    pub folder: PathBuf,
    /// The joint answer.
    pub result: CellResult,
    /// Where it and the estimates were written.
    pub output: AnswerOutput,
}

/// One camera's session replayed.
pub struct OneCameraReplay {
    /// The session folder.
    pub folder: SessionFolder,
    /// The cell as the session recorded it (its board, the lens the frames were measured with).
    pub cell: PreparedCell,
    /// The lens the frames were measured with (the config's, else the one the run estimated).
    pub camera_model: CameraModel,
    /// Every saved frame as measured again, plan order.
    pub visits: Vec<PoseVisit>,
    /// The answer, its verdict and evidence.
    pub solved: SolvedSession,
    /// The samples it was solved from.
    pub dataset: Dataset,
    /// The result file written.
    pub output: PathBuf,
}

/// Replays the session of `request`: every camera's saved frames measured again and solved.
/// `measured` is told each frame as measured again (with the camera's name in a cell of
/// several), before the solve, so a solve that fails still leaves what each frame gave on the
/// screen.
pub fn replay_session(
    request: ReplayRequest<'_>,
    measured: &mut dyn FnMut(Option<&str>, &[PoseVisit]),
) -> anyhow::Result<Replayed> {
    if cameras::is_cameras_folder(request.session) {
        let recorded = cameras::read_manifest(request.session)?.config;
        let config = super::session_config(request.config, &recorded)?;
        let cell = super::prepare_config(config).context("preparing the cell")?;
        // Every camera's frames measured again with its board and lens, as one camera's are.
        let mut visits = Vec::new();
        for (camera, name) in cell
            .cameras
            .iter()
            .zip(cell.config.cameras.iter().map(|c| &c.name))
        {
            let folder = SessionFolder::open(&cameras::camera_folder(request.session, name))?;
            let (_, measured_now) = redetect(
                &folder,
                &camera.board,
                &camera.camera_model,
                cell.detector_options(),
                cell.config.session.max_reprojection_rms_px,
            )?;
            measured(Some(name), &measured_now);
            visits.push(measured_now);
        }
        let output = AnswerOutput::replay(request.session, request.output);
        let result = cameras::solve_cameras_folder(request.session, &cell.config, visits, &output)?;
        return Ok(Replayed::Cameras(Box::new(CamerasReplay {
            folder: request.session.to_path_buf(),
            result,
            output,
        })));
    }
    let folder = SessionFolder::open(request.session)?;
    let manifest = folder.read_manifest()?;
    let config = super::config_of_camera_folder(
        super::session_config(request.config, &manifest.config)?,
        request.session,
    )
    .context("reading the cell config")?;
    let cell = prepare_for(&folder, config)?;
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
    // A cell without configured intrinsics replays with the ones its run estimated.
    let camera_model = if cell.camera().intrinsics_known {
        cell.camera().camera_model
    } else {
        let file = folder.root().join(handeye_records::solve::CAMERA_INFO_FILE);
        CameraModel::load(&file).context(
            "the config has no intrinsics and the session has no estimated ones: solve the session first",
        )?
    };
    let (dataset, visits) = redetect(
        &folder,
        &cell.camera().board,
        &camera_model,
        cell.detector_options(),
        cell.config.session.max_reprojection_rms_px,
    )?;
    measured(None, &visits);
    // Solved and judged as a run's solve is: the checks of the given files included.
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
    let answer_output = AnswerOutput::replay(folder.root(), request.output);
    answer_output.create_folder()?;
    let AnswerOutput {
        result: output,
        estimates,
    } = answer_output;
    // The estimates of a file the cell model blames, beside the replay's result (the run's own
    // stay as they were).
    let written = handeye_records::solve::write_corrected_files(&estimates, &solved, &cell.config)?;
    handeye_records::solve::record_written(&mut solved, &written);
    solved.name_replay(folder.root(), &estimates, &cell.config);
    solved
        .result_file(&dataset.pairs, &cell.config)
        .save(&output)?;
    Ok(Replayed::OneCamera(Box::new(OneCameraReplay {
        folder,
        cell,
        camera_model,
        visits,
        solved,
        dataset,
        output,
    })))
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
