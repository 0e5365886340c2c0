//! `export --format ros2-launch`: a ROS 2 Python launch file that runs as written
//! (`ros2 launch ./handeye_calibration.launch.py`): one `tf2_ros` `static_transform_publisher`
//! node per solved transform, each `T_parent_child` with its translation and quaternion.
//!
//! A camera driver usually publishes its own `camera_link → … → camera_optical_frame`; a frame
//! has one parent in TF, so publishing `T_flange_camera_optical_frame` beside it breaks the tree.
//! [`through_camera_link`] turns the camera's transform into one to its mounting link, given the
//! driver's own `T_link_optical` (read from the graph by the CLI; [`link_from_optical`] is the
//! bare optical rotation of REP 103 body axes), which the driver's chain then completes.

use std::fmt::Write as _;

use nalgebra::{Matrix3, Rotation3, Translation3, UnitQuaternion};

use super::export::{ExportedCell, FramedTransform};
use handeye_core::geometry::Pose;

/// `T_link_optical` of a camera whose link has REP 103 body axes: optical z (forward) is the
/// link's x, optical x (right) its -y, optical y (down) its -z; no offset.
pub fn link_from_optical() -> Pose {
    let columns = Matrix3::new(0.0, 0.0, 1.0, -1.0, 0.0, 0.0, 0.0, -1.0, 0.0);
    let rotation = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(columns));
    Pose::from_parts(Translation3::identity(), rotation)
}

/// The camera's transform re-hung from its mounting link `link`, whose chain to the optical
/// frame is `link_from_optical`: `T_parent_link = T_parent_optical · inv(T_link_optical)`, child
/// `link`.
pub fn through_camera_link(
    camera: &FramedTransform,
    link: &str,
    link_from_optical: &Pose,
) -> FramedTransform {
    FramedTransform {
        key: camera.key.clone(),
        parent: camera.parent.clone(),
        child: link.to_string(),
        parent_from_child: camera.parent_from_child * link_from_optical.inverse(),
    }
}

/// The launch file publishing `transforms`.
pub fn launch_file(cell: ExportedCell, transforms: &[FramedTransform]) -> String {
    let mut out = format!(
        "# handeye calibration {cell}: static transforms for ROS 2, run with\n\
         #   ros2 launch ./handeye_calibration.launch.py\n\
         # Each node publishes T_parent_child on /tf_static (frame-id = parent, child-frame-id = child).\n\
         from launch import LaunchDescription\n\
         from launch_ros.actions import Node\n\n\n\
         def generate_launch_description():\n    return LaunchDescription([\n"
    );
    for t in transforms {
        let (p, q) = (
            t.parent_from_child.translation.vector,
            t.parent_from_child.rotation,
        );
        let _ = writeln!(
            out,
            "        # {key}\n        Node(\n            package='tf2_ros',\n            executable='static_transform_publisher',\n            name='handeye_{name}',\n            arguments=['--x', '{}', '--y', '{}', '--z', '{}',\n                       '--qx', '{}', '--qy', '{}', '--qz', '{}', '--qw', '{}',\n                       '--frame-id', '{}', '--child-frame-id', '{}'],\n        ),",
            p.x,
            p.y,
            p.z,
            q.i,
            q.j,
            q.k,
            q.w,
            t.parent,
            t.child,
            key = t.key,
            name = t.key.to_lowercase(),
        );
    }
    out.push_str("    ])\n");
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Vector3;

    #[test]
    fn the_optical_rotation_maps_forward_to_forward() {
        let r = link_from_optical();
        // Optical z (forward) is the link's x; optical x (right) the link's -y.
        assert!((r * Vector3::z() - Vector3::x()).norm() < 1e-12);
        assert!((r * Vector3::x() + Vector3::y()).norm() < 1e-12);
        assert!((r * Vector3::y() + Vector3::z()).norm() < 1e-12);
    }
}
