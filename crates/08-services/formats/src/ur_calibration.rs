//! ur_robot_driver's kinematics calibration YAML (the form `ur_calibration` writes and
//! `ur_description` loads as `kinematics_params_file`) from the arm's model a solve estimated
//! (`result.yaml`'s `kinematics:` section, issue #41).
//!
//! ```yaml
//! kinematics:
//!   shoulder: {x: .., y: .., z: .., roll: .., pitch: .., yaw: ..}
//!   upper_arm: ...
//!   forearm: ...
//!   wrist_1: ...
//!   wrist_2: ...
//!   wrist_3: ...
//!   hash: calib_handeye_...
//! ```
//!
//! Each entry is the origin of one joint in its parent link (`ur_description`'s
//! `ur_macro.xacro`: `origin xyz rpy`, then the joint's rotation about its own z, the URDF's
//! `rpy` being `Rz(yaw)·Ry(pitch)·Rx(roll)`): from the published DH chain and the offsets,
//! joint `i`'s origin is `Tx(a_{i−1}) · Rx(α_{i−1}) · Tz(d_i) · Rz(δ_i)` (`Tz(d_i)` commutes with
//! the joint's turn). Chained from `base` (= `base_link_inertia`) to `tool0` (whose fixed
//! transforms to `wrist_3_link` compose to the identity) it reproduces the corrected forward
//! kinematics `FK(q + δ)` of the model. With the published table this is `ur_description`'s own
//! `default_kinematics.yaml`.
//!
//! `hash` names where the file came from: the driver compares it with the controller's own
//! calibration checksum and warns when they differ — these are handeye's estimates, not the
//! controller's factory calibration. Depends on `robot::kinematics` and `session::result`.

use std::fmt::Write as _;

use nalgebra::{Rotation3, Translation3, UnitQuaternion, Vector3};

use handeye_core::geometry::{dh_link, Pose};
use handeye_records::result::KinematicsYaml;
use handeye_robot::kinematics::{UrModel, JOINT_NAMES};

/// The joint names of the YAML, base first.
pub const LINKS: [&str; 6] = [
    "shoulder",
    "upper_arm",
    "forearm",
    "wrist_1",
    "wrist_2",
    "wrist_3",
];

/// Why no calibration file can be written.
#[derive(Debug, thiserror::Error)]
pub enum UrCalibrationError {
    /// The result's arm model is not one whose DH table handeye knows.
    #[error("kinematics.model: `{0}` is not a Universal Robots model handeye knows ({names})", names = UrModel::NAMES.join(", "))]
    UnknownModel(String),
    /// The result's offsets are not one per joint of a UR.
    #[error("kinematics.joint_offsets: {0} joints, a UR has 6")]
    JointCount(usize),
    /// A link correction names no joint or parameter of the chain.
    #[error("kinematics.links: `{joint} {parameter}` ({unit}) is not a link correction of a UR's chain (joints {joints}; parameters d and a in mm, alpha in deg)", joints = JOINT_NAMES.join(", "))]
    Link {
        /// The row's joint.
        joint: String,
        /// The row's parameter.
        parameter: String,
        /// The row's unit.
        unit: String,
    },
}

/// Each joint's origin in its parent link (see the module docs) for `model` with the joint zero
/// offsets `offsets_rad`.
pub fn joint_origins(model: &UrModel, offsets_rad: &[f64; 6]) -> [Pose; 6] {
    std::array::from_fn(|i| {
        let before = if i == 0 {
            Pose::identity()
        } else {
            dh_link(0.0, 0.0, model.a[i - 1], model.alpha[i - 1])
        };
        before
            * Pose::from_parts(
                Translation3::new(0.0, 0.0, model.d[i]),
                UnitQuaternion::from_axis_angle(&Vector3::z_axis(), offsets_rad[i]),
            )
    })
}

/// The arm's model a result's `kinematics` section holds: its model's published DH chain with
/// the section's link corrections (`links:`, `estimated: dh`), and the estimated joint zero
/// offsets, rad. Every export of the arm's model (this file, `arm_model`'s DH table and URDF)
/// starts here.
pub fn corrected_arm(
    kinematics: &KinematicsYaml,
) -> Result<(UrModel, [f64; 6]), UrCalibrationError> {
    let mut model = UrModel::by_name(&kinematics.model)
        .ok_or_else(|| UrCalibrationError::UnknownModel(kinematics.model.clone()))?;
    for link in &kinematics.links {
        let joint = JOINT_NAMES.iter().position(|n| *n == link.joint);
        let (slot, scale) = match (joint, link.parameter.as_str(), link.unit.as_str()) {
            (Some(j), "d", "mm") => (&mut model.d[j], 1e-3),
            (Some(j), "a", "mm") => (&mut model.a[j], 1e-3),
            (Some(j), "alpha", "deg") => (&mut model.alpha[j], 1f64.to_radians()),
            _ => {
                return Err(UrCalibrationError::Link {
                    joint: link.joint.clone(),
                    parameter: link.parameter.clone(),
                    unit: link.unit.clone(),
                })
            }
        };
        *slot += link.correction * scale;
    }
    let offsets: [f64; 6] = kinematics
        .joint_offsets
        .iter()
        .map(|o| o.offset_deg.to_radians())
        .collect::<Vec<_>>()
        .try_into()
        .map_err(|v: Vec<f64>| UrCalibrationError::JointCount(v.len()))?;
    Ok((model, offsets))
}

/// The calibration YAML of the arm's model in `kinematics` (a result's section).
pub fn ur_calibration_yaml(kinematics: &KinematicsYaml) -> Result<String, UrCalibrationError> {
    let (model, offsets) = corrected_arm(kinematics)?;
    let origins = joint_origins(&model, &offsets);
    let mut text = format!(
        "# ur_robot_driver kinematics calibration (the form ur_calibration writes; load it as\n\
         # kinematics_params_file): the {} published DH model (with the link corrections of\n\
         # `estimated: dh`) and the joint zero offsets handeye\n\
         # estimated (deg, base first: {}). Offsets the cell's transforms absorb are held at 0.\n\
         kinematics:\n",
        model.name,
        offsets
            .iter()
            .map(|o| format!("{:.5}", o.to_degrees()))
            .collect::<Vec<_>>()
            .join(", ")
    );
    let mut digest: u64 = 0xcbf2_9ce4_8422_2325;
    for (name, origin) in LINKS.iter().zip(&origins) {
        let t = origin.translation.vector;
        let (roll, pitch, yaw) = Rotation3::from(origin.rotation).euler_angles();
        let _ = writeln!(text, "  {name}:");
        for (key, value) in [
            ("x", t.x),
            ("y", t.y),
            ("z", t.z),
            ("roll", roll),
            ("pitch", pitch),
            ("yaw", yaw),
        ] {
            let _ = writeln!(text, "    {key}: {value}");
            // FNV-1a of the values: the hash names these numbers, not the controller's.
            for byte in value.to_bits().to_le_bytes() {
                digest = (digest ^ u64::from(byte)).wrapping_mul(0x100_0000_01b3);
            }
        }
    }
    let _ = writeln!(text, "  hash: calib_handeye_{digest:016x}");
    Ok(text)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_published_model_gives_ur_descriptions_default_kinematics() {
        // ur_description's config/ur10e/default_kinematics.yaml, as Universal Robots ships it.
        let origins = joint_origins(&UrModel::ur10e(), &[0.0; 6]);
        let expected = [
            ([0.0, 0.0, 0.1807], [0.0, 0.0, 0.0]),
            ([0.0, 0.0, 0.0], [std::f64::consts::FRAC_PI_2, 0.0, 0.0]),
            ([-0.6127, 0.0, 0.0], [0.0, 0.0, 0.0]),
            ([-0.57155, 0.0, 0.17415], [0.0, 0.0, 0.0]),
            (
                [0.0, -0.11985, 0.0],
                [std::f64::consts::FRAC_PI_2, 0.0, 0.0],
            ),
            (
                [0.0, 0.11655, 0.0],
                [
                    std::f64::consts::FRAC_PI_2,
                    std::f64::consts::PI,
                    std::f64::consts::PI,
                ],
            ),
        ];
        for (i, (origin, (xyz, rpy))) in origins.iter().zip(expected).enumerate() {
            assert!(
                (origin.translation.vector - Vector3::from(xyz)).norm() < 1e-9,
                "{i}: {origin}"
            );
            let want = Rotation3::from_euler_angles(rpy[0], rpy[1], rpy[2]);
            assert!(
                Rotation3::from(origin.rotation).angle_to(&want) < 1e-9,
                "{i}: {origin}"
            );
        }
    }
}
