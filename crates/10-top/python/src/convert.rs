//! Between numpy and the library's types: stacks of 4x4 homogeneous matrices in and out, and the
//! library's serde types (notices, the verdict, noise figures) as plain Python dicts and lists.
//!
//! A 4x4 input is read through the same pose parser as a dataset file's `matrix:` form
//! ([`PoseYaml::to_pose`]): the same checks (finite values, an orthonormal rotation with
//! determinant +1 within 1e-6, a translation no robot cell exceeds) and the same messages, with
//! the array's name and index as the path (`T_base_flange[3].matrix: not a rotation matrix ...`).

use handeye_core::geometry::yaml::{PoseProblem, MATRIX_ORTHONORMALITY_TOLERANCE};
use handeye_core::geometry::{to_matrix4_rows, Pose, PoseYaml};
use nalgebra::Matrix3;
use numpy::ndarray::{Array2, Array3, ArrayView2, Axis, Ix2};
use numpy::{
    IntoPyArray, PyArray2, PyArray3, PyArrayDyn, PyArrayMethods, PyReadonlyArrayDyn,
    PyUntypedArrayMethods,
};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList, PyTuple};

use crate::errors;

/// Largest accepted deviation of a homogeneous matrix's last row from `[0, 0, 0, 1]`.
const LAST_ROW_TOLERANCE: f64 = 1e-9;

/// A pose from one 4x4 homogeneous matrix `m` whose translation is in `units`, named `path` in
/// errors.
pub(crate) fn pose_from_matrix(
    m: ArrayView2<'_, f64>,
    path: &str,
    units: Units,
) -> Result<Pose, String> {
    let last = [m[(3, 0)], m[(3, 1)], m[(3, 2)], m[(3, 3)]];
    if last
        .iter()
        .zip([0.0, 0.0, 0.0, 1.0])
        .any(|(v, want)| (v - want).abs().is_nan() || (v - want).abs() > LAST_ROW_TOLERANCE)
    {
        return Err(format!(
            "{path}: the last row of a homogeneous transform must be [0, 0, 0, 1], found {last:?}"
        ));
    }
    let yaml = PoseYaml {
        translation: Some(vec![
            units.to_metres(m[(0, 3)]),
            units.to_metres(m[(1, 3)]),
            units.to_metres(m[(2, 3)]),
        ]),
        matrix: Some(
            (0..3)
                .map(|r| (0..3).map(|c| m[(r, c)]).collect())
                .collect(),
        ),
        ..PoseYaml::default()
    };
    yaml.to_pose(path).map_err(|e| e.to_string())
}

/// The unit of the translations a call takes and answers in: metres (the default, the unit of
/// every handeye file) or millimetres (KUKA and ABB controllers, object points in mm).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Units {
    /// As the caller spells it: `"m"` or `"mm"`.
    pub(crate) name: &'static str,
    /// Units per metre (1 or 1000: exact, so `x * 1000 / 1000` is `x` wherever float64 can).
    pub(crate) per_metre: f64,
}

impl Units {
    /// Metres.
    pub(crate) const METRES: Units = Units {
        name: "m",
        per_metre: 1.0,
    };

    /// `"m"` or `"mm"`, else `InputError` naming the argument.
    pub(crate) fn parse(py: Python<'_>, text: &str) -> PyResult<Units> {
        match text {
            "m" => Ok(Units::METRES),
            "mm" => Ok(Units {
                name: "mm",
                per_metre: 1000.0,
            }),
            other => Err(errors::input(
                py,
                format!("units `{other}`: expected `m` (metres, the default) or `mm` (millimetres); every translation in and out is in that unit"),
            )),
        }
    }

    /// A translation in these units from one in metres.
    pub(crate) fn of_metres(self, metres: f64) -> f64 {
        metres * self.per_metre
    }

    /// A translation in metres from one in these units.
    pub(crate) fn to_metres(self, value: f64) -> f64 {
        value / self.per_metre
    }
}

/// What `calibrate` takes, and where to go with rotations and translations given apart.
const CALIBRATE_SHAPES: &str = "calibrate takes two (N, 4, 4) stacks of homogeneous transforms (T_base_flange, T_camera_target); for rotations and translations given apart, as cv2.calibrateHandEye takes them, call handeye.calibrateHandEye(R_gripper2base, t_gripper2base, R_target2cam, t_target2cam) with a list of N rotations (3x3 or rotation vectors) and a list of N translations (3,) or (3, 1) each";

/// `value` as a float64 numpy array: itself when it is one (no copy), else `numpy.asarray(value,
/// dtype=float64)` (lists, tuples, float32); `None` when numpy cannot make one array of it.
fn f64_array<'py>(
    py: Python<'py>,
    value: &Bound<'py, PyAny>,
) -> PyResult<Result<PyReadonlyArrayDyn<'py, f64>, String>> {
    let array = match value.cast::<PyArrayDyn<f64>>() {
        Ok(array) => array.clone(),
        Err(_) => {
            let kwargs = PyDict::new(py);
            kwargs.set_item("dtype", "float64")?;
            match py
                .import("numpy")?
                .call_method("asarray", (value,), Some(&kwargs))
            {
                Ok(converted) => match converted.cast_into::<PyArrayDyn<f64>>() {
                    Ok(array) => array,
                    Err(e) => return Ok(Err(e.to_string())),
                },
                Err(e) if e.is_instance_of::<pyo3::exceptions::PyKeyboardInterrupt>(py) => {
                    return Err(e)
                }
                Err(e) => return Ok(Err(e.value(py).to_string())),
            }
        }
    };
    Ok(array.try_readonly().map_err(|e| e.to_string()))
}

/// When `value` is a list of `(R, t)` pairs (`list(zip(R, t))`), the shapes of its first pair.
fn pair_shapes(value: &Bound<'_, PyAny>) -> Option<String> {
    if value.cast::<PyArrayDyn<f64>>().is_ok() {
        return None;
    }
    let first = value.get_item(0).ok()?;
    if !(first.cast::<PyTuple>().is_ok() || first.cast::<PyList>().is_ok())
        || first.len().ok()? != 2
    {
        return None;
    }
    let shape = |item: Bound<'_, PyAny>| -> String {
        item.getattr("shape")
            .and_then(|s| s.extract::<Vec<usize>>())
            .map(|s| shape_text(&s))
            .unwrap_or_else(|_| "?".into())
    };
    Some(format!(
        "{} and {}",
        shape(first.get_item(0).ok()?),
        shape(first.get_item(1).ok()?)
    ))
}

/// The poses of an `(N, 4, 4)` array (a single `(4, 4)` matrix is refused: it is one pose, and
/// a calibration needs many) or anything numpy makes one of, translations in `units`, named
/// `name` in errors. A wrong shape is named with the call that takes rotations and
/// translations apart.
pub(crate) fn poses_from_any(
    py: Python<'_>,
    value: &Bound<'_, PyAny>,
    name: &str,
    units: Units,
) -> PyResult<Vec<Pose>> {
    let expected = format!(
        "{name} must be an (N, 4, 4) array of homogeneous transforms (translations in {})",
        unit_word(units)
    );
    if let Some(shapes) = pair_shapes(value) {
        return Err(errors::input(
            py,
            format!("{expected}, found a list of pairs ({name}[0] holds two arrays, {shapes}: a rotation and a translation?): {CALIBRATE_SHAPES} (from pairs: [R for R, t in pairs], [t for R, t in pairs])"),
        ));
    }
    let array = match f64_array(py, value)? {
        Ok(array) => array,
        Err(why) => {
            return Err(errors::input(
                py,
                format!("{expected}: {why}; {CALIBRATE_SHAPES}"),
            ))
        }
    };
    let shape = array.shape();
    if shape.len() != 3 || shape[1] != 4 || shape[2] != 4 {
        return Err(errors::input(
            py,
            format!(
                "{expected}, found shape {}; {CALIBRATE_SHAPES}",
                shape_text(shape)
            ),
        ));
    }
    let view = array.as_array();
    (0..shape[0])
        .map(|i| {
            let m = view.index_axis(Axis(0), i);
            let m = m
                .into_dimensionality::<Ix2>()
                .map_err(|e| errors::input(py, e.to_string()))?;
            pose_from_matrix(m, &format!("{name}[{i}]"), units)
                .map_err(|e| errors::input(py, with_units_hint(e, units)))
        })
        .collect()
}

/// `metres` or `millimetres`.
fn unit_word(units: Units) -> &'static str {
    if units == Units::METRES {
        "metres"
    } else {
        "millimetres"
    }
}

/// A translation refused as millimetres given as metres also names `units="mm"`.
fn with_units_hint(message: String, units: Units) -> String {
    if units == Units::METRES && message.contains("millimetres given as metres") {
        format!("{message}; pass units=\"mm\" when every translation (robot and camera) is in millimetres")
    } else {
        message
    }
}

/// Largest `‖RᵀR − I‖_F` (and `|det R − 1|`) of a rotation matrix the OpenCV-shaped calls take
/// and project onto the nearest rotation (float32 round-off, printed digits), as OpenCV's
/// Rodrigues does; farther off is refused rather than silently "fixed".
pub(crate) const PROJECT_TOLERANCE: f64 = 1e-3;

/// The numbers of one array (row-major) and its shape.
type Numbers = (Vec<f64>, Vec<usize>);

/// One argument of an OpenCV-shaped call: a list (or tuple) of N arrays, or a stacked array
/// with N first.
struct Items<'py> {
    stacked: Option<PyReadonlyArrayDyn<'py, f64>>,
    list: Vec<Bound<'py, PyAny>>,
}

impl<'py> Items<'py> {
    fn new(py: Python<'py>, value: &Bound<'py, PyAny>, name: &str) -> PyResult<Items<'py>> {
        // One array for the whole argument when numpy makes one (a stacked array, or a list of
        // arrays of one shape: one call into numpy instead of one per pose); else item by item
        // (a list of mixed shapes, which OpenCV takes too).
        if let Ok(array) = f64_array(py, value)? {
            if array.shape().len() >= 2 {
                return Ok(Items {
                    stacked: Some(array),
                    list: Vec::new(),
                });
            }
        }
        let iter = value.try_iter().map_err(|_| {
            errors::input(
                py,
                format!(
                    "{name}: expected a list of arrays (one per pose), found {}",
                    type_name(value)
                ),
            )
        })?;
        Ok(Items {
            stacked: None,
            list: iter.collect::<PyResult<Vec<_>>>()?,
        })
    }

    fn len(&self) -> usize {
        match &self.stacked {
            Some(array) => array.shape()[0],
            None => self.list.len(),
        }
    }

    /// Item `i`'s numbers (row-major) and shape, or why it is not an array of numbers.
    fn get(&self, py: Python<'py>, i: usize) -> PyResult<Result<Numbers, String>> {
        Ok(match &self.stacked {
            Some(array) => {
                let view = array.as_array();
                let item = view.index_axis(Axis(0), i);
                Ok((item.iter().copied().collect(), item.shape().to_vec()))
            }
            None => f64_array(py, &self.list[i])?.map(|a| {
                let view = a.as_array();
                (view.iter().copied().collect(), view.shape().to_vec())
            }),
        })
    }
}

/// The Python type name of `value`, for messages.
fn type_name(value: &Bound<'_, PyAny>) -> String {
    value
        .get_type()
        .name()
        .map(|n| n.to_string())
        .unwrap_or_else(|_| "?".into())
}

/// The nearest rotation (SVD) of a matrix within [`PROJECT_TOLERANCE`] of one, else `None`; a
/// matrix the pose parser takes as it is (within [`MATRIX_ORTHONORMALITY_TOLERANCE`]) is
/// returned as it is, so the same numbers give the same answer as `calibrate`'s 4x4 matrices.
fn nearest_rotation(m: &Matrix3<f64>) -> Option<Matrix3<f64>> {
    let off = (m.transpose() * m - Matrix3::identity()).norm();
    let det_off = (m.determinant() - 1.0).abs();
    if off > PROJECT_TOLERANCE || det_off > PROJECT_TOLERANCE {
        return None;
    }
    if off <= MATRIX_ORTHONORMALITY_TOLERANCE && det_off <= MATRIX_ORTHONORMALITY_TOLERANCE {
        return Some(*m);
    }
    let svd = m.svd(true, true);
    let (u, v_t) = (svd.u?, svd.v_t?);
    let d = (u * v_t).determinant().signum();
    Some(u * Matrix3::from_diagonal(&nalgebra::Vector3::new(1.0, 1.0, d)) * v_t)
}

/// One pose from a rotation (3x3 matrix or rotation vector (3,), (3, 1), (1, 3), radians) and a
/// translation ((3,), (3, 1), (1, 3), in `units`), read through the same pose parser as a YAML
/// file's (the same checks: finite, a rotation vector longer than 2π refused as degrees, a
/// translation no cell has), named `r_name` / `t_name` in errors.
fn pose_from_rt(
    rotation: Numbers,
    translation: Numbers,
    r_name: &str,
    t_name: &str,
    units: Units,
) -> Result<Pose, String> {
    let (t, t_shape) = translation;
    if t.len() != 3 || t_shape.len() > 2 {
        return Err(format!(
            "{t_name}: expected a translation (3,), (3, 1) or (1, 3), found shape {}",
            shape_text(&t_shape)
        ));
    }
    let (r, r_shape) = rotation;
    let mut yaml = PoseYaml {
        translation: Some(t.iter().map(|&v| units.to_metres(v)).collect()),
        ..PoseYaml::default()
    };
    if r_shape == [3, 3] {
        if let Some(bad) = r.iter().find(|v| !v.is_finite()) {
            return Err(format!("{r_name}: value is not finite ({bad})"));
        }
        let m = Matrix3::from_row_slice(&r);
        let Some(projected) = nearest_rotation(&m) else {
            return Err(format!(
                "{r_name}: not a rotation matrix: ‖RᵀR − I‖ = {:.3e}, det = {:.6} (expected orthonormal with det +1 within {PROJECT_TOLERANCE:e})",
                (m.transpose() * m - Matrix3::identity()).norm(),
                m.determinant()
            ));
        };
        yaml.matrix = Some(
            (0..3)
                .map(|row| (0..3).map(|c| projected[(row, c)]).collect())
                .collect(),
        );
    } else if r.len() == 3 && r_shape.len() <= 2 {
        yaml.rotation_vector = Some(r);
    } else {
        return Err(format!(
            "{r_name}: expected a 3x3 rotation matrix or a rotation vector (3,), (3, 1) or (1, 3) in radians, found shape {}",
            shape_text(&r_shape)
        ));
    }
    yaml.to_pose("").map_err(|e| {
        let name = if e.path.starts_with("translation") {
            t_name
        } else {
            r_name
        };
        let mut message = format!("{name}: {}", e.problem);
        if matches!(e.problem, PoseProblem::DegreesInRotationVector { .. }) {
            message.push_str(" (in Python: np.radians(rvec); cv2.Rodrigues takes radians too)");
        }
        with_units_hint(message, units)
    })
}

/// The poses of an OpenCV-shaped call's rotation and translation lists (`names[0]`,
/// `names[1]`), translations in `units`.
pub(crate) fn poses_from_rt(
    py: Python<'_>,
    rotations: &Bound<'_, PyAny>,
    translations: &Bound<'_, PyAny>,
    names: (&str, &str),
    units: Units,
) -> PyResult<Vec<Pose>> {
    let rs = Items::new(py, rotations, names.0)?;
    let ts = Items::new(py, translations, names.1)?;
    if rs.len() != ts.len() {
        return Err(errors::input(
            py,
            format!(
                "{} has {} entries but {} has {}: give one rotation and one translation per pose",
                names.0,
                rs.len(),
                names.1,
                ts.len()
            ),
        ));
    }
    (0..rs.len())
        .map(|i| {
            let r_name = format!("{}[{i}]", names.0);
            let t_name = format!("{}[{i}]", names.1);
            let r = rs.get(py, i)?.map_err(|why| {
                errors::input(py, format!("{r_name}: not an array of numbers: {why}"))
            })?;
            let t = ts.get(py, i)?.map_err(|why| {
                errors::input(py, format!("{t_name}: not an array of numbers: {why}"))
            })?;
            pose_from_rt(r, t, &r_name, &t_name, units).map_err(|e| errors::input(py, e))
        })
        .collect()
}

/// The 4x4 homogeneous matrix of a pose.
pub(crate) fn matrix(pose: &Pose) -> Array2<f64> {
    matrix_in(pose, Units::METRES)
}

/// The 4x4 homogeneous matrix of a pose, translation in `units`.
pub(crate) fn matrix_in(pose: &Pose, units: Units) -> Array2<f64> {
    let rows = to_matrix4_rows(pose);
    Array2::from_shape_fn((4, 4), |(r, c)| {
        if c == 3 && r < 3 {
            units.of_metres(rows[r][c])
        } else {
            rows[r][c]
        }
    })
}

/// A shape as Python prints it: `(8, 3, 4)`, `(4,)`.
pub(crate) fn shape_text(shape: &[usize]) -> String {
    match shape {
        [one] => format!("({one},)"),
        _ => format!(
            "({})",
            shape
                .iter()
                .map(|d| d.to_string())
                .collect::<Vec<_>>()
                .join(", ")
        ),
    }
}

/// A pose as a `(4, 4)` numpy array.
pub(crate) fn pose_to_py<'py>(py: Python<'py>, pose: &Pose) -> Bound<'py, PyArray2<f64>> {
    matrix(pose).into_pyarray(py)
}

/// A pose as a `(4, 4)` numpy array, translation in `units`.
pub(crate) fn pose_to_py_in<'py>(
    py: Python<'py>,
    pose: &Pose,
    units: Units,
) -> Bound<'py, PyArray2<f64>> {
    matrix_in(pose, units).into_pyarray(py)
}

/// Poses as an `(N, 4, 4)` numpy array.
pub(crate) fn poses_to_py<'py>(py: Python<'py>, poses: &[Pose]) -> Bound<'py, PyArray3<f64>> {
    poses_to_py_in(py, poses, Units::METRES)
}

/// Poses as an `(N, 4, 4)` numpy array, translations in `units`.
pub(crate) fn poses_to_py_in<'py>(
    py: Python<'py>,
    poses: &[Pose],
    units: Units,
) -> Bound<'py, PyArray3<f64>> {
    let mut out = Array3::zeros((poses.len(), 4, 4));
    for (i, pose) in poses.iter().enumerate() {
        out.index_axis_mut(Axis(0), i)
            .assign(&matrix_in(pose, units));
    }
    out.into_pyarray(py)
}

/// Any serde value of the library as plain Python objects (dicts, lists, str, int, float,
/// bool, None). NaN and infinities become None (as in JSON).
pub(crate) fn to_py<'py, T: serde::Serialize>(
    py: Python<'py>,
    value: &T,
) -> PyResult<Bound<'py, PyAny>> {
    let value = serde_json::to_value(value)
        .map_err(|e| errors::raise(py, "HandeyeError", format!("internal conversion: {e}")))?;
    json_to_py(py, &value)
}

fn json_to_py<'py>(py: Python<'py>, value: &serde_json::Value) -> PyResult<Bound<'py, PyAny>> {
    use serde_json::Value;
    Ok(match value {
        Value::Null => py.None().into_bound(py),
        Value::Bool(b) => b.into_pyobject(py)?.to_owned().into_any(),
        Value::Number(n) => match (n.as_i64(), n.as_u64(), n.as_f64()) {
            (Some(i), _, _) => i.into_pyobject(py)?.into_any(),
            (None, Some(u), _) => u.into_pyobject(py)?.into_any(),
            (None, None, f) => f.unwrap_or(f64::NAN).into_pyobject(py)?.into_any(),
        },
        Value::String(s) => s.into_pyobject(py)?.into_any(),
        Value::Array(items) => {
            let list = PyList::empty(py);
            for item in items {
                list.append(json_to_py(py, item)?)?;
            }
            list.into_any()
        }
        Value::Object(map) => {
            let dict = PyDict::new(py);
            for (key, item) in map {
                dict.set_item(key, json_to_py(py, item)?)?;
            }
            dict.into_any()
        }
    })
}
