//! `handeye.calibrate`: pose pairs as numpy arrays in, a [`Calibration`] out (both transforms,
//! their 1-sigma, the residuals, the notices, and the verdict with its reason).
//!
//! The options are the CLI's (`handeye solve`): the same defaults (the refined method, the
//! board-pose noise estimated from the residuals, outliers dropped and named), the same checks
//! of explicit sigmas, and the same verdict (`verdict::assess_result` at the default accuracy
//! unless one is given). The verdict needs a held-out solve per sample, so it is computed when
//! first read (`Calibration.verdict`), not by `calibrate` itself.

use std::path::PathBuf;
use std::sync::OnceLock;

use handeye_config::validate;
use handeye_core::error_text::error_chain;
use handeye_core::geometry::Pose;
use handeye_core::setup::{PosePair, Setup, ViewSigma};
use handeye_records::result::ResultFile;
use handeye_solve::verdict::{self, Accuracy, Verdict};
use handeye_solve::{Method, RobustLoss, SolveError, SolveOptions, SolverChoice};
use numpy::{IntoPyArray, PyArray2, PyArray3};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};

use crate::convert::{pose_to_py_in, poses_from_any, poses_from_rt, poses_to_py_in, to_py, Units};
use crate::errors;

/// The setup named by `name` (`eye_in_hand` or `eye_to_hand`).
pub(crate) fn parse_setup(py: Python<'_>, name: &str) -> PyResult<Setup> {
    match name {
        "eye_in_hand" => Ok(Setup::EyeInHand),
        "eye_to_hand" => Ok(Setup::EyeToHand),
        other => Err(errors::input(
            py,
            format!("setup `{other}`: expected `eye_in_hand` (camera on the flange) or `eye_to_hand` (camera fixed, board on the flange)"),
        )),
    }
}

/// The solver options of `handeye solve` from its arguments (names as in Python).
#[allow(clippy::too_many_arguments)]
fn options(
    py: Python<'_>,
    method: &str,
    rotation_sigma_deg: Option<f64>,
    translation_sigma_mm: Option<f64>,
    robust: &str,
    robust_scale: f64,
    keep_outliers: bool,
    warm_start: bool,
    weigh_views: bool,
) -> PyResult<SolveOptions> {
    let method: Method = method.parse().map_err(|e: String| errors::input(py, e))?;
    // Checked as the CLI and the config's `solver:` section check them.
    validate::check_solver_choice(
        rotation_sigma_deg,
        translation_sigma_mm,
        robust_scale,
        &str::to_string,
    )
    .map_err(|e| errors::input(py, e))?;
    let robust = RobustLoss::named(robust, robust_scale).map_err(|e| errors::input(py, e))?;
    Ok(SolverChoice {
        method,
        rotation_sigma_deg,
        translation_sigma_mm,
        estimate_noise: true,
        robust,
        drop_outliers: !keep_outliers,
        // Samples without a view precision (`view_sigmas` not given) weigh alike either way.
        weigh_views,
        warm_start,
    }
    .options())
}

/// The accuracy the verdict judges against (mm, degrees).
pub(crate) fn accuracy(py: Python<'_>, accuracy_mm: f64, accuracy_deg: f64) -> PyResult<Accuracy> {
    for (name, value) in [("accuracy_mm", accuracy_mm), ("accuracy_deg", accuracy_deg)] {
        if !(value.is_finite() && value > 0.0) {
            return Err(errors::input(
                py,
                format!("{name} = {value}: must be a positive number"),
            ));
        }
    }
    Ok(Accuracy {
        translation_mm: accuracy_mm,
        rotation_deg: accuracy_deg,
    })
}

/// Solves for both unknowns of a cell (see the package docstring in `handeye/__init__.py`).
#[pyfunction]
#[pyo3(signature = (
    base_from_flange, camera_from_target, setup = "eye_in_hand", *, method = "refined",
    rotation_sigma_deg = None, translation_sigma_mm = None, robust = "none", robust_scale = 3.0,
    keep_outliers = false, warm_start = false, ids = None, weights = None, view_sigmas = None,
    weigh_views = true, accuracy_mm = verdict::DEFAULT_ACCURACY_MM, accuracy_deg = verdict::DEFAULT_ACCURACY_DEG,
    units = "m",
))]
#[allow(clippy::too_many_arguments)]
pub(crate) fn calibrate(
    py: Python<'_>,
    base_from_flange: &Bound<'_, PyAny>,
    camera_from_target: &Bound<'_, PyAny>,
    setup: &str,
    method: &str,
    rotation_sigma_deg: Option<f64>,
    translation_sigma_mm: Option<f64>,
    robust: &str,
    robust_scale: f64,
    keep_outliers: bool,
    warm_start: bool,
    ids: Option<Vec<String>>,
    weights: Option<Vec<f64>>,
    view_sigmas: Option<Vec<Option<(f64, f64)>>>,
    weigh_views: bool,
    accuracy_mm: f64,
    accuracy_deg: f64,
    units: &str,
) -> PyResult<Calibration> {
    let setup = parse_setup(py, setup)?;
    let options = options(
        py,
        method,
        rotation_sigma_deg,
        translation_sigma_mm,
        robust,
        robust_scale,
        keep_outliers,
        warm_start,
        weigh_views,
    )?;
    let accuracy = accuracy(py, accuracy_mm, accuracy_deg)?;
    let units = Units::parse(py, units)?;
    let flange = poses_from_any(py, base_from_flange, "T_base_flange", units)?;
    let camera = poses_from_any(py, camera_from_target, "T_camera_target", units)?;
    if flange.len() != camera.len() {
        return Err(errors::input(
            py,
            format!(
                "T_base_flange has {} poses but T_camera_target has {}: give one of each per sample",
                flange.len(),
                camera.len()
            ),
        ));
    }
    let n = flange.len();
    for (name, len) in [
        ("ids", ids.as_ref().map(Vec::len)),
        ("weights", weights.as_ref().map(Vec::len)),
        ("view_sigmas", view_sigmas.as_ref().map(Vec::len)),
    ] {
        if let Some(len) = len.filter(|&len| len != n) {
            return Err(errors::input(
                py,
                format!("{name} has {len} entries for {n} samples: give one per sample"),
            ));
        }
    }
    // Each view's precision checked as a file's `view_sigma` is (`ViewSigma::new`).
    let view_sigmas: Vec<Option<ViewSigma>> = match view_sigmas {
        None => vec![None; n],
        Some(rows) => rows
            .into_iter()
            .enumerate()
            .map(|(i, row)| {
                row.map(|(r, t)| ViewSigma::new(r, t))
                    .transpose()
                    .map_err(|e| {
                        errors::input(
                            py,
                            format!("view_sigmas[{i}]: {e}; None for a view of unknown precision"),
                        )
                    })
            })
            .collect::<PyResult<_>>()?,
    };
    let pairs: Vec<PosePair> = flange
        .into_iter()
        .zip(camera)
        .zip(view_sigmas)
        .enumerate()
        .map(
            |(i, ((base_from_flange, camera_from_target), view_sigma))| PosePair {
                base_from_flange,
                camera_from_target,
                weight: weights.as_ref().map_or(1.0, |w| w[i]),
                id: ids.as_ref().map(|ids| ids[i].clone()),
                view_sigma,
            },
        )
        .collect();
    solve_pairs(py, setup, pairs, options, accuracy, units)
}

/// The solve of the OpenCV-shaped calls (`calibrateHandEye`, `calibrateRobotWorldHandEye`):
/// lists of rotations and translations (`names` in errors: robot side first), every check in
/// Rust, then the solve of [`calibrate`] with its defaults and `method`. With `invert_flange`
/// the robot side is `T_flange_base` (OpenCV's `base2gripper`) and is inverted.
#[pyfunction]
#[pyo3(signature = (
    robot_rotations, robot_translations, camera_rotations, camera_translations, names, *,
    method = "refined", units = "m", invert_flange = false,
))]
#[allow(clippy::too_many_arguments)]
pub(crate) fn calibrate_rt(
    py: Python<'_>,
    robot_rotations: &Bound<'_, PyAny>,
    robot_translations: &Bound<'_, PyAny>,
    camera_rotations: &Bound<'_, PyAny>,
    camera_translations: &Bound<'_, PyAny>,
    names: [String; 4],
    method: &str,
    units: &str,
    invert_flange: bool,
) -> PyResult<Calibration> {
    let options = options(py, method, None, None, "none", 3.0, false, false, true)?;
    let units = Units::parse(py, units)?;
    let robot = poses_from_rt(
        py,
        robot_rotations,
        robot_translations,
        (&names[0], &names[1]),
        units,
    )?;
    let camera = poses_from_rt(
        py,
        camera_rotations,
        camera_translations,
        (&names[2], &names[3]),
        units,
    )?;
    if robot.len() != camera.len() {
        return Err(errors::input(
            py,
            format!(
                "{} has {} poses but {} has {}: give one of each per sample",
                names[0],
                robot.len(),
                names[2],
                camera.len()
            ),
        ));
    }
    let pairs: Vec<PosePair> = robot
        .into_iter()
        .zip(camera)
        .map(|(robot, camera_from_target)| PosePair {
            base_from_flange: if invert_flange {
                robot.inverse()
            } else {
                robot
            },
            camera_from_target,
            weight: 1.0,
            id: None,
            view_sigma: None,
        })
        .collect();
    solve_pairs(
        py,
        Setup::EyeInHand,
        pairs,
        options,
        Accuracy::default(),
        units,
    )
}

/// Solves `pairs` (already checked), raising `InputError` (with the REDO verdict as its
/// `verdict` attribute) when the solver refuses them.
pub(crate) fn solve_pairs(
    py: Python<'_>,
    setup: Setup,
    pairs: Vec<PosePair>,
    options: SolveOptions,
    accuracy: Accuracy,
    units: Units,
) -> PyResult<Calibration> {
    let result = py.detach(|| handeye_solve::solve(setup, &pairs, &options));
    match result {
        Ok(inner) => Ok(Calibration {
            inner,
            pairs,
            options: Some(options),
            accuracy,
            verdict: OnceLock::new(),
            reprojection: None,
            units,
        }),
        Err(error) => {
            let err = match &error {
                // The check's advice names metres: the translations it read were converted.
                SolveError::ImplausibleUnits { .. } if units != Units::METRES => errors::input(
                    py,
                    format!(
                        "{} (read with units=\"{}\", converted to metres: give every translation, robot and camera, in {})",
                        error_chain(&error),
                        units.name,
                        units.name
                    ),
                ),
                _ => errors::from_error(py, &error),
            };
            let refused = Verdict::refused(&error, pairs.len(), accuracy);
            err.value(py)
                .setattr("verdict", Py::new(py, VerdictPy { inner: refused })?)?;
            Err(err)
        }
    }
}

/// The answer of a solve: both transforms, their 1-sigma, residuals, notices and verdict.
#[pyclass(name = "Calibration", module = "handeye", frozen)]
pub(crate) struct Calibration {
    pub(crate) inner: handeye_solve::Calibration,
    /// The samples it was solved from (for ids, the held-out check and the result file).
    pub(crate) pairs: Vec<PosePair>,
    /// The options of the solve, for the verdict's held-out solves; `None` for an answer read
    /// from a file or made by a session solve (whose verdict is set).
    pub(crate) options: Option<SolveOptions>,
    pub(crate) accuracy: Accuracy,
    pub(crate) verdict: OnceLock<Option<Verdict>>,
    /// A session's reprojection-space summary (`reprojection.yaml`'s content), when it has one.
    pub(crate) reprojection: Option<serde_json::Value>,
    /// The unit of the translations it was given and answers in (files are always metres).
    pub(crate) units: Units,
}

impl Calibration {
    /// An answer whose verdict is already known (a session's solve, a result file).
    pub(crate) fn with_verdict(
        inner: handeye_solve::Calibration,
        pairs: Vec<PosePair>,
        verdict: Option<Verdict>,
        reprojection: Option<serde_json::Value>,
    ) -> Calibration {
        let accuracy = verdict.as_ref().map(|v| v.accuracy).unwrap_or_default();
        Calibration {
            inner,
            pairs,
            options: None,
            accuracy,
            verdict: OnceLock::from(verdict),
            reprojection,
            units: Units::METRES,
        }
    }

    fn verdict_inner(&self, py: Python<'_>) -> Option<&Verdict> {
        if let Some(verdict) = self.verdict.get() {
            return verdict.as_ref();
        }
        // Computed without the GIL and outside the OnceLock's initialisation: a second thread
        // asking meanwhile computes its own (the same) verdict instead of waiting for this one
        // while holding the GIL this one needs to return.
        let verdict = self.options.as_ref().map(|options| {
            py.detach(|| {
                verdict::assess_result(Ok(&self.inner), &self.pairs, options, self.accuracy)
            })
        });
        let _ = self.verdict.set(verdict);
        self.verdict.get().and_then(Option::as_ref)
    }

    fn names(&self) -> (&'static str, &'static str) {
        self.inner.setup.unknown_names()
    }

    fn mount(&self, py: Python<'_>, name: &str) -> PyResult<Py<PyArray2<f64>>> {
        let (camera, target) = self.names();
        let pose = if name == camera {
            &self.inner.camera_mount
        } else if name == target {
            &self.inner.target_mount
        } else {
            return Err(pyo3::exceptions::PyAttributeError::new_err(format!(
                "{name} is not an unknown of {}: this calibration solved {camera} and {target}",
                self.inner.setup
            )));
        };
        Ok(pose_to_py_in(py, pose, self.units).unbind())
    }
}

#[pymethods]
impl Calibration {
    /// `"eye_in_hand"` or `"eye_to_hand"`.
    #[getter]
    fn setup(&self) -> &'static str {
        self.inner.setup.name()
    }

    /// The unit of the translations of its transforms, `"m"` or `"mm"` (the `units` it was
    /// given; sigmas and residuals say theirs in their names).
    #[getter]
    fn units(&self) -> &'static str {
        self.units.name
    }

    /// The camera mount, 4x4 (translation in `units`): `T_flange_camera` (eye-in-hand) or
    /// `T_base_camera`.
    #[getter]
    fn camera_mount<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        pose_to_py_in(py, &self.inner.camera_mount, self.units)
    }

    /// The target mount, 4x4 (translation in `units`): `T_base_target` (eye-in-hand) or
    /// `T_flange_target`.
    #[getter]
    fn target_mount<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        pose_to_py_in(py, &self.inner.target_mount, self.units)
    }

    /// Both transforms by frame name, camera mount first: `{"T_flange_camera": 4x4, ...}`
    /// (translations in `units`).
    #[getter]
    fn transforms<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let dict = PyDict::new(py);
        for (name, pose) in self.inner.unknowns() {
            dict.set_item(name, pose_to_py_in(py, &pose, self.units))?;
        }
        Ok(dict)
    }

    /// `T_flange_camera` (eye-in-hand only), 4x4, metres.
    #[getter(T_flange_camera)]
    fn t_flange_camera(&self, py: Python<'_>) -> PyResult<Py<PyArray2<f64>>> {
        self.mount(py, "T_flange_camera")
    }

    /// `T_base_target` (eye-in-hand only), 4x4, metres.
    #[getter(T_base_target)]
    fn t_base_target(&self, py: Python<'_>) -> PyResult<Py<PyArray2<f64>>> {
        self.mount(py, "T_base_target")
    }

    /// `T_base_camera` (eye-to-hand only), 4x4, metres.
    #[getter(T_base_camera)]
    fn t_base_camera(&self, py: Python<'_>) -> PyResult<Py<PyArray2<f64>>> {
        self.mount(py, "T_base_camera")
    }

    /// `T_flange_target` (eye-to-hand only), 4x4, metres.
    #[getter(T_flange_target)]
    fn t_flange_target(&self, py: Python<'_>) -> PyResult<Py<PyArray2<f64>>> {
        self.mount(py, "T_flange_target")
    }

    /// 1-sigma of each transform by frame name (`rotation_deg`, `translation_mm`, per axis of
    /// the transform's first frame), or None (no covariance: a closed-form method).
    #[getter]
    fn sigma<'py>(&self, py: Python<'py>) -> PyResult<Option<Bound<'py, PyDict>>> {
        let Some(u) = &self.inner.uncertainty else {
            return Ok(None);
        };
        let (camera, target) = self.names();
        let dict = PyDict::new(py);
        dict.set_item(camera, to_py(py, &u.camera_mount)?)?;
        dict.set_item(target, to_py(py, &u.target_mount)?)?;
        Ok(Some(dict))
    }

    /// 12x12 covariance (camera mount [rotation rad, translation in `units`], target mount
    /// [same]), or None.
    #[getter]
    fn covariance<'py>(&self, py: Python<'py>) -> Option<Bound<'py, PyArray2<f64>>> {
        // Rows 3..6 and 9..12 are translations: scaled by the unit once per index.
        let scale = |i: usize| {
            if (3..6).contains(&(i % 6)) {
                self.units.of_metres(1.0)
            } else {
                1.0
            }
        };
        self.inner.uncertainty.as_ref().map(|u| {
            let c = &u.covariance;
            numpy::ndarray::Array2::from_shape_fn((12, 12), |(r, k)| {
                c[(r, k)] * scale(r) * scale(k)
            })
            .into_pyarray(py)
        })
    }

    /// Per-sample and summary residuals against the measured `T_camera_target`: `rotation_deg`,
    /// `translation_mm`, `normalised` (sigmas) per sample (NaN for a dropped sample), and
    /// `rotation_rms_deg`, `rotation_max_deg`, `translation_rms_mm`, `translation_max_mm`.
    #[getter]
    fn residuals<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let r = &self.inner.residuals;
        let dict = PyDict::new(py);
        dict.set_item("rotation_deg", r.rotation_deg.clone().into_pyarray(py))?;
        dict.set_item("translation_mm", r.translation_mm.clone().into_pyarray(py))?;
        dict.set_item("normalised", r.normalised.clone().into_pyarray(py))?;
        dict.set_item("rotation_rms_deg", r.rotation_rms_deg)?;
        dict.set_item("rotation_max_deg", r.rotation_max_deg)?;
        dict.set_item("translation_rms_mm", r.translation_rms_mm)?;
        dict.set_item("translation_max_mm", r.translation_max_mm)?;
        Ok(dict)
    }

    /// Indices of the samples flagged as outliers.
    #[getter]
    fn outliers(&self) -> Vec<usize> {
        self.inner.outliers.clone()
    }

    /// Indices of the samples left out of the final solve.
    #[getter]
    fn dropped(&self) -> Vec<usize> {
        self.inner.dropped.clone()
    }

    /// Sample ids (None where a sample has none).
    #[getter]
    fn ids(&self) -> Vec<Option<String>> {
        self.pairs.iter().map(|p| p.id.clone()).collect()
    }

    /// The board-pose noise the fit used (per-axis 1-sigma, estimated or given), or None.
    #[getter]
    fn noise<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        to_py(py, &self.inner.noise)
    }

    /// Things to know, each `{"severity": "info"|"warning"|"error", "kind": ..., "message": ...}`.
    #[getter]
    fn notices<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        to_py(py, &self.inner.notices)
    }

    /// How the solver got there: `method`, `iterations`, `converged`, `restarts`.
    #[getter]
    fn solver<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let s = &self.inner.solver;
        let dict = PyDict::new(py);
        dict.set_item("method", s.method.name())?;
        dict.set_item("iterations", s.iterations)?;
        dict.set_item("converged", s.converged)?;
        dict.set_item("restarts", s.restarts)?;
        Ok(dict)
    }

    /// A session's reprojection-space summary (RMS px of both answers, per frame), or None.
    #[getter]
    fn reprojection<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        to_py(py, &self.reprojection)
    }

    /// GOOD / CHECK / REDO with its reason (computed on first read: one held-out solve per
    /// sample), or None for a result file written without one.
    #[getter]
    pub(crate) fn verdict(&self, py: Python<'_>) -> PyResult<Option<Py<VerdictPy>>> {
        self.verdict_inner(py)
            .map(|v| Py::new(py, VerdictPy { inner: v.clone() }))
            .transpose()
    }

    /// The `T_camera_target` this calibration predicts for each `T_base_flange` ((N, 4, 4),
    /// translations in `units`, as given and answered).
    fn predict<'py>(
        &self,
        py: Python<'py>,
        base_from_flange: &Bound<'py, PyAny>,
    ) -> PyResult<Bound<'py, PyArray3<f64>>> {
        let flange = poses_from_any(py, base_from_flange, "T_base_flange", self.units)?;
        let predicted: Vec<Pose> = flange
            .iter()
            .map(|p| self.inner.predict_camera_from_target(p))
            .collect();
        Ok(poses_to_py_in(py, &predicted, self.units))
    }

    /// The terminal summary `handeye solve` prints.
    fn summary(&self) -> String {
        self.inner.summary()
    }

    /// Writes the result file `handeye solve -o` writes (YAML, atomically, in metres whatever
    /// the `units`), verdict first.
    fn save(&self, py: Python<'_>, path: PathBuf) -> PyResult<()> {
        let mut file = ResultFile::from_calibration(&self.inner, &self.pairs);
        if let Some(verdict) = self.verdict_inner(py) {
            file = file.with_verdict(verdict.clone());
        }
        file.save(&path).map_err(|e| errors::from_error(py, &e))
    }

    fn __repr__(&self) -> String {
        let (camera, target) = self.names();
        format!(
            "<handeye.Calibration {} ({} and {}), {} samples, method {}>",
            self.inner.setup,
            camera,
            target,
            self.pairs.len(),
            self.inner.solver.method.name()
        )
    }
}

/// GOOD / CHECK / REDO, the one reason that decided it, and the next action.
#[pyclass(name = "Verdict", module = "handeye", frozen)]
pub(crate) struct VerdictPy {
    pub(crate) inner: Verdict,
}

#[pymethods]
impl VerdictPy {
    /// `"GOOD"`, `"CHECK"` or `"REDO"`.
    #[getter]
    fn level(&self) -> &'static str {
        self.inner.level.word()
    }

    /// What decided it (`held_out_error`, `uncertainty`, `refused`, ...).
    #[getter]
    fn basis<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        to_py(py, &self.inner.basis)
    }

    /// The measured fact that decided it, with its numbers and threshold.
    #[getter]
    fn reason(&self) -> &str {
        &self.inner.reason
    }

    /// What to do next.
    #[getter]
    fn next_action(&self) -> &str {
        &self.inner.next_action
    }

    /// The accuracy judged against: `{"translation_mm": .., "rotation_deg": ..}`.
    #[getter]
    fn accuracy<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        to_py(py, &self.inner.accuracy)
    }

    /// The measured figures (held-out errors in mm and degrees, 1-sigma, residual RMS, ...).
    #[getter]
    fn figures<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        to_py(py, &self.inner.figures)
    }

    /// Further findings, worst first, each `{"level", "basis", "reason", "next_action"}`.
    #[getter]
    fn also<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyList>> {
        let list = PyList::empty(py);
        for finding in &self.inner.also {
            let item = to_py(py, finding)?;
            item.set_item("level", finding.level.word())?;
            list.append(item)?;
        }
        Ok(list)
    }

    /// The lines the CLI prints (`verdict: GOOD — reason`, `next: ...`).
    fn __str__(&self) -> String {
        self.inner.terminal_lines()
    }

    fn __repr__(&self) -> String {
        format!(
            "<handeye.Verdict {}: {}>",
            self.inner.level, self.inner.reason
        )
    }
}
