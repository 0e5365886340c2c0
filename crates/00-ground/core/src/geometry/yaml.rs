//! The pose form of every YAML file (DESIGN.md): `translation` plus exactly one of
//! `quaternion {w,x,y,z}`, `rotation_vector` (radians), `matrix`, `rpy_deg` (degrees, fixed-axis
//! roll about x, pitch about y, yaw about z: `R = Rz(yaw)·Ry(pitch)·Rx(roll)`, as URDF). A
//! rotation vector longer than 2π is refused as degrees written where radians belong.
//!
//! Parsing is two steps: serde reads the raw shape ([`PoseYaml`], unknown keys refused), then
//! [`PoseYaml::to_pose`] checks the values and names the YAML path of any problem
//! (`samples[3].T_camera_target.quaternion: ...`). Outputs use [`PoseRecord`], which carries
//! both `quaternion` and `rotation_vector` for people and other tools.

use nalgebra::{Matrix3, Quaternion, Translation3, UnitQuaternion, Vector3};
use serde::{Deserialize, Serialize};

use super::{check_translation, rotation_from_matrix, rotvec, Pose, TranslationProblem};

/// Largest accepted deviation of a quaternion's norm from 1 before it is called wrong
/// (not silently renormalised).
pub const QUATERNION_NORM_TOLERANCE: f64 = 1e-6;
/// Largest accepted `‖RᵀR − I‖_F` (and `|det R − 1|`) for a rotation matrix.
pub const MATRIX_ORTHONORMALITY_TOLERANCE: f64 = 1e-6;
/// Longest accepted rotation vector, rad: longer, it is almost surely degrees.
pub const MAX_ROTATION_VECTOR_RAD: f64 = 2.0 * std::f64::consts::PI;
/// Largest accepted disagreement (rad) between the two rotation forms of a [`PoseRecord`].
pub const RECORD_CONSISTENCY_TOLERANCE: f64 = 1e-6;

/// A quaternion with keyed components, so wxyz/xyzw order can never be confused.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, expecting = "a quaternion mapping {w, x, y, z}")]
pub struct QuaternionYaml {
    /// Scalar part.
    pub w: f64,
    /// Vector part, x.
    pub x: f64,
    /// Vector part, y.
    pub y: f64,
    /// Vector part, z.
    pub z: f64,
}

impl From<&UnitQuaternion<f64>> for QuaternionYaml {
    fn from(q: &UnitQuaternion<f64>) -> Self {
        // Write the w >= 0 hemisphere: one canonical form for diffs and people.
        let q = if q.w < 0.0 {
            -q.into_inner()
        } else {
            q.into_inner()
        };
        QuaternionYaml {
            w: q.w,
            x: q.i,
            y: q.j,
            z: q.k,
        }
    }
}

/// A pose as read from YAML, before validation. Lengths are checked by [`PoseYaml::to_pose`]
/// so the error can name the field.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(
    deny_unknown_fields,
    expecting = "a pose mapping (translation: [x, y, z] m and quaternion: {w, x, y, z}, rotation_vector: [rx, ry, rz] rad or rpy_deg: [roll, pitch, yaw] degrees)"
)]
pub struct PoseYaml {
    /// Translation in metres, `[x, y, z]`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub translation: Option<Vec<f64>>,
    /// Rotation as a unit quaternion.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub quaternion: Option<QuaternionYaml>,
    /// Rotation as axis · angle in radians (UR's form).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rotation_vector: Option<Vec<f64>>,
    /// Rotation as a row-major 3x3 matrix.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub matrix: Option<Vec<Vec<f64>>>,
    /// Rotation as fixed-axis roll (x), pitch (y), yaw (z) in degrees: `R = Rz·Ry·Rx` (URDF's
    /// `rpy`, in degrees for people).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rpy_deg: Option<Vec<f64>>,
}

/// What is wrong with a pose, and where (the YAML path of the offending field).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{path}: {problem}")]
pub struct PoseError {
    /// YAML path of the field, e.g. `samples[3].T_camera_target.quaternion`.
    pub path: String,
    /// What was expected and what was found.
    pub problem: PoseProblem,
}

/// The ways a YAML pose can be wrong.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PoseProblem {
    /// No `translation` key.
    #[error("missing key `translation` (expected [x, y, z] in metres)")]
    MissingTranslation,
    /// None of the rotation keys.
    #[error("missing rotation: expected exactly one of `quaternion`, `rotation_vector`, `matrix`, `rpy_deg`")]
    MissingRotation,
    /// More than one rotation key.
    #[error("{0} rotation keys given ({1}): expected exactly one of `quaternion`, `rotation_vector`, `matrix`, `rpy_deg`")]
    MultipleRotations(usize, String),
    /// A rotation vector longer than [`MAX_ROTATION_VECTOR_RAD`]: degrees where radians belong.
    #[error("rotation vector {given} is {norm:.1} long, more than 2π: it looks like degrees, but a rotation_vector is axis × angle in radians; write it in radians ({radians}) or as `rpy_deg: [roll, pitch, yaw]` in degrees")]
    DegreesInRotationVector {
        /// The vector as written.
        given: String,
        /// Its length.
        norm: f64,
        /// The same numbers read as degrees, converted to radians.
        radians: String,
    },
    /// An array of the wrong length.
    #[error("expected {expected} numbers, found {found}")]
    WrongLength {
        /// How many numbers the field takes.
        expected: usize,
        /// How many were given.
        found: usize,
    },
    /// NaN or infinity.
    #[error("value is not finite ({0})")]
    NotFinite(f64),
    /// A translation no robot cell has (see [`super::MAX_TRANSLATION_M`]).
    #[error("{0}")]
    Translation(TranslationProblem),
    /// A quaternion whose norm is off by more than [`QUATERNION_NORM_TOLERANCE`].
    #[error("quaternion norm is {0:.9}, expected 1 within {QUATERNION_NORM_TOLERANCE:e} (not renormalised: check the values and the component names w, x, y, z)")]
    QuaternionNorm(f64),
    /// A matrix that is not a rotation.
    #[error("not a rotation matrix: ‖RᵀR − I‖ = {orthonormality:.3e}, det = {determinant:.6} (expected orthonormal with det +1 within {MATRIX_ORTHONORMALITY_TOLERANCE:e})")]
    NotRotation {
        /// `‖RᵀR − I‖_F`.
        orthonormality: f64,
        /// `det R`.
        determinant: f64,
    },
    /// A [`PoseRecord`] whose `quaternion` and `rotation_vector` disagree.
    #[error("`quaternion` and `rotation_vector` disagree by {0:.3e} rad")]
    InconsistentForms(f64),
}

fn err(path: &str, field: &str, problem: PoseProblem) -> PoseError {
    let path = if field.is_empty() {
        path.to_string()
    } else if path.is_empty() {
        field.to_string()
    } else {
        format!("{path}.{field}")
    };
    PoseError { path, problem }
}

fn vector3(values: &[f64], path: &str, field: &str) -> Result<Vector3<f64>, PoseError> {
    if values.len() != 3 {
        return Err(err(
            path,
            field,
            PoseProblem::WrongLength {
                expected: 3,
                found: values.len(),
            },
        ));
    }
    finite(values, path, field)?;
    Ok(Vector3::new(values[0], values[1], values[2]))
}

/// A `translation` field: three numbers, checked by [`check_translation`].
fn translation(values: &[f64], path: &str) -> Result<Vector3<f64>, PoseError> {
    let t = vector3(values, path, "translation")?;
    check_translation(&t)
        .map_err(|problem| err(path, "translation", PoseProblem::Translation(problem)))?;
    Ok(t)
}

fn finite(values: &[f64], path: &str, field: &str) -> Result<(), PoseError> {
    match values.iter().find(|v| !v.is_finite()) {
        Some(bad) => Err(err(path, field, PoseProblem::NotFinite(*bad))),
        None => Ok(()),
    }
}

fn unit_quaternion(q: &QuaternionYaml, path: &str) -> Result<UnitQuaternion<f64>, PoseError> {
    finite(&[q.w, q.x, q.y, q.z], path, "quaternion")?;
    let raw = Quaternion::new(q.w, q.x, q.y, q.z);
    let norm = raw.norm();
    if (norm - 1.0).abs() > QUATERNION_NORM_TOLERANCE {
        return Err(err(path, "quaternion", PoseProblem::QuaternionNorm(norm)));
    }
    // A quaternion written from a unit one (as every file handeye writes holds) is read back as
    // written: renormalising a norm of 1 ± a few ulp would move the last digit on each read, so a
    // pose read, written and read again would not be the pose read (the report's "use it" text and
    // `handeye export` of the same result.yaml differed in the last digit). Further from 1, it is
    // normalised.
    if (norm - 1.0).abs() <= UNIT_NORM_ULPS * f64::EPSILON {
        return Ok(UnitQuaternion::new_unchecked(raw));
    }
    Ok(UnitQuaternion::from_quaternion(raw))
}

/// How far (in units of `f64::EPSILON`) a quaternion's norm may be from 1 and still count as a
/// unit one as written: a product of a few unit quaternions in memory stays within this.
const UNIT_NORM_ULPS: f64 = 8.0;

impl PoseYaml {
    /// Validates and converts to a pose; `path` is this pose's YAML path, used in errors.
    pub fn to_pose(&self, path: &str) -> Result<Pose, PoseError> {
        let translation = match &self.translation {
            Some(t) => translation(t, path)?,
            None => return Err(err(path, "", PoseProblem::MissingTranslation)),
        };
        let given: Vec<&str> = [
            self.quaternion.as_ref().map(|_| "quaternion"),
            self.rotation_vector.as_ref().map(|_| "rotation_vector"),
            self.matrix.as_ref().map(|_| "matrix"),
            self.rpy_deg.as_ref().map(|_| "rpy_deg"),
        ]
        .into_iter()
        .flatten()
        .collect();
        if given.len() > 1 {
            return Err(err(
                path,
                "",
                PoseProblem::MultipleRotations(given.len(), given.join(", ")),
            ));
        }
        let rotation = if let Some(q) = &self.quaternion {
            unit_quaternion(q, path)?
        } else if let Some(rv) = &self.rotation_vector {
            let v = vector3(rv, path, "rotation_vector")?;
            if v.norm() > MAX_ROTATION_VECTOR_RAD {
                let list = |v: Vector3<f64>| {
                    format!(
                        "[{}]",
                        v.iter()
                            .map(|x| super::readable(*x))
                            .collect::<Vec<_>>()
                            .join(", ")
                    )
                };
                return Err(err(
                    path,
                    "rotation_vector",
                    PoseProblem::DegreesInRotationVector {
                        given: list(v),
                        norm: v.norm(),
                        radians: format!(
                            "[{}]",
                            v.iter()
                                .map(|x| format!("{:.4}", x.to_radians()))
                                .collect::<Vec<_>>()
                                .join(", ")
                        ),
                    },
                ));
            }
            UnitQuaternion::from_scaled_axis(v)
        } else if let Some(rows) = &self.matrix {
            matrix_rotation(rows, path)?
        } else if let Some(rpy) = &self.rpy_deg {
            let v = vector3(rpy, path, "rpy_deg")?.map(f64::to_radians);
            UnitQuaternion::from_euler_angles(v[0], v[1], v[2])
        } else {
            return Err(err(path, "", PoseProblem::MissingRotation));
        };
        Ok(Pose::from_parts(Translation3::from(translation), rotation))
    }

    /// The compact form (translation + quaternion) that [`PoseYaml::to_pose`] reads back exactly.
    pub fn from_pose(pose: &Pose) -> Self {
        PoseYaml {
            translation: Some(pose.translation.vector.iter().copied().collect()),
            quaternion: Some(QuaternionYaml::from(&pose.rotation)),
            rotation_vector: None,
            matrix: None,
            rpy_deg: None,
        }
    }
}

fn matrix_rotation(rows: &[Vec<f64>], path: &str) -> Result<UnitQuaternion<f64>, PoseError> {
    if rows.len() != 3 {
        return Err(err(
            path,
            "matrix",
            PoseProblem::WrongLength {
                expected: 3,
                found: rows.len(),
            },
        ));
    }
    let mut m = Matrix3::zeros();
    for (r, row) in rows.iter().enumerate() {
        let field = format!("matrix[{r}]");
        if row.len() != 3 {
            return Err(err(
                path,
                &field,
                PoseProblem::WrongLength {
                    expected: 3,
                    found: row.len(),
                },
            ));
        }
        finite(row, path, &field)?;
        for (c, v) in row.iter().enumerate() {
            m[(r, c)] = *v;
        }
    }
    rotation_from_matrix(&m, MATRIX_ORTHONORMALITY_TOLERANCE).ok_or_else(|| {
        err(
            path,
            "matrix",
            PoseProblem::NotRotation {
                orthonormality: (m.transpose() * m - Matrix3::identity()).norm(),
                determinant: m.determinant(),
            },
        )
    })
}

/// A pose as written in results: translation, quaternion and rotation vector together.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(
    deny_unknown_fields,
    expecting = "a pose mapping (translation: [x, y, z] m and quaternion: {w, x, y, z}, rotation_vector: [rx, ry, rz] rad or rpy_deg: [roll, pitch, yaw] degrees)"
)]
pub struct PoseRecord {
    /// Translation in metres.
    pub translation: [f64; 3],
    /// Rotation as a unit quaternion (w >= 0).
    pub quaternion: QuaternionYaml,
    /// The same rotation as axis · angle in radians.
    pub rotation_vector: [f64; 3],
}

impl PoseRecord {
    /// The record of a pose.
    pub fn from_pose(pose: &Pose) -> Self {
        let rv = rotvec(&pose.rotation);
        let t = pose.translation.vector;
        PoseRecord {
            translation: [t.x, t.y, t.z],
            quaternion: QuaternionYaml::from(&pose.rotation),
            rotation_vector: [rv.x, rv.y, rv.z],
        }
    }

    /// Reads the pose back, checking that both rotation forms agree.
    pub fn to_pose(&self, path: &str) -> Result<Pose, PoseError> {
        let translation = translation(&self.translation, path)?;
        let rotation = unit_quaternion(&self.quaternion, path)?;
        let from_rotvec = UnitQuaternion::from_scaled_axis(vector3(
            &self.rotation_vector,
            path,
            "rotation_vector",
        )?);
        let disagreement = rotation.angle_to(&from_rotvec);
        if disagreement > RECORD_CONSISTENCY_TOLERANCE {
            return Err(err(path, "", PoseProblem::InconsistentForms(disagreement)));
        }
        Ok(Pose::from_parts(Translation3::from(translation), rotation))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(text: &str) -> Result<Pose, PoseError> {
        let raw: PoseYaml = serde_yaml_ng::from_str(text).expect("shape parses");
        raw.to_pose("samples[3].T_camera_target")
    }

    #[test]
    fn reads_each_rotation_form_to_the_same_pose() {
        let q = parse("translation: [1, 2, 3]\nquaternion: {w: 0.7071067811865476, x: 0, y: 0, z: 0.7071067811865476}").unwrap();
        let rv =
            parse("translation: [1, 2, 3]\nrotation_vector: [0, 0, 1.5707963267948966]").unwrap();
        let m =
            parse("translation: [1, 2, 3]\nmatrix: [[0, -1, 0], [1, 0, 0], [0, 0, 1]]").unwrap();
        let rpy = parse("translation: [1, 2, 3]\nrpy_deg: [0, 0, 90]").unwrap();
        assert!(q.rotation.angle_to(&rv.rotation) < 1e-12);
        assert!(q.rotation.angle_to(&m.rotation) < 1e-12);
        assert!(q.rotation.angle_to(&rpy.rotation) < 1e-12);
        // Fixed-axis roll, pitch, yaw: R = Rz(yaw)·Ry(pitch)·Rx(roll).
        let rpy = parse("translation: [0, 0, 0]\nrpy_deg: [10, -20, 30]").unwrap();
        let expected = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), 30f64.to_radians())
            * UnitQuaternion::from_axis_angle(&Vector3::y_axis(), (-20f64).to_radians())
            * UnitQuaternion::from_axis_angle(&Vector3::x_axis(), 10f64.to_radians());
        assert!(rpy.rotation.angle_to(&expected) < 1e-12);
        assert_eq!(q.translation.vector, Vector3::new(1.0, 2.0, 3.0));
    }

    #[test]
    fn errors_name_path_and_problem() {
        let cases = [
            ("quaternion: {w: 1, x: 0, y: 0, z: 0}", "samples[3].T_camera_target: missing key `translation`"),
            ("translation: [0, 0, 0]", "missing rotation"),
            ("translation: [0, 0, 0]\nquaternion: {w: 1, x: 0, y: 0, z: 0}\nrotation_vector: [0, 0, 0]", "2 rotation keys given (quaternion, rotation_vector)"),
            ("translation: [0, 0]\nrotation_vector: [0, 0, 0]", "samples[3].T_camera_target.translation: expected 3 numbers, found 2"),
            ("translation: [0, .nan, 0]\nrotation_vector: [0, 0, 0]", "translation: value is not finite"),
            ("translation: [0, 0, 0]\nrotation_vector: [0, .inf, 0]", "rotation_vector: value is not finite"),
            // Issue #13.7: a huge finite translation.
            ("translation: [1e300, 0, 0]\nrotation_vector: [0, 0, 0]", "samples[3].T_camera_target.translation: [1e300, 0, 0] m lies 1e300 m from the origin, beyond the 100 m"),
            ("translation: [0, 0, 0]\nquaternion: {w: 1, x: 0.01, y: 0, z: 0}", "samples[3].T_camera_target.quaternion: quaternion norm is 1.000049999"),
            ("translation: [0, 0, 0]\nmatrix: [[1, 0.1, 0], [0, 1, 0], [0, 0, 1]]", "matrix: not a rotation matrix"),
            ("translation: [0, 0, 0]\nmatrix: [[1, 0, 0], [0, 1, 0]]", "matrix: expected 3 numbers, found 2"),
            ("translation: [0, 0, 0]\nmatrix: [[1, 0, 0], [0, 1], [0, 0, 1]]", "matrix[1]: expected 3 numbers, found 2"),
            // Issue #30: degrees in a rotation vector.
            ("translation: [0, 0, 0]\nrotation_vector: [0, 0, -90]", "samples[3].T_camera_target.rotation_vector: rotation vector [0, 0, -90] is 90.0 long, more than 2π: it looks like degrees, but a rotation_vector is axis × angle in radians; write it in radians ([0.0000, 0.0000, -1.5708]) or as `rpy_deg: [roll, pitch, yaw]` in degrees"),
            ("translation: [0, 0, 0]\nrpy_deg: [0, 0]", "rpy_deg: expected 3 numbers, found 2"),
            ("translation: [0, 0, 0]\nrpy_deg: [0, 0, 0]\nmatrix: [[1, 0, 0], [0, 1, 0], [0, 0, 1]]", "2 rotation keys given (matrix, rpy_deg)"),
        ];
        for (text, expected) in cases {
            let message = parse(text).unwrap_err().to_string();
            assert!(message.contains(expected), "{text:?} gave {message:?}");
        }
    }

    /// A pose written and read back is the pose written, bit for bit, and a pose read, written
    /// and read again is the pose read: the YAML round trip is idempotent (what `handeye export`
    /// reads from result.yaml is what the report showed from the same answer).
    #[test]
    fn written_poses_read_back_bit_for_bit() {
        let mut rotation = UnitQuaternion::identity();
        for k in 0..2000 {
            // Products of rotations drift off unit norm by a few ulp, as answers in memory do.
            let k = f64::from(k);
            let step = Vector3::new((k * 0.37).sin(), (k * 0.71).cos(), (k * 1.13).sin()) * 0.9;
            rotation *= UnitQuaternion::from_scaled_axis(step);
            let pose = Pose::from_parts(Translation3::new(k * 1e-3, -0.25, 1.0 / 3.0), rotation);
            let read = |text: &str| {
                serde_yaml_ng::from_str::<PoseYaml>(text)
                    .unwrap()
                    .to_pose("")
                    .unwrap()
            };
            let text = serde_yaml_ng::to_string(&PoseYaml::from_pose(&pose)).unwrap();
            let once = read(&text);
            let again = read(&serde_yaml_ng::to_string(&PoseYaml::from_pose(&once)).unwrap());
            assert_eq!(once, again, "{text}");
            let q = QuaternionYaml::from(&pose.rotation);
            let back = QuaternionYaml::from(&once.rotation);
            if (pose.rotation.norm() - 1.0).abs() <= UNIT_NORM_ULPS * f64::EPSILON {
                assert_eq!(
                    [q.w, q.x, q.y, q.z],
                    [back.w, back.x, back.y, back.z],
                    "{text}"
                );
            }
            assert_eq!(pose.translation, once.translation);
        }
    }

    #[test]
    fn unknown_keys_are_refused() {
        let result: Result<PoseYaml, _> =
            serde_yaml_ng::from_str("translation: [0, 0, 0]\nrotation_vectr: [0, 0, 0]");
        assert!(result.unwrap_err().to_string().contains("rotation_vectr"));
    }

    #[test]
    fn tiny_norm_error_is_accepted_and_normalised() {
        let p =
            parse("translation: [0, 0, 0]\nquaternion: {w: 1.0000004, x: 0, y: 0, z: 0}").unwrap();
        assert!((p.rotation.into_inner().norm() - 1.0).abs() < 1e-15);
    }

    #[test]
    fn records_round_trip_and_detect_inconsistency() {
        let pose = Pose::from_parts(
            Translation3::new(0.1, -0.2, 0.3),
            UnitQuaternion::from_euler_angles(0.3, -1.2, 2.9),
        );
        let record = PoseRecord::from_pose(&pose);
        let text = serde_yaml_ng::to_string(&record).unwrap();
        let back: PoseRecord = serde_yaml_ng::from_str(&text).unwrap();
        let back = back.to_pose("x").unwrap();
        assert!(back.rotation.angle_to(&pose.rotation) < 1e-12);
        assert!((back.translation.vector - pose.translation.vector).norm() < 1e-15);

        let mut bad = record.clone();
        bad.rotation_vector[0] += 0.01;
        assert!(matches!(
            bad.to_pose("x").unwrap_err().problem,
            PoseProblem::InconsistentForms(_)
        ));
        let compact = PoseYaml::from_pose(&pose).to_pose("x").unwrap();
        assert!(compact.rotation.angle_to(&pose.rotation) < 1e-15);
    }
}
