//! Exports of a cell with several cameras (`result.yaml` of a several-camera session): every
//! camera's mount, the boards, and the camera-to-camera transforms, each `T_parent_child` under
//! its frame ids.
//!
//! Frame ids: `base` and `flange` as [`FrameIds`] says; camera `<name>` is
//! `<camera id>_<name>` (`camera_optical_frame_wrist` with the default ids, so every camera's
//! optical frame is distinct); the fixed board is the target id, the flange board the target id
//! with `_flange`. ROS 2 and URDF hold a tree (one parent per frame), so they carry the mounts
//! and boards, with the camera-to-camera transforms as comments (published too, they would give
//! a camera two parents); OpenCV's file holds every transform as a 4x4 matrix.

use std::fmt::Write as _;

use handeye_core::geometry::Pose;
use handeye_session::cell::rig::solve::NamedTransform;
use handeye_session::cell::rig::RigResultFile;

use super::export::{
    is_ur_base_link, opencv_matrix, static_publisher_command, ur_base_link_from_base, urdf_joint,
    ExportError, ExportFormat, FrameIds,
};

/// One exported transform with its frame ids.
struct Exported<'a> {
    name: &'a str,
    parent: String,
    child: String,
    pose: Pose,
}

fn frame_id(frame: &str, ids: &FrameIds, flange_board: bool) -> String {
    match frame {
        "base" => ids.base.clone(),
        "flange" => ids.flange.clone(),
        "target" if flange_board => format!("{}_flange", ids.target),
        "target" => ids.target.clone(),
        camera => format!(
            "{}_{}",
            ids.camera,
            camera.strip_prefix("cam_").unwrap_or(camera)
        ),
    }
}

fn exported<'a>(t: &'a NamedTransform, ids: &FrameIds) -> Exported<'a> {
    let flange_board = t.parent == "flange" && t.child == "target";
    let pose = if t.parent == "base" && is_ur_base_link(&ids.base) {
        ur_base_link_from_base() * t.pose
    } else {
        t.pose
    };
    Exported {
        name: &t.name,
        parent: frame_id(&t.parent, ids, flange_board),
        child: frame_id(&t.child, ids, flange_board),
        pose,
    }
}

/// The text of a several-camera result in `format` (ROS 2, URDF or OpenCV).
pub fn export_rig(
    result: &RigResultFile,
    format: ExportFormat,
    ids: &FrameIds,
) -> Result<String, ExportError> {
    ids.validate()?;
    let tree: Vec<Exported> = result
        .cameras
        .iter()
        .filter_map(|c| c.joint.as_ref())
        .chain(&result.boards)
        .map(|t| exported(t, ids))
        .collect();
    let relative: Vec<Exported> = result
        .camera_to_camera
        .iter()
        .map(|t| exported(t, ids))
        .collect();
    let mut out = String::new();
    match format {
        ExportFormat::Ros2 => {
            out.push_str("# handeye calibration of a cell with several cameras: static transforms for ROS 2 (tf2_ros).\n# Each publishes T_parent_child: frame-id = parent, child-frame-id = child.\n");
            for t in &tree {
                let _ = writeln!(
                    out,
                    "# {}\n{}",
                    t.name,
                    static_publisher_command(&t.parent, &t.child, &t.pose)
                );
            }
            for t in &relative {
                let (p, q) = (t.pose.translation.vector, t.pose.rotation);
                let _ = writeln!(
                    out,
                    "# {} (implied by the mounts above; not published: {} already has a parent): xyz [{}, {}, {}], quaternion xyzw [{}, {}, {}, {}]",
                    t.name, t.child, p.x, p.y, p.z, q.i, q.j, q.k, q.w
                );
            }
        }
        ExportFormat::Urdf => {
            out.push_str("<!-- handeye calibration of a cell with several cameras. Each fixed joint holds T_parent_child;\n     rpy is fixed-axis roll (x), pitch (y), yaw (z). -->\n");
            for t in &tree {
                let _ = writeln!(out, "{}", urdf_joint(t.name, &t.parent, &t.child, &t.pose));
            }
            for t in &relative {
                let _ = writeln!(out, "<!-- {} is implied by the joints above -->", t.name);
            }
        }
        ExportFormat::Opencv => {
            out.push_str("%YAML:1.0\n---\n# handeye calibration of a cell with several cameras: 4x4 T_parent_child, row-major, metres.\n");
            for t in tree.iter().chain(&relative) {
                let _ = writeln!(out, "{}", opencv_matrix(t.name, &t.parent, &t.child, &t.pose));
            }
        }
        other => {
            return Err(ExportError::Unsupported(format!(
                "`{}` holds the two transforms of a one-camera cell; a cell with several cameras exports as ros2, urdf or opencv",
                other.name()
            )))
        }
    }
    Ok(out)
}
