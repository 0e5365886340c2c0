//! Between numpy and the library's types: stacks of 4x4 homogeneous matrices in and out, and the
//! library's serde types (notices, the verdict, noise figures) as plain Python dicts and lists.
//!
//! A 4x4 input is read through the same pose parser as a dataset file's `matrix:` form
//! ([`PoseYaml::to_pose`]): the same checks (finite values, an orthonormal rotation with
//! determinant +1 within 1e-6, a translation no robot cell exceeds) and the same messages, with
//! the array's name and index as the path (`T_base_flange[3].matrix: not a rotation matrix ...`).

use handeye_core::geometry::{to_matrix4_rows, Pose, PoseYaml};
use numpy::ndarray::{Array2, Array3, ArrayView2};
use numpy::{IntoPyArray, PyArray2, PyArray3, PyReadonlyArrayDyn, PyUntypedArrayMethods};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};

use crate::errors;

/// Largest accepted deviation of a homogeneous matrix's last row from `[0, 0, 0, 1]`.
const LAST_ROW_TOLERANCE: f64 = 1e-9;

/// A pose from one 4x4 homogeneous matrix `m` (metres), named `path` in errors.
pub(crate) fn pose_from_matrix(m: ArrayView2<'_, f64>, path: &str) -> Result<Pose, String> {
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
        translation: Some(vec![m[(0, 3)], m[(1, 3)], m[(2, 3)]]),
        matrix: Some(
            (0..3)
                .map(|r| (0..3).map(|c| m[(r, c)]).collect())
                .collect(),
        ),
        ..PoseYaml::default()
    };
    yaml.to_pose(path).map_err(|e| e.to_string())
}

/// The poses of an `(N, 4, 4)` array (a single `(4, 4)` matrix is refused: it is one pose, and
/// a calibration needs many), named `name` in errors.
pub(crate) fn poses_from_array(
    py: Python<'_>,
    array: &PyReadonlyArrayDyn<'_, f64>,
    name: &str,
) -> PyResult<Vec<Pose>> {
    let shape = array.shape();
    if shape.len() != 3 || shape[1] != 4 || shape[2] != 4 {
        return Err(errors::input(
            py,
            format!(
                "{name} must be an (N, 4, 4) array of homogeneous transforms (metres), found shape {}",
                shape_text(shape)
            ),
        ));
    }
    let view = array.as_array();
    (0..shape[0])
        .map(|i| {
            let m = view.index_axis(numpy::ndarray::Axis(0), i);
            let m = m
                .into_dimensionality::<numpy::ndarray::Ix2>()
                .map_err(|e| errors::input(py, e.to_string()))?;
            pose_from_matrix(m, &format!("{name}[{i}]")).map_err(|e| errors::input(py, e))
        })
        .collect()
}

/// The 4x4 homogeneous matrix of a pose.
pub(crate) fn matrix(pose: &Pose) -> Array2<f64> {
    let rows = to_matrix4_rows(pose);
    Array2::from_shape_fn((4, 4), |(r, c)| rows[r][c])
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

/// Poses as an `(N, 4, 4)` numpy array.
pub(crate) fn poses_to_py<'py>(py: Python<'py>, poses: &[Pose]) -> Bound<'py, PyArray3<f64>> {
    let mut out = Array3::zeros((poses.len(), 4, 4));
    for (i, pose) in poses.iter().enumerate() {
        out.index_axis_mut(numpy::ndarray::Axis(0), i)
            .assign(&matrix(pose));
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
