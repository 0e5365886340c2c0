//! The joint solve of a several-camera session folder and its `result.yaml`.
//!
//! The measurements are each camera's pose records (a run's) or its frames measured again (a
//! replay's, `cell::replay`). Each camera is first solved alone from its own (the one-camera pose-space solve with
//! the config's solver settings: robust start, outliers left out, its noise estimated); those
//! answers start the joint solve (`handeye_solve::cameras`), which fits every mount and one board per
//! setup together. `result.yaml` names every transform by its frames (`T_flange_cam_wrist`,
//! `T_base_cam_left`, `T_base_target`, `T_cam_left_cam_right`), with its 1-sigma, and gives a
//! verdict per camera and for the cell. Each camera's own answer is kept beside the joint one
//! (`alone`), so the gain of solving together is on the page. When the config simulates the cell,
//! every transform's error against the simulator's truth is written too.

use std::path::{Path, PathBuf};

use super::{camera_folder, read_manifest};
use crate::cell::replay::AnswerOutput;
use handeye_config::{CellCamera, CellConfig, SolveSpace};
use handeye_core::camera_model::CameraModel;
use handeye_core::geometry::Pose;
use handeye_core::setup::{PosePair, Setup};
use handeye_records::result::{CameraResult, CellResult, NamedTransform, SampleResidualYaml};
use handeye_records::solve::{
    board_pose, frames_from_visits, reprojection_options, write_estimates,
};
use handeye_records::{PoseVisit, SessionError, SessionFolder};
use handeye_solve::cameras::{
    pose_error, solve_cameras, solve_cameras_pixels, CameraSpec, CamerasData, CamerasError,
    CamerasFrame, CamerasObservation, CamerasOptions, CamerasSolution, CamerasStart, PoseResidual,
};
use handeye_solve::cell_model::{fit_cell_model, CellModel};
use handeye_solve::reprojection::Frame;
use handeye_solve::verdict::{self, Accuracy, HeldOut};
use handeye_solve::Calibration;
use handeye_solve::PoseSigma;
use handeye_vision::Target;
use nalgebra::Point3;

/// Why a several-camera session could not be solved.
#[derive(Debug, thiserror::Error)]
pub enum CamerasSolveError {
    /// Reading the folder.
    #[error(transparent)]
    Session(#[from] SessionError),
    /// The joint solve failed.
    #[error("the joint solve: {0}")]
    Joint(#[from] CamerasError),
    /// A camera's board or lens file could not be read.
    #[error("camera `{camera}`: {}: {problem}", file.display())]
    Input {
        /// The camera.
        camera: String,
        /// The file.
        file: PathBuf,
        /// What is wrong.
        problem: String,
    },
    /// No camera has enough views to be solved.
    #[error("no camera saw its board at {0} poses or more: nothing to solve")]
    NothingToSolve(usize),
}

/// The plan poses of the visits that gave a sample.
fn plan_poses_of_samples(visits: &[PoseVisit]) -> Vec<usize> {
    visits
        .iter()
        .filter(|v| v.sample().is_some())
        .map(|v| v.plan_index)
        .collect()
}

/// A camera's residual at each plan pose of its samples (`sample_poses`), in the one-camera
/// result's per-sample form; a sample its own robust solve dropped (so the joint solve left it
/// out) is `dropped`, without a residual.
fn per_pose_residuals(sample_poses: &[usize], joint: &[PoseResidual]) -> Vec<SampleResidualYaml> {
    sample_poses
        .iter()
        .map(|&pose| {
            let r = joint.iter().find(|r| r.pose == pose);
            SampleResidualYaml {
                index: pose,
                id: None,
                rotation_deg: r.map(|r| r.rotation_rad.to_degrees()),
                translation_mm: r.map(|r| r.translation_m * 1e3),
                normalised: None,
                outlier: false,
                dropped: r.is_none(),
            }
        })
        .collect()
}

fn named(
    parent: &str,
    child: &str,
    pose: Pose,
    sigma: PoseSigma,
    truth: Option<Pose>,
) -> NamedTransform {
    let error = truth.map(|t| pose_error(&pose, &t));
    NamedTransform {
        name: format!("T_{parent}_{child}"),
        parent: parent.into(),
        child: child.into(),
        pose,
        sigma: Some(sigma),
        truth_error_deg: error.map(|e| e.0),
        truth_error_mm: error.map(|e| e.1),
    }
}

/// What the joint solve reads from a session: its data with each camera's own answer as the
/// start, and which cameras are in it.
pub struct CamerasProblem {
    /// The data of the cameras in the solve.
    pub data: CamerasData,
    /// Each camera's own answer (same order as `data.cameras`).
    pub start: CamerasStart,
    /// Per camera in `data`: its index in the config.
    pub config_index: Vec<usize>,
    /// Per config camera: accepted samples, and why it is left out (if it is).
    pub cameras: Vec<(usize, Option<String>)>,
    /// Per config camera: the plan poses of its accepted samples.
    pub sample_poses: Vec<Vec<usize>>,
    /// Per config camera: the leave-one-out check of its own samples (the one-camera verdict's
    /// held-out error), or why there is none.
    pub held_out: Vec<Result<HeldOut, String>>,
    /// The corners of every accepted board pose (the pixel-space solve's data).
    pub frames: Vec<CamerasFrame>,
    /// Per camera in `data`: its lens (the cell model's estimate when it corrected the file).
    pub models: Vec<CameraModel>,
    /// Per config camera: its cell model (issue #38: which of its given files its corners
    /// contradict), fitted on its own views; `None` when it is left out or the fit failed.
    pub cell_models: Vec<Option<CellModel>>,
}

/// A camera's board and lens files, read; an error names the camera and the file.
fn camera_files(camera: &CellCamera) -> Result<(Target, CameraModel), CamerasSolveError> {
    let input = |file: &Path, problem: String| CamerasSolveError::Input {
        camera: camera.name.clone(),
        file: file.to_path_buf(),
        problem,
    };
    let board = Target::load(&camera.target).map_err(|e| input(&camera.target, e.to_string()))?;
    let lens = camera.intrinsics.clone().unwrap_or_default();
    let model = CameraModel::load(&lens).map_err(|e| input(&lens, e.to_string()))?;
    Ok((board, model))
}

/// Each camera's measurements as its pose records hold them (config order): what a run
/// measured.
pub fn recorded_visits(
    root: &Path,
    cell: &CellConfig,
) -> Result<Vec<Vec<PoseVisit>>, CamerasSolveError> {
    cell.cameras
        .iter()
        .map(|camera| {
            let folder = SessionFolder::open(&camera_folder(root, &camera.name))?;
            Ok(folder.read_visits()?)
        })
        .collect()
}

/// The joint problem of the session at `root` from each camera's measurements `visits`
/// (config order: recorded, [`recorded_visits`], or measured again from the frames by a
/// replay), each camera solved alone for its start.
pub fn load_joint_problem(
    root: &Path,
    cell: &CellConfig,
    visits: Vec<Vec<PoseVisit>>,
) -> Result<CamerasProblem, CamerasSolveError> {
    let manifest = read_manifest(root)?;
    // The plan as the planner camera's session holds it (an adaptive session's grows there).
    let plan = SessionFolder::open(&camera_folder(root, &manifest.planner))?
        .read_manifest()?
        .plan;
    let mut data = CamerasData {
        cameras: Vec::new(),
        base_from_flange: plan.iter().map(|p| p.base_from_flange).collect(),
        observations: Vec::new(),
    };
    let mut start = CamerasStart {
        camera_mounts: Vec::new(),
        base_from_target: None,
        flange_from_target: None,
    };
    let mut config_index = Vec::new();
    let mut cameras = Vec::new();
    let mut held_out = Vec::new();
    let mut frames = Vec::new();
    let mut models = Vec::new();
    let mut cell_models = Vec::new();
    let mut sample_poses = Vec::new();
    for ((c, camera), visits) in cell.cameras.iter().enumerate().zip(visits) {
        let pairs: Vec<_> = visits.iter().filter_map(|v| v.sample()).collect();
        let samples = pairs.len();
        sample_poses.push(plan_poses_of_samples(&visits));
        if samples < handeye_solve::cameras::MIN_VIEWS_PER_CAMERA {
            held_out.push(Err(format!("only {samples} samples")));
            cameras.push((
                samples,
                Some(format!(
                    "saw its board at {samples} poses; a camera needs at least {} to be solved",
                    handeye_solve::cameras::MIN_VIEWS_PER_CAMERA
                )),
            ));
            continue;
        }
        let setup = camera.setup;
        let options = cell.solver.to_options();
        // A camera whose own solve fails (its samples too few or too alike, say after it was
        // lost early) is left out of the joint solve, named with why; the others are solved.
        let alone = match handeye_solve::solve(setup, &pairs, &options) {
            Ok(alone) => alone,
            Err(e) => {
                let why = format!("its own solve of its {samples} samples failed: {e}");
                held_out.push(Err(why.clone()));
                cameras.push((samples, Some(why)));
                continue;
            }
        };
        let index = data.cameras.len();
        let (board, file_model) = camera_files(camera)?;
        // The joint solve keeps the samples the camera's own robust solve kept.
        let dropped: std::collections::BTreeSet<usize> = alone.dropped.iter().copied().collect();
        let kept: Vec<&PoseVisit> = visits
            .iter()
            .filter(|v| v.sample().is_some())
            .enumerate()
            .filter(|(k, _)| !dropped.contains(k))
            .map(|(_, v)| v)
            .collect();
        let model = camera_cell_model(&cell.for_camera(c), &kept, &board, &file_model, &alone);
        // Where the views determine a wrong file's quantity, the camera's board poses, its lens
        // and its board points are those of the estimate: its held-out check and the joint solve
        // judge and use the corrected cell, not the wrong file.
        let correction = model
            .as_ref()
            .filter(|m| m.summary.corrects())
            .map(|m| (m.camera(), m.board_scale()));
        let (lens_used, scale) = correction.unwrap_or((file_model, 1.0));
        let corners_of = |visit: &PoseVisit| -> Vec<_> {
            visit
                .corners_px
                .iter()
                .filter_map(|c| {
                    board
                        .observation_point(c)
                        .map(|p| (Point3::from(p.coords * scale), c.pixel))
                })
                .collect()
        };
        let corrected_pose = |visit: &PoseVisit| {
            correction
                .and_then(|_| board_pose(&lens_used, &corners_of(visit)))
                .or(visit.camera_from_target)
        };
        let judged: Vec<_> = visits
            .iter()
            .filter_map(|v| {
                v.sample().map(|pair| PosePair {
                    camera_from_target: corrected_pose(v).unwrap_or(pair.camera_from_target),
                    ..pair
                })
            })
            .collect();
        held_out.push(verdict::held_out(setup, &judged, &options, &alone));
        models.push(lens_used);
        let weights = ViewWeights::of(&pairs, &kept, &options);
        for visit in kept {
            if let Some(camera_from_target) = corrected_pose(visit) {
                // Every camera records the same flange pose at a plan index; the reported pose
                // (not the planned one) is what the solve must use.
                data.base_from_flange[visit.plan_index] = visit.base_from_flange;
                data.observations.push(CamerasObservation {
                    camera: index,
                    pose: visit.plan_index,
                    camera_from_target,
                    weight: weights.board_pose(visit),
                });
                frames.push(CamerasFrame {
                    camera: index,
                    pose: visit.plan_index,
                    corners: corners_of(visit),
                    weight: weights.corners(visit),
                });
            }
        }
        data.cameras.push(CameraSpec {
            name: camera.name.clone(),
            setup,
            noise: alone.noise.map_or(options.noise, |n| n.model()),
        });
        start.camera_mounts.push(match (&model, correction) {
            (Some(m), Some(_)) => m.fit.camera_mount,
            _ => alone.camera_mount,
        });
        cell_models.resize(c, None);
        cell_models.push(model);
        // The board of each setup starts from the first camera of that setup.
        let board_start = match setup {
            Setup::EyeInHand => &mut start.base_from_target,
            Setup::EyeToHand => &mut start.flange_from_target,
        };
        board_start.get_or_insert(alone.target_mount);
        config_index.push(c);
        cameras.push((samples, None));
    }
    if data.cameras.is_empty() {
        return Err(CamerasSolveError::NothingToSolve(
            handeye_solve::cameras::MIN_VIEWS_PER_CAMERA,
        ));
    }
    Ok(CamerasProblem {
        data,
        start,
        config_index,
        cameras,
        sample_poses,
        held_out,
        frames,
        models,
        cell_models: {
            cell_models.resize(cell.cameras.len(), None);
            cell_models
        },
    })
}

/// The cell model of one camera (issue #38), fitted on the corners of its `kept` visits through
/// the lens and board of its files, from its own pose-space answer `alone`; `None` when the fit
/// fails (fewer than 3 frames with corners, say): its verdict then rests on its mount alone.
fn camera_cell_model(
    config: &CellConfig,
    kept: &[&PoseVisit],
    board: &Target,
    lens: &CameraModel,
    alone: &Calibration,
) -> Option<CellModel> {
    let frames: Vec<Frame> = frames_from_visits(kept.iter().copied(), board, true)
        .ok()?
        .into_iter()
        .map(|(_, frame)| frame)
        .collect();
    if frames.len() < 3 {
        return None;
    }
    fit_cell_model(
        config.camera().setup,
        &frames,
        lens,
        &alone.camera_mount,
        &alone.target_mount,
        &reprojection_options(config),
        config.verdict.accuracy(),
    )
    .ok()
}

/// Solves a several-camera session folder jointly from each camera's measurements `visits`
/// (config order; [`load_joint_problem`]) and writes the result and the estimates where
/// `output` says.
pub fn solve_cameras_folder(
    root: &Path,
    cell: &CellConfig,
    visits: Vec<Vec<PoseVisit>>,
    output: &AnswerOutput,
) -> Result<CellResult, CamerasSolveError> {
    let problem = load_joint_problem(root, cell, visits)?;
    let joint = solve_joint(&problem, pixel_space(cell), robot_sigma(cell))?;
    let mut result = result_file(cell, &problem, &joint);
    let written = write_corrected_files(output, cell, &problem)?;
    for (entry, files) in result.cameras.iter_mut().zip(written) {
        let model = entry
            .verdict
            .as_mut()
            .and_then(|v| v.figures.cell_model.as_mut());
        if let Some(model) = model {
            model.written = files.iter().map(|p| p.display().to_string()).collect();
        }
    }
    name_files(root, output, cell, &mut result);
    output.create_folder()?;
    result.save(&output.result).map_err(SessionError::from)?;
    Ok(result)
}

/// Writes the estimate of each camera whose cell model corrects a file into its own folder
/// (`camera_info.yaml`, `board.yaml`); per config camera, the files written.
fn write_corrected_files(
    output: &AnswerOutput,
    cell: &CellConfig,
    problem: &CamerasProblem,
) -> Result<Vec<Vec<PathBuf>>, SessionError> {
    let mut written = Vec::new();
    for (camera, model) in cell.cameras.iter().zip(&problem.cell_models) {
        written.push(match model {
            Some(model) => write_estimates(
                &output.estimates_of(&camera.name),
                &model.summary,
                &model.fit,
                &camera.target,
            )?,
            None => Vec::new(),
        });
    }
    Ok(written)
}

/// Names each camera's folder, its estimates' folder, the cell config, its board and lens
/// files in its verdict's advice, and the cell's verdict again from them.
fn name_files(root: &Path, output: &AnswerOutput, cell: &CellConfig, result: &mut CellResult) {
    for (camera, entry) in cell.cameras.iter().zip(&mut result.cameras) {
        let files = verdict::SessionFiles {
            session: camera_folder(root, &camera.name).display().to_string(),
            estimates: output.estimates_of(&camera.name).display().to_string(),
            config: cell.file.display().to_string(),
            board: camera.target.display().to_string(),
            intrinsics: camera
                .intrinsics
                .as_ref()
                .map(|f| f.display().to_string())
                .unwrap_or_default(),
        };
        if let Some(verdict) = entry.verdict.as_mut() {
            verdict.name_session(&files);
        }
    }
    result.verdict = Some(cell_verdict(&result.cameras, cell.verdict.accuracy()));
}

/// Whether the config asks for the answer in pixel space (`solver.space: reprojection`, the
/// default) rather than pose space.
pub fn pixel_space(cell: &CellConfig) -> bool {
    cell.solver.space == SolveSpace::Reprojection
}

/// The robot's repeatability (m, rad) the pixel-space solve estimates the flange poses with.
pub fn robot_sigma(cell: &CellConfig) -> (f64, f64) {
    cell.robot_repeatability()
}

/// The joint answer: pose space, then (when `pixels`) refined on the corners with every flange
/// pose estimated around the reported one (1-sigma `robot`, m and rad).
pub fn solve_joint(
    problem: &CamerasProblem,
    pixels: bool,
    robot: (f64, f64),
) -> Result<CamerasSolution, CamerasError> {
    solve_subset(problem, &problem.data, &problem.start, None, pixels, robot)
}

/// The joint answer of `data` (all cameras, or camera `only` of `problem` alone).
fn solve_subset(
    problem: &CamerasProblem,
    data: &CamerasData,
    start: &CamerasStart,
    only: Option<usize>,
    pixels: bool,
    robot: (f64, f64),
) -> Result<CamerasSolution, CamerasError> {
    let pose_space = solve_cameras(data, start, &CamerasOptions::default())?;
    if !pixels {
        return Ok(pose_space);
    }
    let (models, frames): (Vec<CameraModel>, Vec<CamerasFrame>) = match only {
        None => (problem.models.clone(), problem.frames.clone()),
        Some(k) => (
            vec![problem.models[k]],
            problem
                .frames
                .iter()
                .filter(|f| f.camera == k)
                .map(|f| CamerasFrame {
                    camera: 0,
                    ..f.clone()
                })
                .collect(),
        ),
    };
    let options = CamerasOptions {
        robot_sigma: Some(robot),
        ..CamerasOptions::default()
    };
    solve_cameras_pixels(data, &models, &frames, &pose_space, &options)
}

/// A camera's views at their precision in the joint solve.
struct ViewWeights {
    /// Each sample's board-pose weight by its id (`pose-NNN`), as the camera's own solve weighs
    /// it (`SolveOptions::weighted`: its view's 1-sigma against the typical view's).
    board_poses: std::collections::HashMap<String, f64>,
    /// The camera's typical board RMS over the views kept, px.
    typical_rms_px: f64,
}

impl ViewWeights {
    fn of(
        pairs: &[PosePair],
        kept: &[&PoseVisit],
        options: &handeye_solve::SolveOptions,
    ) -> ViewWeights {
        let board_rms: Vec<f64> = kept.iter().filter_map(|v| v.reprojection_rms_px).collect();
        ViewWeights {
            board_poses: options
                .weighted(pairs)
                .iter()
                .filter_map(|pair| Some((pair.id.clone()?, pair.weight)))
                .collect(),
            typical_rms_px: handeye_solve::diagnostics::median(&board_rms),
        }
    }

    /// The weight of `visit`'s board pose in the pose-space solve.
    fn board_pose(&self, visit: &PoseVisit) -> f64 {
        self.board_poses
            .get(&visit.sample_id())
            .copied()
            .unwrap_or(1.0)
    }

    /// The weight of `visit`'s corners in the pixel-space solve: a frame of small, far or
    /// oblique tags fits its corners worse than the camera's typical frame (its board RMS) and
    /// counts for less, by the rule of the board poses (`handeye_solve::relative_weight`).
    fn corners(&self, visit: &PoseVisit) -> f64 {
        visit.reprojection_rms_px.map_or(1.0, |rms| {
            handeye_solve::relative_weight((rms / self.typical_rms_px).powi(2))
        })
    }
}

/// `result.yaml` from the joint answer; each camera's own answer is solved again by the same
/// estimator with its views alone, so `alone` and `joint` differ only by solving together.
pub fn result_file(
    cell: &CellConfig,
    problem: &CamerasProblem,
    joint: &CamerasSolution,
) -> CellResult {
    let accuracy = cell.verdict.accuracy();
    let truth_of = |c: usize| cell.cameras[c].simulation.map(|s| s.camera_mount);
    let mut cameras = Vec::new();
    for (c, camera) in cell.cameras.iter().enumerate() {
        let (samples, left_out) = problem.cameras[c].clone();
        let setup = camera.setup;
        let frame = &camera.frame;
        let mut entry = CameraResult {
            name: camera.name.clone(),
            setup,
            samples,
            left_out: left_out.clone(),
            joint: None,
            alone: None,
            corner_noise_px: None,
            residual_rotation_rms_deg: None,
            residual_translation_rms_mm: None,
            residuals_per_pose: Vec::new(),
            held_out: problem.held_out[c].as_ref().ok().copied(),
            verdict: Some(verdict::mount::left_out(
                left_out.as_deref().unwrap_or_default(),
                samples,
                accuracy,
            )),
            answer: None,
        };
        if let Some(k) = problem.config_index.iter().position(|&i| i == c) {
            // The mount's parent frame: `flange` (eye in hand) or `base` (eye to hand).
            let [(parent, _), _] = setup.unknown_frames();
            entry.joint = Some(named(
                parent,
                frame,
                joint.camera_mounts[k],
                joint.camera_sigmas[k],
                truth_of(c),
            ));
            let start_alone = CamerasStart {
                camera_mounts: vec![problem.start.camera_mounts[k]],
                ..problem.start.clone()
            };
            if let Ok(alone) = solve_subset(
                problem,
                &problem.data.only(k),
                &start_alone,
                Some(k),
                pixel_space(cell),
                robot_sigma(cell),
            ) {
                entry.alone = Some(named(
                    parent,
                    frame,
                    alone.camera_mounts[0],
                    alone.camera_sigmas[0],
                    truth_of(c),
                ));
            }
            entry.corner_noise_px = joint.pixel_sigma_px.get(k).copied();
            entry.residual_rotation_rms_deg = Some(joint.residuals[k].rotation_rms_deg);
            entry.residual_translation_rms_mm = Some(joint.residuals[k].translation_rms_mm);
            entry.residuals_per_pose =
                per_pose_residuals(&problem.sample_poses[c], &joint.residuals[k].per_pose);
            entry.verdict = Some(verdict::assess_mount(
                &joint.camera_sigmas[k],
                problem.held_out[c].as_ref().map_err(String::as_str),
                samples,
                accuracy,
                problem.cell_models[c].as_ref().map(|m| &m.summary),
            ));
        }
        cameras.push(entry);
    }
    let cell_verdict = cell_verdict(&cameras, accuracy);
    let board_truth = |setup: Setup| {
        cell.cameras
            .iter()
            .find(|c| c.setup == setup)
            .and_then(|c| c.simulation.map(|s| s.target_mount))
    };
    // The board of each setup the cell has: eye-in-hand cameras see it in the cell, eye-to-hand
    // ones on the flange.
    let boards: Vec<NamedTransform> = [
        (Setup::EyeInHand, joint.base_from_target),
        (Setup::EyeToHand, joint.flange_from_target),
    ]
    .into_iter()
    .filter_map(|(setup, board)| {
        let (pose, sigma) = board?;
        Some(named(
            setup.unknown_frames()[1].0,
            "target",
            pose,
            sigma,
            board_truth(setup),
        ))
    })
    .collect();
    let camera_to_camera = joint
        .relative
        .iter()
        .map(|r| {
            let (from, to) = (problem.config_index[r.from], problem.config_index[r.to]);
            let truth = truth_of(from)
                .zip(truth_of(to))
                .map(|(a, b)| a.inverse() * b);
            named(
                &cell.cameras[from].frame,
                &cell.cameras[to].frame,
                r.pose,
                r.sigma,
                truth,
            )
        })
        .collect();
    CellResult {
        robot_frames: Some(cell.robot.frames()),
        cameras,
        boards,
        camera_to_camera,
        variance_factor: Some(joint.variance_factor),
        verdict: Some(cell_verdict),
    }
}

/// The cell's verdict: the worst of its cameras' (each several-camera entry has one).
fn cell_verdict(cameras: &[CameraResult], accuracy: Accuracy) -> verdict::Verdict {
    verdict::worst_camera(
        cameras
            .iter()
            .filter_map(|c| Some((c.name.as_str(), c.verdict.as_ref()?))),
        accuracy,
    )
}
