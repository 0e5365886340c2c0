//! Exporters: the two solved unknowns of a result file written in the forms other tools read.
//!
//! | format   | what is written                                                                  |
//! |----------|----------------------------------------------------------------------------------|
//! | `ros2`   | one `ros2 run tf2_ros static_transform_publisher` command per unknown, and a Python launch snippet with the same two publishers |
//! | `urdf`   | one fixed `<joint>` per unknown (`<origin xyz rpy>`; URDF rpy = fixed-axis roll about x, then pitch about y, then yaw about z) |
//! | `ur`     | UR pose literals `p[x, y, z, rx, ry, rz]` (m, rotation vector rad): `set_tcp(..)` for a flange mount, a plain pose for a base mount |
//! | `json`   | an object keyed by `T_a_b`, each with parent, child, translation, quaternion (x, y, z, w), rotation vector and the 4x4 matrix |
//! | `opencv` | OpenCV FileStorage YAML (`%YAML:1.0`) with one `!!opencv-matrix` 4x4 (`dt: d`) per unknown |
//!
//! Every form carries `T_parent_child`: the transform that maps points in the child frame into
//! the parent frame (a ROS/TF transform from `frame_id` = parent to `child_frame_id` = child, a URDF
//! joint from parent link to child link). Numbers are printed with Rust's shortest round-trip
//! formatting, so nothing is lost to printing. The camera frame is the optical frame (x right,
//! y down, z forward): name its ROS id accordingly (`*_optical_frame`).
//! Depends on `geometry`, `setup::Setup` and `setup::CellTransforms` only; writes no files.

use std::fmt::Write as _;

use serde_json::json;

use crate::geometry::{rotvec, to_matrix4_rows, Pose};
use crate::setup::CellTransforms;
use crate::setup::Setup;

/// An export form.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ExportFormat {
    /// ROS 2 `static_transform_publisher` commands and a launch snippet.
    Ros2,
    /// URDF fixed-joint snippets.
    Urdf,
    /// UR pose literals `p[x, y, z, rx, ry, rz]`.
    Ur,
    /// JSON object.
    Json,
    /// OpenCV FileStorage YAML with 4x4 matrices.
    Opencv,
}

impl ExportFormat {
    /// Every format, in documentation order.
    pub const ALL: [ExportFormat; 5] = [
        ExportFormat::Ros2,
        ExportFormat::Urdf,
        ExportFormat::Ur,
        ExportFormat::Json,
        ExportFormat::Opencv,
    ];

    /// The name on the command line.
    pub fn name(self) -> &'static str {
        match self {
            ExportFormat::Ros2 => "ros2",
            ExportFormat::Urdf => "urdf",
            ExportFormat::Ur => "ur",
            ExportFormat::Json => "json",
            ExportFormat::Opencv => "opencv",
        }
    }
}

/// The frame ids written for our four frames (ROS TF ids, URDF link names, JSON parent/child).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct FrameIds {
    /// The robot base (the frame the robot reports `T_base_flange` in).
    pub base: String,
    /// The tool flange.
    pub flange: String,
    /// The camera's optical frame.
    pub camera: String,
    /// The board frame.
    pub target: String,
}

impl Default for FrameIds {
    /// ROS-Industrial / ur_robot_driver names: `base`, `tool0`, `camera_optical_frame`,
    /// `calibration_target`. (`base` is the frame the UR controller reports poses in; ROS
    /// `base_link` differs from it by 180° about z.)
    fn default() -> Self {
        FrameIds {
            base: "base".into(),
            flange: "tool0".into(),
            camera: "camera_optical_frame".into(),
            target: "calibration_target".into(),
        }
    }
}

/// One exported transform: `T_parent_child` with its frame ids.
#[derive(Debug, Clone, PartialEq)]
pub struct NamedTransform {
    /// Our name, `T_a_b` (`T_flange_camera`, ...).
    pub key: &'static str,
    /// The parent frame id (frame `a`).
    pub parent: String,
    /// The child frame id (frame `b`).
    pub child: String,
    /// `T_parent_child`.
    pub parent_from_child: Pose,
}

/// The two unknowns of a solved cell with their frame ids: camera mount first, target mount second.
pub fn named_transforms(mounts: &CellTransforms, ids: &FrameIds) -> [NamedTransform; 2] {
    let (camera_key, target_key) = mounts.setup.unknown_names();
    let (camera_parent, target_parent) = match mounts.setup {
        Setup::EyeInHand => (&ids.flange, &ids.base),
        Setup::EyeToHand => (&ids.base, &ids.flange),
    };
    [
        NamedTransform {
            key: camera_key,
            parent: camera_parent.clone(),
            child: ids.camera.clone(),
            parent_from_child: mounts.camera_mount,
        },
        NamedTransform {
            key: target_key,
            parent: target_parent.clone(),
            child: ids.target.clone(),
            parent_from_child: mounts.target_mount,
        },
    ]
}

/// The text of `mounts` in `format`.
pub fn export(mounts: &CellTransforms, format: ExportFormat, ids: &FrameIds) -> String {
    let transforms = named_transforms(mounts, ids);
    match format {
        ExportFormat::Ros2 => ros2(mounts.setup, &transforms),
        ExportFormat::Urdf => urdf(mounts.setup, &transforms),
        ExportFormat::Ur => ur(mounts.setup, &transforms),
        ExportFormat::Json => json_text(mounts.setup, &transforms),
        ExportFormat::Opencv => opencv(mounts.setup, &transforms),
    }
}

fn ros2(setup: Setup, transforms: &[NamedTransform; 2]) -> String {
    let mut out = format!(
        "# handeye calibration ({setup}): static transforms for ROS 2 (tf2_ros).\n\
         # Each publishes T_parent_child: frame-id = parent, child-frame-id = child.\n"
    );
    for t in transforms {
        let (p, q) = (
            t.parent_from_child.translation.vector,
            t.parent_from_child.rotation,
        );
        let _ = writeln!(
            out,
            "# {}\nros2 run tf2_ros static_transform_publisher --x {} --y {} --z {} --qx {} --qy {} --qz {} --qw {} --frame-id {} --child-frame-id {}",
            t.key, p.x, p.y, p.z, q.i, q.j, q.k, q.w, t.parent, t.child
        );
    }
    out.push_str(
        "\n# Launch snippet (Python launch file):\n\
         from launch import LaunchDescription\n\
         from launch_ros.actions import Node\n\n\n\
         def generate_launch_description():\n    return LaunchDescription([\n",
    );
    for t in transforms {
        let (p, q) = (
            t.parent_from_child.translation.vector,
            t.parent_from_child.rotation,
        );
        let name = t.key.to_lowercase();
        let _ = writeln!(
            out,
            "        Node(\n            package='tf2_ros',\n            executable='static_transform_publisher',\n            name='handeye_{name}',\n            arguments=['--x', '{}', '--y', '{}', '--z', '{}',\n                       '--qx', '{}', '--qy', '{}', '--qz', '{}', '--qw', '{}',\n                       '--frame-id', '{}', '--child-frame-id', '{}'],\n        ),",
            p.x, p.y, p.z, q.i, q.j, q.k, q.w, t.parent, t.child
        );
    }
    out.push_str("    ])\n");
    out
}

fn urdf(setup: Setup, transforms: &[NamedTransform; 2]) -> String {
    let mut out = format!(
        "<!-- handeye calibration ({setup}). Each fixed joint holds T_parent_child; rpy is fixed-axis\n     roll (x), pitch (y), yaw (z): R = Rz(yaw) Ry(pitch) Rx(roll). Add the child links if\n     your URDF lacks them. -->\n"
    );
    for t in transforms {
        let p = t.parent_from_child.translation.vector;
        let (roll, pitch, yaw) = t.parent_from_child.rotation.euler_angles();
        let _ = writeln!(
            out,
            "<!-- {} -->\n<joint name=\"{}_to_{}_joint\" type=\"fixed\">\n  <parent link=\"{}\"/>\n  <child link=\"{}\"/>\n  <origin xyz=\"{} {} {}\" rpy=\"{} {} {}\"/>\n</joint>",
            t.key, t.parent, t.child, t.parent, t.child, p.x, p.y, p.z, roll, pitch, yaw
        );
    }
    out
}

/// The UR pose literal `p[x, y, z, rx, ry, rz]` of a pose (m, rotation vector in rad).
pub fn ur_pose_literal(pose: &Pose) -> String {
    let p = pose.translation.vector;
    let r = rotvec(&pose.rotation);
    format!("p[{}, {}, {}, {}, {}, {}]", p.x, p.y, p.z, r.x, r.y, r.z)
}

fn ur(setup: Setup, transforms: &[NamedTransform; 2]) -> String {
    let mut out = format!(
        "# handeye calibration ({setup}) as UR pose literals p[x, y, z, rx, ry, rz] (m, rotation vector rad).\n"
    );
    for (i, t) in transforms.iter().enumerate() {
        let literal = ur_pose_literal(&t.parent_from_child);
        let is_flange_mount = match setup {
            Setup::EyeInHand => i == 0,
            Setup::EyeToHand => i == 1,
        };
        if is_flange_mount {
            let _ = writeln!(
                out,
                "# {}: a TCP offset from the flange (Installation > TCP, or in a program):\nset_tcp({literal})",
                t.key
            );
        } else {
            let _ = writeln!(
                out,
                "# {}: a pose in the robot base frame (e.g. a plane or point feature):\n{}_{} = {literal}",
                t.key, t.parent, t.child
            );
        }
    }
    out
}

fn json_value(setup: Setup, transforms: &[NamedTransform; 2]) -> serde_json::Value {
    let mut object = serde_json::Map::new();
    object.insert("setup".into(), json!(setup.name()));
    for t in transforms {
        let p = t.parent_from_child.translation.vector;
        let q = t.parent_from_child.rotation;
        let r = rotvec(&q);
        object.insert(
            t.key.into(),
            json!({
                "parent": t.parent,
                "child": t.child,
                "translation": [p.x, p.y, p.z],
                "quaternion": {"x": q.i, "y": q.j, "z": q.k, "w": q.w},
                "rotation_vector": [r.x, r.y, r.z],
                "matrix": to_matrix4_rows(&t.parent_from_child),
            }),
        );
    }
    serde_json::Value::Object(object)
}

fn json_text(setup: Setup, transforms: &[NamedTransform; 2]) -> String {
    let mut text = serde_json::to_string_pretty(&json_value(setup, transforms))
        .expect("a JSON value always serialises");
    text.push('\n');
    text
}

fn opencv(setup: Setup, transforms: &[NamedTransform; 2]) -> String {
    let mut out = format!(
        "%YAML:1.0\n---\n# handeye calibration: 4x4 T_parent_child, row-major, metres.\nsetup: \"{setup}\"\n"
    );
    for t in transforms {
        let data: Vec<String> = to_matrix4_rows(&t.parent_from_child)
            .iter()
            .flatten()
            .map(|v| format!("{v:e}"))
            .collect();
        let _ = writeln!(
            out,
            "{}: !!opencv-matrix\n   rows: 4\n   cols: 4\n   dt: d\n   data: [ {} ]\n{}_parent: \"{}\"\n{}_child: \"{}\"",
            t.key,
            data.join(", "),
            t.key,
            t.parent,
            t.key,
            t.child
        );
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Translation3, UnitQuaternion, Vector3};

    fn mounts(setup: Setup) -> CellTransforms {
        CellTransforms {
            setup,
            camera_mount: Pose::from_parts(
                Translation3::new(0.05, -0.02, 0.11),
                UnitQuaternion::from_euler_angles(0.1, -0.2, 1.3),
            ),
            target_mount: Pose::from_parts(
                Translation3::new(0.8, 0.1, -0.03),
                UnitQuaternion::from_euler_angles(3.0, 0.4, -2.2),
            ),
        }
    }

    #[test]
    fn ur_literal_is_translation_and_rotation_vector() {
        let pose = Pose::from_parts(
            Translation3::new(0.1, 0.2, 0.3),
            UnitQuaternion::from_scaled_axis(Vector3::new(0.0, 0.0, 0.5)),
        );
        assert_eq!(ur_pose_literal(&pose), "p[0.1, 0.2, 0.3, 0, 0, 0.5]");
    }

    #[test]
    fn frame_ids_follow_the_setup() {
        let ids = FrameIds::default();
        let [camera, target] = named_transforms(&mounts(Setup::EyeInHand), &ids);
        assert_eq!(
            (camera.key, camera.parent.as_str(), camera.child.as_str()),
            ("T_flange_camera", "tool0", "camera_optical_frame")
        );
        assert_eq!(
            (target.key, target.parent.as_str()),
            ("T_base_target", "base")
        );
        let [camera, target] = named_transforms(&mounts(Setup::EyeToHand), &ids);
        assert_eq!(
            (camera.key, camera.parent.as_str()),
            ("T_base_camera", "base")
        );
        assert_eq!(
            (target.key, target.parent.as_str()),
            ("T_flange_target", "tool0")
        );
        let ur_text = export(&mounts(Setup::EyeToHand), ExportFormat::Ur, &ids);
        assert!(ur_text.contains("set_tcp(p["), "{ur_text}");
        assert!(
            ur_text.contains("base_camera_optical_frame = p["),
            "{ur_text}"
        );
    }
}
