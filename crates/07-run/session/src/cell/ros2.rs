//! Opening the `backend: ros2` arm and camera (docs/ros2-live.md): one ROS 2 node for both, on
//! the domain and interfaces the config names; the camera alone takes its own `graph`. A
//! several-camera cell's other ROS 2 cameras subscribe on the same node ([`Ros2Node`]). Built
//! with the `ros2` feature; without it, a clear error says the build lacks it.

use handeye_camera::Camera;
use handeye_core::camera_model::CameraModel;
use handeye_robot::kinematics::UrModel;

use super::CellError;
use handeye_config::CellConfig;

/// The ROS 2 node a cell's arm was opened on: its other cameras subscribe on it.
#[cfg(feature = "ros2")]
pub type Ros2Node = handeye_ros2::link::Ros2Link;

/// Without the `ros2` feature there is no node (nothing makes one: `open_arm` refuses).
#[cfg(not(feature = "ros2"))]
#[derive(Debug, Clone)]
pub struct Ros2Node;

/// Opens the ROS 2 arm and camera of `config` (both `backend: ros2`).
#[cfg(not(feature = "ros2"))]
pub fn open_arm(
    _: &CellConfig,
    _: Option<UrModel>,
) -> Result<(Box<dyn handeye_robot::Robot>, Ros2Node), CellError> {
    Err(no_ros2())
}

/// Opens a ROS 2 camera on the node of the cell's arm.
#[cfg(not(feature = "ros2"))]
pub fn open_camera(
    _: &CellConfig,
    _: &Ros2Node,
    _: CameraModel,
) -> Result<Box<dyn Camera>, CellError> {
    Err(no_ros2())
}

#[cfg(not(feature = "ros2"))]
fn no_ros2() -> CellError {
    CellError::Backend(
        "backend `ros2` needs a handeye build with the `ros2` feature: `cargo build --release --features ros2` (no ROS installation needed)".into(),
    )
}

/// Opens the ROS 2 arm of `config` (`robot: {backend: ros2}`), before any camera: its joint
/// states and flange pose must be heard before anything else; the node comes back for the
/// cell's cameras ([`open_camera`]).
#[cfg(feature = "ros2")]
pub fn open_arm(
    config: &CellConfig,
    arm: Option<UrModel>,
) -> Result<(Box<dyn handeye_robot::Robot>, Ros2Node), CellError> {
    use std::time::Duration;

    use handeye_ros2::arm::{ArmOptions, Framing, Ros2Arm};
    use handeye_ros2::link::{LinkOptions, Ros2Link};

    use handeye_config::ros2::{Rmw, RosDistro};
    use handeye_config::RobotConfig;
    use handeye_ros2::freedrive::{Distro, FreedriveOptions};

    let RobotConfig::Ros2(r) = &config.robot else {
        return Err(CellError::Backend(
            "the ROS 2 cell needs `robot: {backend: ros2}` and `camera: {backend: ros2}`".into(),
        ));
    };
    let link = Ros2Link::open(LinkOptions {
        domain_id: r.graph.domain_id,
        interfaces: r.graph.interfaces.clone(),
        node_name: "handeye".into(),
    })
    .map_err(|e| CellError::Backend(e.to_string()))?;
    let timeout = Duration::from_secs_f64(r.graph.connect_timeout_s);
    let robot = Ros2Arm::open(
        &link,
        ArmOptions {
            base_frame: r.base_frame.clone(),
            flange_frame: r.flange_frame.clone(),
            joint_names: r.joint_names.clone(),
            joint_states_topic: r.joint_states_topic.clone(),
            tf_topic: r.tf_topic.clone(),
            tf_static_topic: r.tf_static_topic.clone(),
            action: r.action.clone(),
            timeout,
            framing: match r.graph.rmw {
                Rmw::Fastrtps => Framing::FastRtps,
                Rmw::Cyclonedds => Framing::Cyclone,
            },
            kinematics: arm,
            flange_from_joints: r.flange_pose == handeye_config::ros2::FlangePose::Joints,
            freedrive: r.freedrive.as_ref().map(|f| FreedriveOptions {
                controller_manager: f.controller_manager.clone(),
                freedrive_controller: f.controller.clone(),
                motion_controller: f.motion_controller.clone(),
                distro: match f.distro {
                    RosDistro::Humble => Distro::Humble,
                    RosDistro::Jazzy => Distro::Jazzy,
                },
                timeout,
            }),
        },
    )
    .map_err(|e| CellError::Robot(Box::new(e)))?;
    Ok((Box::new(robot), link))
}

/// Opens the ROS 2 camera of `config` (`camera: {backend: ros2}`) on `link`.
#[cfg(feature = "ros2")]
pub fn open_camera(
    config: &CellConfig,
    link: &Ros2Node,
    model: CameraModel,
) -> Result<Box<dyn Camera>, CellError> {
    use std::time::Duration;

    use handeye_ros2::camera::{CameraOptions, Ros2Camera};

    use handeye_config::CameraConfig;

    let CameraConfig::Ros2(c) = &config.camera().backend else {
        return Err(CellError::Backend(
            "the ROS 2 cell needs `robot: {backend: ros2}` and `camera: {backend: ros2}`".into(),
        ));
    };
    let camera = Ros2Camera::open(
        link,
        CameraOptions {
            image_topic: c.image_topic.clone(),
            compressed: c.compressed,
            camera_info_topic: c.camera_info_topic.clone(),
            timeout: Duration::from_secs_f64(c.frame_timeout_s),
            model,
        },
    )
    .map_err(|e| CellError::Backend(format!("the ROS 2 camera: {e}")))?;
    Ok(Box::new(camera))
}

/// What a ROS 2 cell's graph holds that its session keeps, as notes to say: the calibration the
/// camera driver publishes (`camera_info_from_topic.yaml`: the cell's intrinsics when the config
/// gives no file, which a replay uses; else what the solve compares the file with) and the
/// static transforms on `/tf_static` (`tf_static.yaml`: the camera driver's chain, the robot
/// driver's static frames).
#[cfg(feature = "ros2")]
pub fn record_graph(
    cell: &super::PreparedCell,
    node: &Ros2Node,
    folder: &handeye_records::SessionFolder,
) -> Vec<String> {
    use handeye_config::{CameraConfig, RobotConfig};
    use handeye_records::tf_static::{StaticTransformsFile, TF_STATIC_FILE};

    let mut notes = Vec::new();
    let camera = cell.camera();
    if let CameraConfig::Ros2(c) = &cell.config.camera().backend {
        if let Some(topic) = &c.camera_info_topic {
            // Without a file the cell's intrinsics are the driver's, read when it was prepared.
            let model = match cell.config.camera().intrinsics {
                None => Ok(Some(camera.camera_model)),
                Some(_) => read_camera_info(node, topic, c.frame_timeout_s),
            };
            let file = folder.root().join(super::INTRINSICS_FROM_TOPIC_FILE);
            notes.push(match model {
                Ok(Some(model)) => match model.save_camera_info(&file) {
                    Ok(()) => format!(
                        "the camera driver's calibration on {topic} kept in {}",
                        super::INTRINSICS_FROM_TOPIC_FILE
                    ),
                    Err(e) => format!("the calibration on {topic} was not kept: {e}"),
                },
                Ok(None) => {
                    format!("no CameraInfo on {topic}: the driver's calibration was not kept")
                }
                Err(e) => format!("the calibration on {topic} was not kept: {e}"),
            });
        }
    }
    if let RobotConfig::Ros2(r) = &cell.config.robot {
        if r.flange_pose == handeye_config::ros2::FlangePose::Joints {
            notes.push(format!(
                "the flange poses are the {} model's forward kinematics at the joints on {} (robot.flange_pose: joints): {} is not read for them",
                r.model.map_or("arm's", |m| m.name()),
                r.joint_states_topic,
                r.tf_topic
            ));
        }
        // Latched messages reach a late joiner once discovery has matched it: a second or so.
        let heard = handeye_ros2::tf_static::hear_static(
            node,
            &r.tf_static_topic,
            std::time::Duration::from_secs_f64(1.5),
        )
        .map_err(|e| e.to_string())
        .map(|tree| StaticTransformsFile::from_tree(&r.tf_static_topic, &tree))
        .and_then(|file| {
            file.save(&folder.root().join(TF_STATIC_FILE))
                .map(|()| file.transforms.len())
                .map_err(|e| e.to_string())
        });
        match heard {
            Ok(0) => {}
            Ok(n) => notes.push(format!(
                "{n} static transforms heard on the graph, kept in {TF_STATIC_FILE}"
            )),
            Err(e) => notes.push(format!("the graph's static transforms were not kept: {e}")),
        }
    }
    notes
}

/// Without ROS 2 in the build there is no graph (and no node to have opened).
#[cfg(not(feature = "ros2"))]
pub fn record_graph(
    _cell: &super::PreparedCell,
    _node: &Ros2Node,
    _folder: &handeye_records::SessionFolder,
) -> Vec<String> {
    Vec::new()
}

/// The intrinsics a ROS 2 camera driver publishes on `topic` (its factory calibration, as a
/// RealSense keeps it): one `sensor_msgs/CameraInfo` heard on the cell's graph within the
/// camera's frame timeout, for a config that gives no `intrinsics:` file.
#[cfg(feature = "ros2")]
pub fn intrinsics_from_topic(
    config: &CellConfig,
    topic: &str,
    timeout_s: f64,
) -> Result<CameraModel, CellError> {
    use handeye_ros2::link::{LinkOptions, Ros2Link};

    use handeye_config::RobotConfig;

    let RobotConfig::Ros2(r) = &config.robot else {
        return Err(CellError::Backend(
            "intrinsics from the camera_info topic need `robot: {backend: ros2}`".into(),
        ));
    };
    let link = Ros2Link::open(LinkOptions {
        domain_id: r.graph.domain_id,
        interfaces: r.graph.interfaces.clone(),
        node_name: "handeye_intrinsics".into(),
    })
    .map_err(|e| CellError::Backend(e.to_string()))?;
    read_camera_info(&link, topic, timeout_s)?.ok_or_else(|| {
        CellError::Backend(format!(
            "intrinsics: none given, so they are read from the camera driver's {topic}, and no CameraInfo arrived there within {timeout_s} s on domain {}: start the camera driver (or check camera.camera_info_topic), or give `intrinsics:` (a camera_info YAML file, `ros2 topic echo --once {topic}` prints one)",
            r.graph.domain_id
        ))
    })
}

/// The calibration in the first `CameraInfo` heard on `topic` within `timeout_s` (`None`: none
/// heard).
#[cfg(feature = "ros2")]
pub fn read_camera_info(
    link: &Ros2Node,
    topic: &str,
    timeout_s: f64,
) -> Result<Option<CameraModel>, CellError> {
    use std::time::{Duration, Instant};

    use handeye_ros2::link::sensor_data_qos;
    use handeye_ros2::msg::CameraInfo;

    let reader = link
        .subscribe::<CameraInfo>(topic, sensor_data_qos())
        .map_err(|e| CellError::Backend(e.to_string()))?;
    let end = Instant::now() + Duration::from_secs_f64(timeout_s);
    while Instant::now() < end {
        match reader.take() {
            Ok(Some((info, _))) => {
                return info.camera_model().map(Some).map_err(|e| {
                    CellError::Backend(format!(
                        "the CameraInfo on {topic} is not a calibration: {e}; give `intrinsics:` (a camera_info YAML file)"
                    ))
                })
            }
            Ok(None) | Err(_) => std::thread::sleep(Duration::from_millis(20)),
        }
    }
    Ok(None)
}

/// Without ROS 2 in the build no topic can be read.
#[cfg(not(feature = "ros2"))]
pub fn read_camera_info(
    _link: &Ros2Node,
    _topic: &str,
    _timeout_s: f64,
) -> Result<Option<CameraModel>, CellError> {
    Err(no_ros2())
}

/// Without ROS 2 in the build no topic can be read.
#[cfg(not(feature = "ros2"))]
pub fn intrinsics_from_topic(
    _config: &CellConfig,
    _topic: &str,
    _timeout_s: f64,
) -> Result<CameraModel, CellError> {
    Err(no_ros2())
}
