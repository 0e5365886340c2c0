//! `export --format ros2-launch`: the launch file runs as written. Python executes it against
//! stand-ins of `launch` and `launch_ros` that record each node (ROS itself is not installed
//! here); the recorded `static_transform_publisher` arguments must be the result's transforms,
//! and with `--camera-link … --optical-rotation-only` the link's transform composed with the
//! optical rotation must be the camera's.

use std::process::Command;

use nalgebra::{Quaternion, Translation3, UnitQuaternion};

use handeye_core::geometry::Pose;
use handeye_formats::export::named_transforms;
use handeye_formats::ros2_launch::link_from_optical;
use handeye_formats::FrameIds;
use handeye_records::result::ResultFile;

use crate::util::{self, handeye, pose_error_mm_deg, repo};

const RUNNER: &str = r#"
import json, sys, types
nodes = []
launch = types.ModuleType("launch")
launch.LaunchDescription = lambda actions: actions
ros = types.ModuleType("launch_ros")
actions = types.ModuleType("launch_ros.actions")
def Node(**kw):
    nodes.append(kw)
    return kw
actions.Node = Node
ros.actions = actions
sys.modules.update({"launch": launch, "launch_ros": ros, "launch_ros.actions": actions})
scope = {}
exec(compile(open(sys.argv[1]).read(), sys.argv[1], "exec"), scope)
scope["generate_launch_description"]()
print(json.dumps(nodes))
"#;

pub(crate) fn launched(file: &std::path::Path) -> Option<Vec<serde_json::Value>> {
    let out = match Command::new("python3")
        .args(["-c", RUNNER])
        .arg(file)
        .output()
    {
        Ok(out) => out,
        Err(_) => {
            util::skip("python3 is absent (it runs the exported launch file)");
            return None;
        }
    };
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    Some(serde_json::from_slice(&out.stdout).unwrap())
}

/// `(parent, child, T_parent_child)` of one recorded node.
pub(crate) fn node_transform(node: &serde_json::Value) -> (String, String, Pose) {
    assert_eq!(node["package"], "tf2_ros");
    assert_eq!(node["executable"], "static_transform_publisher");
    let args: Vec<String> = node["arguments"]
        .as_array()
        .unwrap()
        .iter()
        .map(|a| a.as_str().unwrap().to_string())
        .collect();
    let get = |flag: &str| {
        let i = args.iter().position(|a| a == flag).unwrap();
        args[i + 1].clone()
    };
    let f = |flag: &str| get(flag).parse::<f64>().unwrap();
    let pose = Pose::from_parts(
        Translation3::new(f("--x"), f("--y"), f("--z")),
        UnitQuaternion::from_quaternion(Quaternion::new(
            f("--qw"),
            f("--qx"),
            f("--qy"),
            f("--qz"),
        )),
    );
    (get("--frame-id"), get("--child-frame-id"), pose)
}

#[test]
fn the_launch_file_runs_and_publishes_the_result() {
    let dir = tempfile::tempdir().unwrap();
    let result = repo().join("tests/fuzz-corpus/result/result.yaml");
    let file = dir.path().join("handeye_calibration.launch.py");
    let out = handeye()
        .args(["export", "--format", "ros2-launch", "-o"])
        .arg(&file)
        .arg(&result)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let Some(nodes) = launched(&file) else { return };
    let ids = FrameIds {
        base: "base".into(),
        flange: "tool0".into(),
        camera: "camera_optical_frame".into(),
        target: "calibration_target".into(),
        poses_in: "base".into(),
    };
    let want = named_transforms(&ResultFile::load_mounts(&result).unwrap(), &ids);
    assert_eq!(nodes.len(), 2);
    for (node, w) in nodes.iter().zip(&want) {
        let (parent, child, pose) = node_transform(node);
        assert_eq!(
            (parent.as_str(), child.as_str()),
            (w.parent.as_str(), w.child.as_str())
        );
        let (mm, deg) = pose_error_mm_deg(&pose, &w.parent_from_child);
        assert!(mm < 1e-9 && deg < 1e-9, "{}: {mm} mm {deg}°", w.key);
    }

    // Hung from the camera's mounting link with the chain assumed (the form of earlier versions,
    // one flag away; the chain read from the graph is `ros2_live::camera_chain`): link ∘ optical
    // rotation = the calibrated camera.
    let linked = dir.path().join("linked.launch.py");
    let out = handeye()
        .args([
            "export",
            "--format",
            "ros2-launch",
            "--camera-link",
            "camera_link",
            "--optical-rotation-only",
            "-o",
        ])
        .arg(&linked)
        .arg(&result)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let nodes = launched(&linked).unwrap();
    let (parent, child, flange_from_link) = node_transform(&nodes[0]);
    assert_eq!((parent.as_str(), child.as_str()), ("tool0", "camera_link"));
    let (mm, deg) = pose_error_mm_deg(
        &(flange_from_link * link_from_optical()),
        &want[0].parent_from_child,
    );
    assert!(mm < 1e-9 && deg < 1e-9, "{mm} mm {deg}°");
}

#[test]
fn camera_link_needs_the_launch_format() {
    let out = handeye()
        .args(["export", "--format", "ros2", "--camera-link", "camera_link"])
        .arg(repo().join("tests/fuzz-corpus/result/result.yaml"))
        .output()
        .unwrap();
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("--camera-link applies to --format ros2-launch only"),
        "{err}"
    );
}

/// The RealSense-style chain `camera_link → camera_color_frame → camera_color_optical_frame`
/// (the colour imager 32 mm to the side, turned 0.4° about z) as `tf_static.yaml` records it.
pub(crate) fn realsense_chain() -> (handeye_records::tf_static::StaticTransformsFile, Pose) {
    use handeye_records::tf_static::{HeardTransform, StaticTransformsFile};
    let half = 0.4_f64.to_radians() / 2.0;
    let link_from_color = Pose::from_parts(
        Translation3::new(0.0, 0.032, 0.0),
        UnitQuaternion::from_quaternion(Quaternion::new(half.cos(), 0.0, 0.0, half.sin())),
    );
    let color_from_optical = Pose::from_parts(
        Translation3::identity(),
        UnitQuaternion::from_quaternion(Quaternion::new(0.5, -0.5, 0.5, -0.5)),
    );
    let edge = |parent: &str, child: &str, pose: Pose| HeardTransform {
        parent: parent.into(),
        child: child.into(),
        pose,
    };
    let file = StaticTransformsFile {
        topic: "/tf_static".into(),
        transforms: vec![
            edge("camera_link", "camera_color_frame", link_from_color),
            edge(
                "camera_color_frame",
                "camera_color_optical_frame",
                color_from_optical,
            ),
        ],
    };
    (file, link_from_color * color_from_optical)
}

#[test]
fn the_launch_file_hangs_the_camera_from_the_chain_recorded_in_the_session() {
    let dir = tempfile::tempdir().unwrap();
    // A session of a ROS 2 run: its result and the graph's static transforms it recorded.
    let session = dir.path().join("session");
    std::fs::create_dir(&session).unwrap();
    let result = session.join("result.yaml");
    std::fs::copy(repo().join("tests/fuzz-corpus/result/result.yaml"), &result).unwrap();
    let (recorded, link_from_optical) = realsense_chain();
    recorded.save(&session.join("tf_static.yaml")).unwrap();
    let want = ResultFile::load_mounts(&result).unwrap().camera_mount;
    let elsewhere = dir.path().join("chain.yaml");
    recorded.save(&elsewhere).unwrap();
    // The session's own record (no graph is read: its domain stays empty), then --tf-from a file.
    for extra in [
        vec![],
        vec!["--tf-from".to_string(), elsewhere.display().to_string()],
    ] {
        let launch = dir.path().join("cam.launch.py");
        let out = handeye()
            .args([
                "export",
                "--format",
                "ros2-launch",
                "--camera-link",
                "camera_link",
            ])
            .args(["--camera-frame", "camera_color_optical_frame"])
            .args([
                "--domain-id",
                &util::ros_domain().to_string(),
                "--interface",
                "127.0.0.1",
                "--tf-wait",
                "0",
            ])
            .args(&extra)
            .arg("-o")
            .arg(&launch)
            .arg(&result)
            .output()
            .unwrap();
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        let Some(nodes) = launched(&launch) else {
            return;
        };
        let (parent, child, flange_from_link) = node_transform(&nodes[0]);
        assert_eq!((parent.as_str(), child.as_str()), ("tool0", "camera_link"));
        let composed = flange_from_link * link_from_optical;
        let metres = (composed.translation.vector - want.translation.vector).norm();
        let (_, deg) = pose_error_mm_deg(&composed, &want);
        assert!(metres < 1e-6 && deg < 1e-6, "{extra:?}: {metres} m, {deg}°");
    }
    // A chain without the link is refused, naming what the record holds.
    let out = handeye()
        .args([
            "export",
            "--format",
            "ros2-launch",
            "--camera-link",
            "realsense_link",
        ])
        .args([
            "--camera-frame",
            "camera_color_optical_frame",
            "--tf-wait",
            "0",
        ])
        .arg(&result)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "{err}");
    assert!(
        err.contains("camera_color_optical_frame's chain")
            && err.contains("camera_link → camera_color_frame → camera_color_optical_frame, without realsense_link"),
        "{err}"
    );
}
