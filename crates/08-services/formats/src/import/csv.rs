//! Pose CSV (ours, defined here): one pose is `tx,ty,tz,qx,qy,qz,qw` (quaternion, scalar last)
//! or UR's `x,y,z,rx,ry,rz` (rotation vector, rad); translations in metres (or mm when asked).
//! Either one file with two poses per row, `T_base_flange` then `T_camera_target` (14 or 12
//! columns), or two files of one pose per row paired by row order (robot file: `T_base_flange`,
//! camera file: `T_camera_target`). Blank lines and lines starting with `#` are skipped; a first
//! row with no numeric field is a header. Any other row must have exactly the expected number of
//! finite numbers, or the import fails naming the file and line.
//!
//! Depends on `geometry`, `setup` and the parent's [`ImportError`] and tolerances.

use std::path::Path;

use nalgebra::{Quaternion, Translation3, UnitQuaternion, Vector3};

use super::{checked_translation, read_text, ImportError, QUATERNION_TOLERANCE};
use handeye_core::geometry::{pose_from_rotvec, Pose};
use handeye_core::setup::PosePair;

/// How one pose is written in a CSV row.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CsvPoseForm {
    /// `tx,ty,tz,qx,qy,qz,qw` (quaternion scalar last).
    Quaternion,
    /// UR's `x,y,z,rx,ry,rz` (rotation vector, rad).
    RotationVector,
}

impl CsvPoseForm {
    /// Columns per pose.
    pub fn columns(self) -> usize {
        match self {
            CsvPoseForm::Quaternion => 7,
            CsvPoseForm::RotationVector => 6,
        }
    }

    fn header(self) -> &'static str {
        match self {
            CsvPoseForm::Quaternion => "tx,ty,tz,qx,qy,qz,qw",
            CsvPoseForm::RotationVector => "x,y,z,rx,ry,rz",
        }
    }
}

/// How a CSV file is read.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CsvOptions {
    /// The pose form.
    pub form: CsvPoseForm,
    /// Translations are in millimetres (UR's pendant shows mm) instead of metres.
    pub millimetres: bool,
}

/// The data rows of a CSV file: (1-based line number, numbers), with comments, blank lines and a
/// header skipped; every row checked to hold `columns` finite numbers.
fn csv_rows(
    path: &Path,
    columns: usize,
    expect: &str,
) -> Result<Vec<(usize, Vec<f64>)>, ImportError> {
    let text = read_text(path)?;
    let mut rows = Vec::new();
    let mut first_row = true;
    for (i, raw) in text.lines().enumerate() {
        let line = raw.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let fields: Vec<&str> = line.split(',').map(str::trim).collect();
        let is_first = std::mem::replace(&mut first_row, false);
        if is_first && fields.iter().all(|f| f.parse::<f64>().is_err()) {
            continue;
        }
        let bad = |problem: String| ImportError::Line {
            path: path.to_path_buf(),
            line: i + 1,
            problem,
        };
        if fields.len() != columns {
            return Err(bad(format!(
                "{} fields, expected {columns} ({expect})",
                fields.len()
            )));
        }
        let numbers = fields
            .iter()
            .enumerate()
            .map(|(c, f)| {
                f.parse::<f64>()
                    .ok()
                    .filter(|v| v.is_finite())
                    .ok_or_else(|| {
                        bad(format!(
                            "column {} is `{f}`, not a finite number (expected {expect})",
                            c + 1
                        ))
                    })
            })
            .collect::<Result<Vec<f64>, _>>()?;
        rows.push((i + 1, numbers));
    }
    if rows.is_empty() {
        return Err(ImportError::Format {
            path: path.to_path_buf(),
            expected: "pose CSV",
            problem: format!("no data rows (expected {expect})"),
        });
    }
    Ok(rows)
}

fn csv_pose(
    values: &[f64],
    options: &CsvOptions,
    path: &Path,
    line: usize,
    which: &str,
) -> Result<Pose, ImportError> {
    let scale = if options.millimetres { 1e-3 } else { 1.0 };
    let t = checked_translation(
        Vector3::new(values[0], values[1], values[2]) * scale,
        path,
        &format!("line {line}, {which}"),
    )?;
    match options.form {
        CsvPoseForm::RotationVector => Ok(pose_from_rotvec(
            t,
            Vector3::new(values[3], values[4], values[5]),
        )),
        CsvPoseForm::Quaternion => {
            let q = Quaternion::new(values[6], values[3], values[4], values[5]);
            let norm = q.norm();
            if (norm - 1.0).abs() > QUATERNION_TOLERANCE {
                return Err(ImportError::Line {
                    path: path.to_path_buf(),
                    line,
                    problem: format!(
                        "{which}: quaternion norm {norm:.6} is not 1 (±{QUATERNION_TOLERANCE}); the order is qx,qy,qz,qw"
                    ),
                });
            }
            Ok(Pose::from_parts(
                Translation3::from(t),
                UnitQuaternion::from_quaternion(q),
            ))
        }
    }
}

/// Reads a CSV with both poses per row: `T_base_flange` columns, then `T_camera_target` columns.
/// Sample ids are `line-<n>`.
pub fn import_csv_pairs(path: &Path, options: &CsvOptions) -> Result<Vec<PosePair>, ImportError> {
    let n = options.form.columns();
    let expect = format!(
        "T_base_flange {h}, T_camera_target {h}",
        h = options.form.header()
    );
    csv_rows(path, 2 * n, &expect)?
        .into_iter()
        .map(|(line, v)| {
            let mut pair = PosePair::new(
                csv_pose(&v[..n], options, path, line, "T_base_flange")?,
                csv_pose(&v[n..], options, path, line, "T_camera_target")?,
            );
            pair.id = Some(format!("line-{line}"));
            Ok(pair)
        })
        .collect()
}

/// Reads two CSVs of one pose per row, paired by row order: `robot` holds `T_base_flange`,
/// `camera` holds `T_camera_target`. Both must have the same number of data rows.
pub fn import_csv_two_files(
    robot: &Path,
    camera: &Path,
    options: &CsvOptions,
) -> Result<Vec<PosePair>, ImportError> {
    let n = options.form.columns();
    let header = options.form.header();
    let robot_rows = csv_rows(robot, n, &format!("T_base_flange {header}"))?;
    let camera_rows = csv_rows(camera, n, &format!("T_camera_target {header}"))?;
    if robot_rows.len() != camera_rows.len() {
        return Err(ImportError::Format {
            path: camera.to_path_buf(),
            expected: "camera pose CSV paired with the robot pose CSV",
            problem: format!(
                "{} data rows, but {} has {}",
                camera_rows.len(),
                robot.display(),
                robot_rows.len()
            ),
        });
    }
    robot_rows
        .iter()
        .zip(&camera_rows)
        .enumerate()
        .map(|(i, ((rl, rv), (cl, cv)))| {
            let mut pair = PosePair::new(
                csv_pose(rv, options, robot, *rl, "T_base_flange")?,
                csv_pose(cv, options, camera, *cl, "T_camera_target")?,
            );
            pair.id = Some(format!("row-{}", i + 1));
            Ok(pair)
        })
        .collect()
}
