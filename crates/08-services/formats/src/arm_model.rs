//! The arm's model a solve estimated (`result.yaml`'s `kinematics:` section, issue #41) in two
//! more forms beside ur_robot_driver's calibration file (`ur_calibration`):
//!
//! - a plain DH table ([`dh_table`]): per joint `a`, `d`, `alpha`, `theta_offset` (m, rad) of
//!   the standard DH convention, a header comment saying so, one joint a line;
//! - a standalone URDF of the arm's kinematic chain ([`arm_urdf`]): `base` → the six revolute
//!   joints of `ur_description` (`shoulder_pan_joint` … `wrist_3_joint`, their links
//!   `shoulder_link` … `wrist_3_link`) → `tool0`, each joint's `origin xyz rpy` the joint origin
//!   of the corrected model. A ROS user loads it as it is (`robot_state_publisher`, an IK solver) to get the corrected `T_base_tool0`; it carries kinematics only (no meshes,
//!   no inertias, `effort`/`velocity` 0), so for a full robot description the same numbers go
//!   to `ur_description` through `--format ur-calibration`.
//!
//! Both are computed from the one corrected chain ([`corrected_arm`]) and the URDF's origins by
//! the one [`joint_origins`], so the three forms cannot disagree. `base` is the controller's base
//! frame (`ur_description`'s `base` and `base_link_inertia`), `tool0` the flange (no TCP offset).

use std::fmt::Write as _;

use nalgebra::Rotation3;

use crate::ur_calibration::{corrected_arm, joint_origins, UrCalibrationError};
use handeye_records::result::KinematicsYaml;

// The joints as `ur_description` names them, base first: the names the UR ROS 2 driver
// publishes (one list, the config's); each turns the link of `LINKS` at the same place.
use handeye_config::ros2::UR_DRIVER_JOINT_NAMES as JOINTS;

/// The link each joint moves (`shoulder_pan_joint` the first), as `ur_description` names them.
pub const LINKS: [&str; 6] = [
    "shoulder_link",
    "upper_arm_link",
    "forearm_link",
    "wrist_1_link",
    "wrist_2_link",
    "wrist_3_link",
];

/// Which offsets the transforms absorbed or the data left undetermined (held at zero), as a
/// clause for the files' headers.
fn held(kinematics: &KinematicsYaml) -> String {
    let names: Vec<&str> = kinematics
        .joint_offsets
        .iter()
        .filter(|o| o.absorbed_by.is_some() || o.undetermined)
        .map(|o| o.joint.as_str())
        .collect();
    if names.is_empty() {
        "every offset estimated".into()
    } else {
        format!(
            "held at 0 (absorbed by the cell's transforms or undetermined): {}",
            names.join(", ")
        )
    }
}

/// The DH table of the arm's model in `kinematics` (a result's section).
pub fn dh_table(kinematics: &KinematicsYaml) -> Result<String, UrCalibrationError> {
    let (model, offsets) = corrected_arm(kinematics)?;
    let mut text = format!(
        "# DH table of the {} as handeye estimated it (result.yaml `kinematics:`, estimated: {}).\n\
         # Standard DH, base first: T_{{i-1}}_{{i}} = Rz(q_i + theta_offset_i) * Tz(d_i) * Tx(a_i) * Rx(alpha_i),\n\
         # q_i the joint angle the controller reports; chained from the base frame to the flange (tool0).\n\
         # Metres and radians. The published table (with the link corrections of `estimated: dh`)\n\
         # and the joint zero offsets; {}.\n\
         # joint a d alpha theta_offset\n",
        model.name,
        kinematics.estimated,
        held(kinematics)
    );
    for (i, joint) in JOINTS.iter().enumerate() {
        // `{}` of an f64 is its shortest exact form: the table reads back to the same numbers.
        let _ = writeln!(
            text,
            "{joint} {} {} {} {}",
            model.a[i], model.d[i], model.alpha[i], offsets[i]
        );
    }
    Ok(text)
}

/// The standalone URDF of the arm's kinematic chain in `kinematics` (a result's section).
pub fn arm_urdf(kinematics: &KinematicsYaml) -> Result<String, UrCalibrationError> {
    let (model, offsets) = corrected_arm(kinematics)?;
    let origins = joint_origins(&model, &offsets);
    let mut text = format!(
        "<?xml version=\"1.0\"?>\n\
         <!-- The {name}'s kinematic chain as handeye estimated it (result.yaml `kinematics:`, estimated:\n     \
         {estimated}): ur_description's joints, each origin the DH link (published, corrected under dh) with the joint zero\n     \
         offset ({held}). base is the controller's base frame, tool0 the flange.\n     \
         Kinematics only: no meshes or inertias; effort and velocity are 0, position limits as handeye\n     \
         plans with. origin rpy: R = Rz(yaw) * Ry(pitch) * Rx(roll). -->\n\
         <robot name=\"{name}_handeye\">\n  <link name=\"base\"/>\n",
        name = model.name,
        estimated = kinematics.estimated,
        held = held(kinematics),
    );
    for (i, origin) in origins.iter().enumerate() {
        let t = origin.translation.vector;
        let (roll, pitch, yaw) = Rotation3::from(origin.rotation).euler_angles();
        let parent = if i == 0 { "base" } else { LINKS[i - 1] };
        let (lower, upper) = model.joint_limits[i];
        let _ = write!(
            text,
            "  <link name=\"{link}\"/>\n  <joint name=\"{joint}\" type=\"revolute\">\n    \
             <parent link=\"{parent}\"/>\n    <child link=\"{link}\"/>\n    \
             <origin xyz=\"{} {} {}\" rpy=\"{roll} {pitch} {yaw}\"/>\n    \
             <axis xyz=\"0 0 1\"/>\n    \
             <limit lower=\"{lower}\" upper=\"{upper}\" effort=\"0\" velocity=\"0\"/>\n  </joint>\n",
            t.x,
            t.y,
            t.z,
            link = LINKS[i],
            joint = JOINTS[i],
        );
    }
    text.push_str(
        "  <link name=\"tool0\"/>\n  <joint name=\"wrist_3_link-tool0_fixed_joint\" type=\"fixed\">\n    \
         <parent link=\"wrist_3_link\"/>\n    <child link=\"tool0\"/>\n    \
         <origin xyz=\"0 0 0\" rpy=\"0 0 0\"/>\n  </joint>\n</robot>\n",
    );
    Ok(text)
}
