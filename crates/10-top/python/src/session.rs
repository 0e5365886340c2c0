//! `handeye.Session`: a session folder (what `handeye run` writes) read from Python: its samples,
//! its result and verdict, the simulator's ground truth when the cell is simulated, and
//! `solve(space=...)` as `handeye solve DIR --space ...` runs it (the session's config for the
//! board, the intrinsics and the solver settings). Also `read_dataset` for a dataset file.
//!
//! Reading never locks the folder and writes nothing, except what the session solve itself
//! writes when the intrinsics are estimated (`camera_info.yaml`, `samples.yaml`, as the CLI).

use std::path::{Path, PathBuf};

use handeye_config::{CellConfig, SolveSpace};
use handeye_core::geometry::Pose;
use handeye_core::setup::PosePair;
use handeye_records::dataset::Dataset;
use handeye_records::result::CellResult;
use handeye_records::{SessionFolder, SolveInputs};
use handeye_session::cell::cameras;
use handeye_solve::verdict::Verdict;
use numpy::IntoPyArray;
use pyo3::prelude::*;
use pyo3::types::PyDict;

use crate::calibrate::{Calibration, VerdictPy};
use crate::convert::{pose_to_py, poses_to_py};
use crate::errors;

/// A dataset as Python objects: `{"setup", "T_base_flange" (N, 4, 4), "T_camera_target"
/// (N, 4, 4), "ids", "weights", "view_sigmas" (N, 2)}`; a view's precision is `(rotation_deg,
/// translation_mm)`, a row of NaN where the sample records none (what `calibrate` reads as a
/// view of unknown precision).
fn dataset_to_py<'py>(py: Python<'py>, dataset: &Dataset) -> PyResult<Bound<'py, PyDict>> {
    let flange: Vec<Pose> = dataset.pairs.iter().map(|p| p.base_from_flange).collect();
    let camera: Vec<Pose> = dataset.pairs.iter().map(|p| p.camera_from_target).collect();
    let dict = PyDict::new(py);
    dict.set_item("setup", dataset.setup.name())?;
    dict.set_item("T_base_flange", poses_to_py(py, &flange))?;
    dict.set_item("T_camera_target", poses_to_py(py, &camera))?;
    let ids: Vec<Option<String>> = dataset.pairs.iter().map(|p| p.id.clone()).collect();
    dict.set_item("ids", ids)?;
    let weights: Vec<f64> = dataset.pairs.iter().map(|p| p.weight).collect();
    dict.set_item("weights", weights)?;
    let view_sigmas = numpy::ndarray::Array2::from_shape_fn((dataset.pairs.len(), 2), |(i, k)| {
        dataset.pairs[i]
            .view_sigma
            .map_or(f64::NAN, |s| [s.rotation_deg, s.translation_mm][k])
    });
    dict.set_item("view_sigmas", view_sigmas.into_pyarray(py))?;
    Ok(dict)
}

/// Reads a dataset file (`handeye solve`'s input, a session's `samples.yaml`).
#[pyfunction]
pub(crate) fn read_dataset(py: Python<'_>, path: PathBuf) -> PyResult<Bound<'_, PyDict>> {
    let dataset = Dataset::load(&path).map_err(|e| errors::from_error(py, &e))?;
    dataset_to_py(py, &dataset)
}

/// Reads a result file (`handeye solve -o`, a session's `result.yaml`) as a [`Calibration`]
/// with the verdict it holds; `pairs` are its samples when known (for ids).
fn read_result(py: Python<'_>, path: &Path, pairs: Vec<PosePair>) -> PyResult<Calibration> {
    let cell = CellResult::load(path).map_err(|e| errors::from_error(py, &e))?;
    // One Calibration is one camera's answer: the cell's is the session's `joint`.
    let Some(file) = cell.only_camera() else {
        return Err(errors::input(
            py,
            format!(
                "{}: a several-camera result: read it with handeye.Session({:?}), whose .joint holds every transform and .cameras[name] each camera's own session",
                path.display(),
                path.parent().unwrap_or(Path::new(".")).display().to_string()
            ),
        ));
    };
    let inner = file
        .to_calibration(path)
        .map_err(|e| errors::from_error(py, &e))?;
    Ok(Calibration::with_verdict(
        inner,
        pairs,
        file.verdict.clone(),
        None,
    ))
}

/// Reads a result file as a `Calibration` (transforms, 1-sigma, residuals, notices, verdict).
#[pyfunction]
#[pyo3(name = "read_result")]
pub(crate) fn read_result_py(py: Python<'_>, path: PathBuf) -> PyResult<Calibration> {
    read_result(py, &path, Vec::new())
}

/// A recorded session folder: one camera's, or a cell's with several cameras (`rig.yaml` and a
/// one-camera session folder per camera under `cameras/`).
#[pyclass(name = "Session", module = "handeye", frozen)]
pub(crate) struct Session {
    root: PathBuf,
    /// The session folder read: `root`, or for a listed cell of one camera its camera's folder.
    read: PathBuf,
    config: PathBuf,
    /// One camera's setup; `None` for several cameras (each has its own).
    setup: Option<&'static str>,
    /// Several cameras: their names, config order (empty for one camera).
    cameras: Vec<String>,
}

impl Session {
    /// Refuses `what` of a several-camera session, naming where each camera's is.
    fn one_camera(&self, py: Python<'_>, what: &str) -> PyResult<()> {
        match self.cameras.first() {
            None => Ok(()),
            Some(first) => Err(errors::input(
                py,
                format!(
                    "session {} has {} cameras ({}): `{what}` is each camera's, session.cameras[{first:?}].{what}; the joint answer is session.joint",
                    self.root.display(),
                    self.cameras.len(),
                    self.cameras.join(", ")
                ),
            )),
        }
    }

    /// Several cameras: the joint answer (`result.yaml` at the root), None when not solved.
    fn joint_file(&self, py: Python<'_>) -> PyResult<Option<CellResult>> {
        let path = self.root.join("result.yaml");
        if self.cameras.is_empty() || !path.exists() {
            return Ok(None);
        }
        CellResult::load(&path)
            .map(Some)
            .map_err(|e| errors::from_error(py, &e))
    }

    fn folder(&self, py: Python<'_>) -> PyResult<SessionFolder> {
        SessionFolder::open(&self.read).map_err(|e| errors::from_error(py, &e))
    }

    fn dataset(&self, py: Python<'_>) -> PyResult<Dataset> {
        Dataset::load(&self.folder(py)?.samples_path()).map_err(|e| errors::from_error(py, &e))
    }

    fn load_config(&self, py: Python<'_>, config: Option<PathBuf>) -> PyResult<CellConfig> {
        let path = config.unwrap_or_else(|| self.config.clone());
        CellConfig::load(&path)
            .and_then(|c| handeye_session::cell::config_of_camera_folder(c, &self.read))
            .map_err(|e| errors::with_context(py, "reading the cell config", &e))
    }
}

#[pymethods]
impl Session {
    /// Opens the session folder at `path` (it must hold `session.yaml`, or `rig.yaml` for a
    /// cell with several cameras; a listed cell of one camera opens as its camera's session).
    #[new]
    pub(crate) fn new(py: Python<'_>, path: PathBuf) -> PyResult<Session> {
        // A listed cell of one camera is its camera's session (`cameras/<name>`).
        let read = cameras::session_to_read(&path);
        if cameras::is_cameras_folder(&read) {
            let manifest = cameras::read_manifest(&path).map_err(|e| errors::from_error(py, &e))?;
            return Ok(Session {
                root: path,
                read,
                config: manifest.config,
                setup: None,
                cameras: manifest.cameras.into_iter().map(|c| c.name).collect(),
            });
        }
        let folder = SessionFolder::open(&read).map_err(|e| errors::from_error(py, &e))?;
        let manifest = folder
            .read_manifest()
            .map_err(|e| errors::from_error(py, &e))?;
        Ok(Session {
            root: path,
            read,
            config: manifest.config,
            setup: Some(manifest.setup.name()),
            cameras: Vec::new(),
        })
    }

    /// The folder.
    #[getter]
    fn path(&self) -> PathBuf {
        self.root.clone()
    }

    /// The cell config the session was recorded with.
    #[getter]
    fn config(&self) -> PathBuf {
        self.config.clone()
    }

    /// `"eye_in_hand"` or `"eye_to_hand"`; None for several cameras (each camera's session
    /// has its own).
    #[getter]
    fn setup(&self) -> Option<&'static str> {
        self.setup
    }

    /// Several cameras: each camera's own session (`cameras/<name>`, its frames, samples and
    /// setup) by name, config order; empty for one camera.
    #[getter]
    fn cameras<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let dict = PyDict::new(py);
        for name in &self.cameras {
            let session = Session::new(py, cameras::camera_folder(&self.root, name))?;
            dict.set_item(name, Py::new(py, session)?)?;
        }
        Ok(dict)
    }

    /// Several cameras: the joint answer of `result.yaml` (None when not solved):
    /// `{"transforms": {name: 4x4}, "sigma": {name: {"rotation_deg", "translation_mm"}},
    /// "truth_error": {name: {"rotation_deg", "translation_mm"}}` (a simulated cell's),
    /// `"verdicts": {camera: Verdict}, "verdict": Verdict}` (the cell's: its worst camera's).
    /// None for one camera (its answer is `result`).
    #[getter]
    fn joint<'py>(&self, py: Python<'py>) -> PyResult<Option<Bound<'py, PyDict>>> {
        let Some(file) = self.joint_file(py)? else {
            return Ok(None);
        };
        let (transforms, sigma, truth) = (PyDict::new(py), PyDict::new(py), PyDict::new(py));
        let figures = |deg: f64, mm: f64| -> PyResult<Bound<'py, PyDict>> {
            let d = PyDict::new(py);
            d.set_item("rotation_deg", deg)?;
            d.set_item("translation_mm", mm)?;
            Ok(d)
        };
        for t in file.transforms() {
            transforms.set_item(&t.name, pose_to_py(py, &t.pose))?;
            if let Some(s) = t.sigma {
                sigma.set_item(&t.name, figures(s.rotation_deg, s.translation_mm)?)?;
            }
            if let (Some(deg), Some(mm)) = (t.truth_error_deg, t.truth_error_mm) {
                truth.set_item(&t.name, figures(deg, mm)?)?;
            }
        }
        let verdicts = PyDict::new(py);
        for camera in &file.cameras {
            verdicts.set_item(&camera.name, verdict_py(py, camera.verdict.clone())?)?;
        }
        let joint = PyDict::new(py);
        joint.set_item("transforms", transforms)?;
        joint.set_item("sigma", sigma)?;
        joint.set_item("truth_error", truth)?;
        joint.set_item("verdicts", verdicts)?;
        joint.set_item("verdict", verdict_py(py, file.verdict)?)?;
        Ok(Some(joint))
    }

    /// The accepted samples (`samples.yaml`): `{"setup", "T_base_flange" (N, 4, 4),
    /// "T_camera_target" (N, 4, 4), "ids", "weights"}`, metres.
    #[getter]
    fn samples<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        self.one_camera(py, "samples")?;
        dataset_to_py(py, &self.dataset(py)?)
    }

    /// The session's `result.yaml` as a `Calibration` (with its verdict), or None when the
    /// session was not solved.
    #[getter]
    fn result(&self, py: Python<'_>) -> PyResult<Option<Calibration>> {
        self.one_camera(py, "result")?;
        let path = self.folder(py)?.result_path();
        if !path.exists() {
            return Ok(None);
        }
        let pairs = self.dataset(py).map(|d| d.pairs).unwrap_or_default();
        read_result(py, &path, pairs).map(Some)
    }

    /// The verdict of `result.yaml` (several cameras: the cell's), or None.
    #[getter]
    fn verdict(&self, py: Python<'_>) -> PyResult<Option<Py<VerdictPy>>> {
        if !self.cameras.is_empty() {
            return match self.joint_file(py)? {
                Some(file) => verdict_py(py, file.verdict),
                None => Ok(None),
            };
        }
        match self.result(py)? {
            Some(result) => result.verdict(py),
            None => Ok(None),
        }
    }

    /// The simulator's ground truth (`simulation:` of the session's config) by frame name
    /// (`{"T_flange_camera": 4x4, "T_base_target": 4x4}`), or None for a real cell.
    #[getter]
    fn truth<'py>(&self, py: Python<'py>) -> PyResult<Option<Bound<'py, PyDict>>> {
        self.one_camera(py, "truth")?;
        let config = self.load_config(py, None)?;
        let Some(truth) = config.camera().simulation else {
            return Ok(None);
        };
        let dict = PyDict::new(py);
        for (name, pose) in truth.unknowns() {
            dict.set_item(name, pose_to_py(py, &pose))?;
        }
        Ok(Some(dict))
    }

    /// Solves the session as `handeye solve DIR --space SPACE [--config CONFIG]` does, and
    /// returns the answer (with its verdict; the reprojection summary in `.reprojection`);
    /// warns with `CalibrationWarning` when the verdict is not GOOD.
    /// Writes no result file (`Calibration.save` does).
    #[pyo3(signature = (space = None, config = None))]
    fn solve(
        &self,
        py: Python<'_>,
        space: Option<&str>,
        config: Option<PathBuf>,
    ) -> PyResult<Calibration> {
        self.one_camera(py, "solve()")?;
        let folder = self.folder(py)?;
        let config = self.load_config(py, config)?;
        let space = match space {
            None => config.solver.space,
            Some("pose") => SolveSpace::Pose,
            Some("reprojection") => SolveSpace::Reprojection,
            Some(other) => {
                return Err(errors::input(
                    py,
                    format!("space `{other}`: expected `pose` or `reprojection`"),
                ))
            }
        };
        let inputs = SolveInputs::load(config).map_err(|e| errors::from_error(py, &e))?;
        let (solved, dataset) = py
            .detach(|| handeye_records::load_and_solve(&folder, &inputs, space))
            .map_err(|e| {
                errors::with_context(py, &format!("solving session {}", self.root.display()), &e)
            })?;
        let reprojection = solved
            .reprojection_summary()
            .map(|s| serde_json::to_value(s).unwrap_or(serde_json::Value::Null));
        let calibration = Calibration::with_verdict(
            solved.calibration,
            dataset.pairs,
            solved.verdict,
            reprojection,
        );
        errors::warn_verdict(py, calibration.verdict(py)?)?;
        Ok(calibration)
    }

    fn __repr__(&self) -> String {
        match self.setup {
            Some(setup) => format!("<handeye.Session {} ({setup})>", self.root.display()),
            None => format!(
                "<handeye.Session {} ({} cameras)>",
                self.root.display(),
                self.cameras.len()
            ),
        }
    }
}

/// A result's verdict for Python (None where the file holds none).
fn verdict_py(py: Python<'_>, verdict: Option<Verdict>) -> PyResult<Option<Py<VerdictPy>>> {
    verdict
        .map(|inner| Py::new(py, VerdictPy { inner }))
        .transpose()
}
