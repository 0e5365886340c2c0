//! MoveIt Calibration's pose-sample JSON: a list of samples, each `[T_base_flange,
//! T_camera_target]` as 4x4 row-major homogeneous matrices in metres (`effector_wrt_world`,
//! `object_wrt_sensor`). The file must be that one array and nothing more.
//!
//! Depends on `geometry`, `setup` and the parent's [`ImportError`] and tolerances.

use std::path::Path;

use nalgebra::{Matrix3, Translation3, Vector3};

use super::{checked_translation, read_text, ImportError, MATRIX_TOLERANCE};
use handeye_core::geometry::{rotation_from_matrix, Pose};
use handeye_core::setup::PosePair;

/// A 4x4 homogeneous matrix (row-major) as a pose; `location` names it in errors.
pub fn pose_from_matrix4(
    m: &[[f64; 4]; 4],
    path: &Path,
    location: &str,
) -> Result<Pose, ImportError> {
    let bad = |problem: String| ImportError::Value {
        path: path.to_path_buf(),
        location: location.to_string(),
        problem,
    };
    if m.iter().flatten().any(|v| !v.is_finite()) {
        return Err(bad("holds a value that is not a finite number".into()));
    }
    let bottom = m[3];
    if (bottom[0].abs() + bottom[1].abs() + bottom[2].abs() + (bottom[3] - 1.0).abs()) > 1e-9 {
        return Err(bad(format!(
            "last row {bottom:?} is not [0, 0, 0, 1]: not a homogeneous transform"
        )));
    }
    let r = Matrix3::from_fn(|i, j| m[i][j]);
    let rotation = rotation_from_matrix(&r, MATRIX_TOLERANCE).ok_or_else(|| {
        bad(format!(
            "the 3x3 block is not a rotation (orthonormality error {:.2e}, det {:.6})",
            (r.transpose() * r - Matrix3::identity()).norm(),
            r.determinant()
        ))
    })?;
    let translation = checked_translation(Vector3::new(m[0][3], m[1][3], m[2][3]), path, location)?;
    Ok(Pose::from_parts(Translation3::from(translation), rotation))
}

/// Reads MoveIt Calibration's pose-sample JSON: `[[T_base_flange, T_camera_target], ...]`, 4x4
/// row-major matrices in metres. Sample ids are `moveit-<i>` (0-based).
pub fn import_moveit_json(path: &Path) -> Result<Vec<PosePair>, ImportError> {
    let text = read_text(path)?;
    let mut deserializer = serde_json::Deserializer::from_str(&text);
    let samples: Vec<[[[f64; 4]; 4]; 2]> = serde_path_to_error::deserialize(&mut deserializer)
        .map_err(|e| ImportError::Format {
            path: path.to_path_buf(),
            expected: "MoveIt Calibration pose-sample JSON ([[T_base_flange 4x4, T_camera_target 4x4], ...])",
            problem: format!("at {}: {}", e.path(), e.inner()),
        })?;
    // The whole input must be that one array: trailing text means a truncated copy, two files
    // pasted together or a different format, never something to ignore.
    deserializer.end().map_err(|e| ImportError::Format {
        path: path.to_path_buf(),
        expected: "MoveIt Calibration pose-sample JSON (one array and nothing after it)",
        problem: format!("text after the array: {e}"),
    })?;
    if samples.is_empty() {
        return Err(ImportError::Format {
            path: path.to_path_buf(),
            expected: "MoveIt Calibration pose-sample JSON",
            problem: "no samples".into(),
        });
    }
    samples
        .iter()
        .enumerate()
        .map(|(i, [flange, target])| {
            let mut pair = PosePair::new(
                pose_from_matrix4(
                    flange,
                    path,
                    &format!("sample {i} ([{i}][0], T_base_flange)"),
                )?,
                pose_from_matrix4(
                    target,
                    path,
                    &format!("sample {i} ([{i}][1], T_camera_target)"),
                )?,
            );
            pair.id = Some(format!("moveit-{i}"));
            Ok(pair)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn matrix_that_is_not_a_rotation_is_refused() {
        let m = [
            [1.0, 0.0, 0.0, 0.1],
            [0.0, 2.0, 0.0, 0.0],
            [0.0, 0.0, 1.0, 0.0],
            [0.0, 0.0, 0.0, 1.0],
        ];
        let e = pose_from_matrix4(&m, Path::new("x.json"), "sample 4")
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("x.json: sample 4") && e.contains("not a rotation"),
            "{e}"
        );
    }
}
