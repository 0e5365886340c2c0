//! The `backend: ros2` sections of a cell config: an arm under a ROS 2 driver (`/tf`,
//! `/joint_states`, a FollowJointTrajectory action) and a camera under a ROS 2 camera node
//! (`sensor_msgs/Image` or `CompressedImage` + `CameraInfo`). The DDS domain, the local
//! interfaces and every topic, frame and action name come from here; the defaults are those of
//! the UR ROS 2 driver (`ur_robot_driver`) and a usual camera node. Needs the `ros2` build
//! feature to open (docs/ros2-live.md); any build reads and checks it.

use std::net::IpAddr;

use serde::{Deserialize, Serialize};

use super::schema::ArmModel;
use handeye_core::setup::is_ur_base_link;
use handeye_robot::MAX_JOINTS;

/// Where on the ROS 2 graph handeye joins: shared by the arm and the camera.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Ros2Graph {
    /// The ROS_DOMAIN_ID, 0–232.
    #[serde(default)]
    pub domain_id: u16,
    /// Local addresses DDS may use (the robot network's; `127.0.0.1` for one machine); empty:
    /// every interface.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub interfaces: Vec<IpAddr>,
    /// How long to wait for the first message of each topic and for the action server, s.
    #[serde(default = "default_connect_timeout_s")]
    pub connect_timeout_s: f64,
    /// The ROS middleware the other nodes run: it decides how action calls (request/reply) are
    /// framed on the wire. `fastrtps` is ROS 2's default; `cyclonedds` when the robot's nodes run
    /// with `RMW_IMPLEMENTATION=rmw_cyclonedds_cpp`.
    #[serde(default)]
    pub rmw: Rmw,
}

/// The ROS middleware of the other nodes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Rmw {
    /// rmw_fastrtps_cpp (the default of Humble and Jazzy).
    #[default]
    Fastrtps,
    /// rmw_cyclonedds_cpp.
    Cyclonedds,
}

impl Default for Ros2Graph {
    fn default() -> Self {
        Ros2Graph {
            domain_id: 0,
            interfaces: Vec::new(),
            connect_timeout_s: default_connect_timeout_s(),
            rmw: Rmw::default(),
        }
    }
}

fn default_connect_timeout_s() -> f64 {
    10.0
}

/// `robot: {backend: ros2, ...}`: an arm under a ROS 2 driver.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Ros2Robot {
    /// The arm model whose kinematics plan the poses (a UR model; see `ArmModel`), or `none` for
    /// an arm handeye has no model of: it replays taught plans (joints with the flange pose
    /// taught there) and is calibrated hand-guided. Required: a ROS 2 arm may be any arm, and
    /// guessing a UR model for one that is not would plan with the wrong kinematics.
    #[serde(
        deserialize_with = "model_or_none",
        serialize_with = "write_model_or_none"
    )]
    pub model: Option<ArmModel>,
    /// Allowed range of each joint, `[min, max]` degrees, base joint first: one per name in
    /// `joint_names`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub joint_ranges_deg: Option<Vec<[f64; 2]>>,
    /// Domain, interfaces, timeouts.
    #[serde(default)]
    pub graph: Ros2Graph,
    /// Where each recorded flange pose comes from: `tf` (default), the driver's
    /// `base_frame` → `flange_frame` on /tf, checked against the joints; or `joints`, the
    /// forward kinematics of the arm's published model at the joints on /joint_states, for an
    /// arm whose TF is not to be trusted (a relay, a second chain under the driver's frame
    /// names, a driver that publishes another model): what the controller would report, so
    /// `solver.kinematics` and `solver.arm_model` correct it as any reported pose. Needs
    /// `model`.
    #[serde(default, skip_serializing_if = "FlangePose::is_tf")]
    pub flange_pose: FlangePose,
    /// The TF frame `T_base_flange` is measured in (the UR driver's `base`).
    #[serde(default = "default_base_frame")]
    pub base_frame: String,
    /// The TF frame of the flange (`tool0`).
    #[serde(default = "default_flange_frame")]
    pub flange_frame: String,
    /// The arm's joint names, base joint first, as `/joint_states` and the controller name them:
    /// six on a UR (the UR driver's names by default), seven on a Franka or a KUKA iiwa.
    #[serde(default = "default_joint_names")]
    pub joint_names: Vec<String>,
    /// The `sensor_msgs/JointState` topic.
    #[serde(default = "default_joint_states_topic")]
    pub joint_states_topic: String,
    /// The TF topic.
    #[serde(default = "default_tf_topic")]
    pub tf_topic: String,
    /// The static TF topic.
    #[serde(default = "default_tf_static_topic")]
    pub tf_static_topic: String,
    /// The `control_msgs/action/FollowJointTrajectory` action.
    #[serde(default = "default_action")]
    pub action: String,
    /// Freedrive from handeye (the console's button) through the UR driver's
    /// `freedrive_mode_controller`; absent: the person switches it on the arm.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub freedrive: Option<Ros2Freedrive>,
    /// 1-sigma error of the flange pose the driver reports, mm (default 0.03).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub repeatability_mm: Option<f64>,
    /// 1-sigma rotation error of the reported flange pose, degrees (default 0.003).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub repeatability_deg: Option<f64>,
}

/// `robot.flange_pose`: where a ROS 2 arm's recorded flange poses come from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum FlangePose {
    /// The driver's flange pose on /tf, checked against the joints.
    #[default]
    Tf,
    /// The forward kinematics of the arm's published model at the joints on /joint_states.
    Joints,
}

impl FlangePose {
    /// The default (not written back).
    pub fn is_tf(&self) -> bool {
        *self == FlangePose::Tf
    }
}

/// `robot.freedrive`: the UR driver's controllers that freedrive switches between.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Ros2Freedrive {
    /// The ROS 2 distribution of the controller manager: Humble's and Jazzy's ros2_control lay
    /// the controller switch out differently on the wire, so it is required.
    pub distro: RosDistro,
    /// The controller manager's node.
    #[serde(default = "default_controller_manager")]
    pub controller_manager: String,
    /// The freedrive controller (loaded inactive by the UR driver 2.5 or later).
    #[serde(default = "default_freedrive_controller")]
    pub controller: String,
    /// The controller behind `robot.action`, inactive while freedrive is on.
    #[serde(default = "default_motion_controller")]
    pub motion_controller: String,
}

/// A ROS 2 distribution whose ros2_control handeye speaks.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum RosDistro {
    /// Humble Hawksbill (ros2_control 2.x).
    Humble,
    /// Jazzy Jalisco (ros2_control 4.x).
    Jazzy,
}

fn default_controller_manager() -> String {
    "/controller_manager".into()
}
fn default_freedrive_controller() -> String {
    "freedrive_mode_controller".into()
}
fn default_motion_controller() -> String {
    "scaled_joint_trajectory_controller".into()
}

/// `model: ur10e` or `model: none`.
fn model_or_none<'de, D: serde::Deserializer<'de>>(d: D) -> Result<Option<ArmModel>, D::Error> {
    use serde::de::IntoDeserializer;
    let name = String::deserialize(d)?;
    if name == "none" {
        return Ok(None);
    }
    ArmModel::deserialize(name.as_str().into_deserializer())
        .map(Some)
        .map_err(|e: serde::de::value::Error| {
            serde::de::Error::custom(format!("{e}, or `none` for an arm with no UR model"))
        })
}

fn write_model_or_none<S: serde::Serializer>(
    model: &Option<ArmModel>,
    s: S,
) -> Result<S::Ok, S::Error> {
    s.serialize_str(model.map_or("none", ArmModel::name))
}

fn default_base_frame() -> String {
    "base".into()
}
fn default_flange_frame() -> String {
    "tool0".into()
}
/// The UR ROS 2 driver's joint names, base first: `robot.joint_names`' default.
pub const UR_DRIVER_JOINT_NAMES: [&str; 6] = [
    "shoulder_pan_joint",
    "shoulder_lift_joint",
    "elbow_joint",
    "wrist_1_joint",
    "wrist_2_joint",
    "wrist_3_joint",
];

fn default_joint_names() -> Vec<String> {
    UR_DRIVER_JOINT_NAMES.map(String::from).to_vec()
}
fn default_joint_states_topic() -> String {
    "/joint_states".into()
}
fn default_tf_topic() -> String {
    "/tf".into()
}
fn default_tf_static_topic() -> String {
    "/tf_static".into()
}
fn default_action() -> String {
    "/scaled_joint_trajectory_controller/follow_joint_trajectory".into()
}

/// `camera: {backend: ros2, ...}`: a camera under a ROS 2 camera node.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Ros2Camera {
    /// The image topic (`sensor_msgs/Image`, or `sensor_msgs/CompressedImage` with
    /// `compressed: true`).
    #[serde(default = "default_image_topic")]
    pub image_topic: String,
    /// The image topic carries `CompressedImage` (JPEG or PNG).
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub compressed: bool,
    /// The `sensor_msgs/CameraInfo` topic; its size must match the config's `intrinsics`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub camera_info_topic: Option<String>,
    /// Domain and interfaces when the arm is not on ROS 2 (otherwise the arm's are used).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub graph: Option<Ros2Graph>,
    /// How long to wait for a frame exposed after the arm settled, s.
    #[serde(default = "default_frame_timeout_s")]
    pub frame_timeout_s: f64,
}

fn default_image_topic() -> String {
    "/image_raw".into()
}
fn default_frame_timeout_s() -> f64 {
    5.0
}

/// A problem in a `ros2` section: the key (YAML path) and what is wrong with it.
pub(super) type Problem = (String, String);

fn name_problem(key: &str, name: &str) -> Option<Problem> {
    let ok = name.starts_with('/')
        && name.len() > 1
        && !name.ends_with('/')
        && !name.contains("//")
        && name.split('/').skip(1).all(|part| {
            part.chars().all(|c| c.is_ascii_alphanumeric() || c == '_')
                && !part.starts_with(|c: char| c.is_ascii_digit())
        });
    (!ok).then(|| {
        (
            key.to_string(),
            format!("{name:?} is not an absolute ROS 2 name: expected `/a/b` of letters, digits and `_`, no part starting with a digit"),
        )
    })
}

/// A controller's name: one ROS name part (letters, digits, `_`; not starting with a digit).
fn controller_problem(key: &str, name: &str) -> Option<Problem> {
    name_problem(key, &format!("/{name}")).map(|(key, _)| {
        (
            key,
            format!("{name:?}: expected a controller's name (letters, digits and _, not starting with a digit)"),
        )
    })
    .or_else(|| {
        name.contains('/').then(|| {
            (
                key.to_string(),
                format!("{name:?}: expected the controller's name alone, without a namespace"),
            )
        })
    })
}

pub(super) fn frame_problem(key: &str, frame: &str) -> Option<Problem> {
    let ok = !frame.is_empty()
        && !frame.starts_with('/')
        && frame
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '/');
    (!ok).then(|| {
        (
            key.to_string(),
            format!("{frame:?} is not a TF frame id: expected letters, digits, `_` and `/`, no leading `/`"),
        )
    })
}

fn graph_problem(key: &str, graph: &Ros2Graph) -> Option<Problem> {
    if graph.domain_id > 232 {
        return Some((
            format!("{key}.domain_id"),
            format!(
                "{} is not a ROS 2 domain id: expected 0..=232",
                graph.domain_id
            ),
        ));
    }
    let t = graph.connect_timeout_s;
    (!(t.is_finite() && t > 0.0 && t <= 600.0)).then(|| {
        (
            format!("{key}.connect_timeout_s"),
            format!("{t} s: expected a value in (0, 600] s"),
        )
    })
}

impl super::robot::RobotBackend for Ros2Robot {
    fn name(&self) -> &'static str {
        "ros2"
    }

    fn model(&self) -> Option<ArmModel> {
        self.model
    }

    fn given_joint_ranges_deg(&self) -> Option<&[[f64; 2]]> {
        self.joint_ranges_deg.as_deref()
    }

    fn has_flange_cable(&self) -> bool {
        true
    }

    fn repeatability(&self) -> (f64, f64) {
        (
            self.repeatability_mm.unwrap_or(0.03),
            self.repeatability_deg.unwrap_or(0.003),
        )
    }

    fn frames(&self) -> handeye_core::setup::RobotFrames {
        handeye_core::setup::RobotFrames {
            base: self.base_frame.clone(),
            flange: self.flange_frame.clone(),
        }
    }

    fn check(&self, v: &super::validate::Validator<'_>) -> Result<(), super::ConfigError> {
        if let Some((key, problem)) = self.problem() {
            return Err(v.inconsistent(&key, problem));
        }
        v.repeatability(self.repeatability_mm, self.repeatability_deg)
    }
}

impl Ros2Robot {
    /// A UR model's poses read in the driver's `base_link`: the model plans, and the nominal
    /// transforms and the workspace box are given, in the controller's `base` (`base_link` is
    /// it turned 180° about z), so the two would mix; handeye reads `base` and turns the answer
    /// at export instead.
    fn base_link_problem(&self) -> Option<Problem> {
        let model = self.model?;
        is_ur_base_link(&self.base_frame).then(|| {
            (
                "robot.base_frame".to_string(),
                format!(
                    "`{}` is the UR driver's base_link, the controller's `base` turned 180° about z; with `model: {}` the plan, `nominal` and `workspace` are in `base`: set `base_frame: {}` (the driver publishes both) and export or publish with `--base-frame {}` to get the answer in base_link",
                    self.base_frame,
                    model.name(),
                    self.base_frame.strip_suffix("_link").unwrap_or("base"),
                    self.base_frame
                ),
            )
        })
    }

    /// The names, frames and numbers checked (the first problem found).
    pub(super) fn problem(&self) -> Option<Problem> {
        graph_problem("robot.graph", &self.graph)
            .or_else(|| {
                (self.flange_pose == FlangePose::Joints && self.model.is_none()).then(|| {
                    (
                        "robot.flange_pose".to_string(),
                        "`joints` computes the flange pose through the arm's kinematics: give `model` (a UR model), or leave `flange_pose` out to read it on /tf".to_string(),
                    )
                })
            })
            .or_else(|| frame_problem("robot.base_frame", &self.base_frame))
            .or_else(|| self.base_link_problem())
            .or_else(|| frame_problem("robot.flange_frame", &self.flange_frame))
            .or_else(|| name_problem("robot.joint_states_topic", &self.joint_states_topic))
            .or_else(|| name_problem("robot.tf_topic", &self.tf_topic))
            .or_else(|| name_problem("robot.tf_static_topic", &self.tf_static_topic))
            .or_else(|| name_problem("robot.action", &self.action))
            .or_else(|| {
                let f = self.freedrive.as_ref()?;
                name_problem("robot.freedrive.controller_manager", &f.controller_manager)
                    .or_else(|| controller_problem("robot.freedrive.controller", &f.controller))
                    .or_else(|| {
                        controller_problem(
                            "robot.freedrive.motion_controller",
                            &f.motion_controller,
                        )
                    })
            })
            .or_else(|| {
                let n = self.joint_names.len();
                let expected = match self.model {
                    Some(model) => (n != 6).then(|| format!("six, the joints of a {}", model.name())),
                    None => (!(1..=MAX_JOINTS).contains(&n))
                        .then(|| format!("one per joint of the arm, base first (at most {MAX_JOINTS})")),
                };
                expected.map(|expected| {
                    (
                        "robot.joint_names".to_string(),
                        format!("{n} names: expected {expected}"),
                    )
                })
            })
            .or_else(|| {
                // A UR model brings its ranges; an arm of no known model must name its own, so
                // no taught joint is checked against a UR's.
                let n = self.joint_names.len();
                match &self.joint_ranges_deg {
                    None if self.model.is_none() => Some((
                        "robot.joint_ranges_deg".to_string(),
                        format!("missing: with `model: none` handeye knows no joint ranges of this arm; expected {n} `[min, max]` in degrees, one per name in robot.joint_names, from the arm's datasheet (narrower where cables or the cell need it)"),
                    )),
                    Some(ranges) if ranges.len() != n => Some((
                        "robot.joint_ranges_deg".to_string(),
                        format!("{} ranges: expected {n}, one `[min, max]` per name in robot.joint_names", ranges.len()),
                    )),
                    _ => None,
                }
            })
            .or_else(|| {
                let mut seen = std::collections::BTreeSet::new();
                self.joint_names.iter().enumerate().find_map(|(i, n)| {
                    (n.trim().is_empty() || !seen.insert(n)).then(|| {
                        (
                            format!("robot.joint_names[{i}]"),
                            format!("{n:?}: expected a joint name, each different"),
                        )
                    })
                })
            })
    }
}

impl super::camera::CameraBackend for Ros2Camera {
    fn name(&self) -> &'static str {
        "ros2"
    }

    fn check(
        &self,
        v: &super::validate::Validator<'_>,
        _cell_intrinsics: bool,
    ) -> Result<(), super::ConfigError> {
        match self.problem() {
            Some((key, problem)) => Err(v.inconsistent(&key, problem)),
            None => Ok(()),
        }
    }
}

impl Ros2Camera {
    /// The names and numbers checked (the first problem found).
    pub(super) fn problem(&self) -> Option<Problem> {
        let t = self.frame_timeout_s;
        name_problem("camera.image_topic", &self.image_topic)
            .or_else(|| {
                self.camera_info_topic
                    .as_deref()
                    .and_then(|n| name_problem("camera.camera_info_topic", n))
            })
            .or_else(|| {
                self.graph
                    .as_ref()
                    .and_then(|g| graph_problem("camera.graph", g))
            })
            .or_else(|| {
                (!(t.is_finite() && t > 0.0 && t <= 600.0)).then(|| {
                    (
                        "camera.frame_timeout_s".to_string(),
                        format!("{t} s: expected a value in (0, 600] s"),
                    )
                })
            })
    }
}

#[cfg(test)]
mod tests {
    use super::super::schema::{CameraConfig, RobotConfig};
    use super::*;

    #[test]
    fn the_ur_driver_defaults_and_the_checks() {
        let robot: RobotConfig = serde_yaml_ng::from_str("backend: ros2\nmodel: ur5e\n").unwrap();
        let RobotConfig::Ros2(r) = robot else {
            panic!("not ros2")
        };
        assert_eq!(
            r.action,
            "/scaled_joint_trajectory_controller/follow_joint_trajectory"
        );
        assert_eq!(
            (r.base_frame.as_str(), r.flange_frame.as_str()),
            ("base", "tool0")
        );
        assert_eq!(r.graph.rmw, Rmw::Fastrtps);
        assert!(r.problem().is_none());

        // No model: `none`; it must name its joint ranges.
        let RobotConfig::Ros2(r) = serde_yaml_ng::from_str("backend: ros2\nmodel: none\n").unwrap()
        else {
            panic!("not ros2")
        };
        assert_eq!(r.model, None);
        assert_eq!(r.problem().unwrap().0, "robot.joint_ranges_deg");
        // Absent: refused, not guessed.
        let absent = serde_yaml_ng::from_str::<RobotConfig>("backend: ros2\n");
        let absent = absent.unwrap_err().to_string();
        assert!(absent.contains("model"), "{absent}");
        let typo = serde_yaml_ng::from_str::<RobotConfig>("backend: ros2\nmodel: ur6e\n");
        let typo = typo.unwrap_err().to_string();
        assert!(typo.contains("ur6e") && typo.contains("`none`"), "{typo}");

        let unknown = serde_yaml_ng::from_str::<RobotConfig>("backend: ros2\nhost: 1.2.3.4\n");
        assert!(unknown.unwrap_err().to_string().contains("host"));

        let bad: RobotConfig =
            serde_yaml_ng::from_str("backend: ros2\nmodel: ur5e\naction: relative/name\n").unwrap();
        let RobotConfig::Ros2(r) = bad else { panic!() };
        let (key, problem) = r.problem().unwrap();
        assert_eq!(key, "robot.action");
        assert!(problem.contains("absolute"), "{problem}");

        let domain: RobotConfig =
            serde_yaml_ng::from_str("backend: ros2\nmodel: ur5e\ngraph: {domain_id: 300}\n")
                .unwrap();
        let RobotConfig::Ros2(r) = domain else {
            panic!()
        };
        assert_eq!(r.problem().unwrap().0, "robot.graph.domain_id");

        let camera: CameraConfig =
            serde_yaml_ng::from_str("backend: ros2\nimage_topic: /cam/image_raw\n").unwrap();
        let CameraConfig::Ros2(c) = camera else {
            panic!()
        };
        assert!(c.problem().is_none() && !c.compressed);
        let camera: CameraConfig =
            serde_yaml_ng::from_str("backend: ros2\nframe_timeout_s: 0\n").unwrap();
        let CameraConfig::Ros2(c) = camera else {
            panic!()
        };
        assert_eq!(c.problem().unwrap().0, "camera.frame_timeout_s");
    }

    /// The ROS 2 arm of `yaml` (after `backend: ros2`) and its first problem.
    fn arm_problem(yaml: &str) -> Option<Problem> {
        let robot: RobotConfig =
            serde_yaml_ng::from_str(&format!("backend: ros2\n{yaml}")).unwrap();
        let RobotConfig::Ros2(r) = robot else {
            panic!("not ros2")
        };
        r.problem()
    }

    #[test]
    fn freedrive_names_its_distribution_and_controllers() {
        let robot: RobotConfig =
            serde_yaml_ng::from_str("backend: ros2\nmodel: ur5e\nfreedrive: {distro: humble}\n")
                .unwrap();
        let RobotConfig::Ros2(r) = robot else {
            panic!("not ros2")
        };
        let f = r.freedrive.as_ref().unwrap();
        assert_eq!(f.distro, RosDistro::Humble);
        assert_eq!(f.controller, "freedrive_mode_controller");
        assert_eq!(f.motion_controller, "scaled_joint_trajectory_controller");
        assert_eq!(f.controller_manager, "/controller_manager");
        assert!(r.problem().is_none());
        // The distribution is required: the two lay the switch out differently.
        let missing =
            serde_yaml_ng::from_str::<RobotConfig>("backend: ros2\nmodel: ur5e\nfreedrive: {}\n");
        assert!(missing.unwrap_err().to_string().contains("distro"));
        let iron = serde_yaml_ng::from_str::<RobotConfig>(
            "backend: ros2\nmodel: ur5e\nfreedrive: {distro: iron}\n",
        );
        assert!(iron.unwrap_err().to_string().contains("iron"));
        let (key, problem) = arm_problem(
            "model: ur5e\nfreedrive: {distro: jazzy, controller: ur/freedrive_mode_controller}\n",
        )
        .unwrap();
        assert_eq!(key, "robot.freedrive.controller");
        assert!(problem.contains("without a namespace"), "{problem}");
    }

    #[test]
    fn joint_names_and_ranges_count_the_arms_joints() {
        let seven = "[j1, j2, j3, j4, j5, j6, j7]";
        let seven_ranges = "[[-166, 166], [-101, 101], [-166, 166], [-176, -4], [-166, 166], [-1, 215], [-166, 166]]";
        // A seven-joint arm of no model: seven names, seven ranges.
        let franka =
            format!("model: none\njoint_names: {seven}\njoint_ranges_deg: {seven_ranges}\n");
        assert_eq!(arm_problem(&franka), None);
        // Six ranges for seven names: the count is said.
        let short = franka.replace("[-1, 215], ", "");
        let (key, problem) = arm_problem(&short).unwrap();
        assert_eq!(key, "robot.joint_ranges_deg");
        assert!(problem.starts_with("6 ranges: expected 7"), "{problem}");
        // A UR has six joints, whatever the names say.
        let (key, problem) = arm_problem(&format!("model: ur5e\njoint_names: {seven}\n")).unwrap();
        assert_eq!(key, "robot.joint_names");
        assert_eq!(problem, "7 names: expected six, the joints of a ur5e");
        // More than seven: refused.
        let eight = "model: none\njoint_names: [a, b, c, d, e, f, g, h]\njoint_ranges_deg: []\n";
        assert_eq!(arm_problem(eight).unwrap().0, "robot.joint_names");
    }
}
