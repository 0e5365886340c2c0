//! Live ROS 2 (`--features ros2`) against an independent peer: Eclipse Cyclone DDS from PyPI
//! (`cyclonedds`) running `scripts/ros2-peer.py`, whose message types are written from the ROS 2
//! `.msg` definitions on its own (`scripts/ros2_peer/msgs.py`); `fastdds.rs` runs the same kind of
//! checks against eProsima Fast DDS (a C++ peer, `scripts/fastdds_peer`; what it needs is in that
//! module's doc). Both sides keep to the loopback interface (handeye `--interface 127.0.0.1`, the
//! peer `--loopback`: unicast discovery, no multicast), each test on a domain id of its own.
//!
//! Needs python3 (skips with a printed reason without it); `cyclonedds`, `numpy`, `pyyaml` and
//! `pillow` go into a venv under CARGO_TARGET_TMPDIR on first use (scripts/test.sh does the same for CI).

mod camera_chain;
mod cell;
mod console;
mod fastdds;
mod freedrive;
mod idle;
mod oversized;
mod publish;
mod taught;

use std::path::PathBuf;
use std::process::Command;
use std::sync::OnceLock;
use std::time::Duration;

use handeye_config::ros2::UR_DRIVER_JOINT_NAMES;
use handeye_core::camera_model::CameraModel;
use handeye_ros2::arm::{ArmOptions, Framing, Ros2Arm};
use handeye_ros2::camera::{CameraOptions, Ros2Camera};
use handeye_ros2::freedrive::FreedriveOptions;
use handeye_ros2::link::{LinkOptions, Ros2Link};

use crate::util;

/// The venv's python with cyclonedds, or `None` (printed) without python3.
pub(crate) fn python() -> Option<PathBuf> {
    static PYTHON: OnceLock<Option<PathBuf>> = OnceLock::new();
    PYTHON
        .get_or_init(|| {
            util::venv_python(
                "ros2-venv",
                "cyclonedds, numpy, yaml, PIL",
                &["cyclonedds", "numpy", "pyyaml", "pillow"],
                "the ROS 2 peer is Cyclone DDS's Python binding",
            )
        })
        .clone()
}

/// `scripts/ros2-peer.py` on `domain`, loopback only.
pub(crate) fn peer(python: &PathBuf, domain: u16) -> Command {
    let mut c = Command::new(python);
    c.arg(util::repo().join("scripts/ros2-peer.py")).args([
        "--domain",
        &domain.to_string(),
        "--loopback",
    ]);
    c
}

/// The simulated cell's camera (`configs/cameras/sim-1280x720.yaml`).
pub(crate) fn sim_camera_model() -> CameraModel {
    CameraModel::load(&util::repo().join("configs/cameras/sim-1280x720.yaml")).unwrap()
}

/// handeye's ROS 2 camera on `link` reading `/image_raw` and `/camera_info` of the simulated
/// cell's camera.
pub(crate) fn open_sim_camera(link: &Ros2Link) -> Ros2Camera {
    Ros2Camera::open(
        link,
        CameraOptions {
            image_topic: "/image_raw".into(),
            compressed: false,
            camera_info_topic: Some("/camera_info".into()),
            timeout: Duration::from_secs(10),
            model: sim_camera_model(),
        },
    )
    .unwrap()
}

/// handeye's ROS 2 node on the peer's `domain` (loopback), named `node`.
pub(crate) fn loopback_link(domain: u16, node: &str) -> Ros2Link {
    Ros2Link::open(LinkOptions {
        domain_id: domain,
        interfaces: vec![std::net::Ipv4Addr::LOCALHOST.into()],
        node_name: node.into(),
    })
    .unwrap()
}

/// handeye's arm on `link` as the peer's simulated UR is named (the UR driver's joints, frames
/// and action; no kinematics), switching freedrive with `freedrive`.
pub(crate) fn open_ur_arm(link: &Ros2Link, freedrive: Option<FreedriveOptions>) -> Ros2Arm {
    Ros2Arm::open(
        link,
        ArmOptions {
            base_frame: "base".into(),
            flange_frame: "tool0".into(),
            joint_names: UR_DRIVER_JOINT_NAMES.map(String::from).to_vec(),
            joint_states_topic: "/joint_states".into(),
            tf_topic: "/tf".into(),
            tf_static_topic: "/tf_static".into(),
            action: "/scaled_joint_trajectory_controller/follow_joint_trajectory".into(),
            timeout: Duration::from_secs(10),
            framing: Framing::Cyclone,
            kinematics: None,
            flange_from_joints: false,
            freedrive,
        },
    )
    .unwrap()
}
