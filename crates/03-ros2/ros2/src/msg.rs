//! The ROS 2 messages handeye reads and writes on the wire, as serde structs whose field order is
//! the `.msg` definition's (CDR serialises fields in order, with no names): builtin_interfaces,
//! std_msgs/Header, geometry_msgs transforms, tf2_msgs/TFMessage, sensor_msgs (JointState, Image,
//! CompressedImage, CameraInfo), trajectory_msgs and control_msgs/FollowJointTrajectory,
//! std_msgs/Bool and controller_manager_msgs/SwitchController (freedrive on a UR arm).
//!
//! The DDS type name of each is `pkg::msg::dds_::Type_` ([`RosType`]), the topic `rt/<name>`;
//! ros2-client adds both. Conversions to handeye's types sit beside the structs: a
//! [`Transform`] is `T_parent_child` of its [`TransformStamped`] (header frame = parent, child
//! frame = child), metres, unit quaternion (x, y, z, w on the wire).

use std::time::{Duration as StdDuration, SystemTime, UNIX_EPOCH};

use nalgebra::{Quaternion as NaQuaternion, Translation3, UnitQuaternion};
use serde::{Deserialize, Serialize};

use handeye_core::camera_model::{CameraModel, Distortion};
use handeye_core::geometry::Pose;

/// A ROS 2 interface's package and name, for the DDS type name.
pub trait RosType {
    /// The package, e.g. `tf2_msgs`.
    const PACKAGE: &'static str;
    /// The type, e.g. `TFMessage`.
    const NAME: &'static str;

    /// The ROS 2 type name, e.g. `tf2_msgs/msg/TFMessage` (as a bag's topic list names it).
    fn type_name() -> String {
        format!("{}/msg/{}", Self::PACKAGE, Self::NAME)
    }
}

/// A `uint8[]` field (pixels, compressed files) as one block on the wire: CDR's `sequence<octet>`
/// is a `u32` length and the bytes, the same as a sequence of `u8`, but read and written whole.
mod octets {
    use serde::de::{Error, SeqAccess, Visitor};
    use serde::{Deserializer, Serializer};

    pub(super) fn serialize<S: Serializer, B: AsRef<[u8]>>(
        bytes: &B,
        serializer: S,
    ) -> Result<S::Ok, S::Error> {
        serializer.serialize_bytes(bytes.as_ref())
    }

    /// A container of a `uint8[]` field: owned (`Vec<u8>`, a copy of the message's bytes) or
    /// lent (`&[u8]`, the bytes where they lie in the message being decoded, no copy).
    pub trait Octets<'de>: Sized {
        /// Reads the field.
        fn deserialize<D: Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error>;
    }

    impl<'de> Octets<'de> for Vec<u8> {
        fn deserialize<D: Deserializer<'de>>(deserializer: D) -> Result<Vec<u8>, D::Error> {
            struct Owned;
            impl<'de> Visitor<'de> for Owned {
                type Value = Vec<u8>;
                fn expecting(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
                    f.write_str("a byte sequence")
                }
                fn visit_bytes<E: Error>(self, v: &[u8]) -> Result<Vec<u8>, E> {
                    Ok(v.to_vec())
                }
                fn visit_byte_buf<E: Error>(self, v: Vec<u8>) -> Result<Vec<u8>, E> {
                    Ok(v)
                }
                fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<Vec<u8>, A::Error> {
                    let mut out = Vec::new();
                    while let Some(b) = seq.next_element()? {
                        out.push(b);
                    }
                    Ok(out)
                }
            }
            deserializer.deserialize_byte_buf(Owned)
        }
    }

    impl<'de: 'a, 'a> Octets<'de> for &'a [u8] {
        fn deserialize<D: Deserializer<'de>>(deserializer: D) -> Result<&'a [u8], D::Error> {
            struct Lent;
            impl<'de> Visitor<'de> for Lent {
                type Value = &'de [u8];
                fn expecting(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
                    f.write_str("a byte sequence lent by the message")
                }
                fn visit_borrowed_bytes<E: Error>(self, v: &'de [u8]) -> Result<&'de [u8], E> {
                    Ok(v)
                }
            }
            deserializer.deserialize_bytes(Lent)
        }
    }
}

pub use octets::Octets;

macro_rules! ros_type {
    ($ty:ty, $pkg:literal, $name:literal) => {
        impl RosType for $ty {
            const PACKAGE: &'static str = $pkg;
            const NAME: &'static str = $name;
        }
    };
}

/// builtin_interfaces/Time: seconds and nanoseconds since the Unix epoch.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct Time {
    /// Seconds.
    pub sec: i32,
    /// Nanoseconds, below 1e9.
    pub nanosec: u32,
}

impl Time {
    /// The wall clock now.
    pub fn now() -> Time {
        Time::from_system(SystemTime::now())
    }

    /// A system time (before the epoch counts as the epoch; after 2038 saturates).
    pub fn from_system(t: SystemTime) -> Time {
        let since = t.duration_since(UNIX_EPOCH).unwrap_or_default();
        Time {
            sec: i32::try_from(since.as_secs()).unwrap_or(i32::MAX),
            nanosec: since.subsec_nanos(),
        }
    }

    /// Nanoseconds since the epoch, or why not: a `nanosec` of a second or more is a broken
    /// writer, and read as is it would move the stamp by whole seconds (pairing a frame with
    /// another pose), so it is refused, naming `field` (the stamp's path in its message).
    pub fn checked_ns(self, field: &str) -> Result<i64, crate::cdr::CdrError> {
        if self.nanosec >= 1_000_000_000 {
            return Err(crate::cdr::CdrError::Field {
                field: format!("{field}.nanosec"),
                problem: format!(
                    "{}, expected below 1000000000 (the nanoseconds within second {})",
                    self.nanosec, self.sec
                ),
            });
        }
        Ok(i64::from(self.sec) * 1_000_000_000 + i64::from(self.nanosec))
    }

    /// As a system time (a negative stamp counts as the epoch).
    pub fn to_system(self) -> SystemTime {
        let secs = u64::try_from(self.sec).unwrap_or(0);
        UNIX_EPOCH + StdDuration::new(secs, self.nanosec.min(999_999_999))
    }
}

/// builtin_interfaces/Duration.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct Duration {
    /// Seconds.
    pub sec: i32,
    /// Nanoseconds, below 1e9.
    pub nanosec: u32,
}

impl Duration {
    /// From seconds (negative or not finite counts as zero).
    pub fn from_secs_f64(s: f64) -> Duration {
        let d = if s.is_finite() && s > 0.0 {
            StdDuration::from_secs_f64(s.min(i32::MAX as f64))
        } else {
            StdDuration::ZERO
        };
        Duration {
            sec: d.as_secs() as i32,
            nanosec: d.subsec_nanos(),
        }
    }
}

/// std_msgs/Header.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct Header {
    /// When the data was measured.
    pub stamp: Time,
    /// The frame the data is in.
    pub frame_id: String,
}

/// geometry_msgs/Vector3.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct Vector3 {
    /// x.
    pub x: f64,
    /// y.
    pub y: f64,
    /// z.
    pub z: f64,
}

/// geometry_msgs/Quaternion (x, y, z, w on the wire).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Quaternion {
    /// x.
    pub x: f64,
    /// y.
    pub y: f64,
    /// z.
    pub z: f64,
    /// w.
    pub w: f64,
}

/// geometry_msgs/Transform: `T_parent_child`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Transform {
    /// Child origin in the parent frame, m.
    pub translation: Vector3,
    /// Child axes in the parent frame.
    pub rotation: Quaternion,
}

impl Transform {
    /// From `T_parent_child`.
    pub fn from_pose(parent_from_child: &Pose) -> Transform {
        let t = parent_from_child.translation.vector;
        let q = parent_from_child.rotation.quaternion();
        Transform {
            translation: Vector3 {
                x: t.x,
                y: t.y,
                z: t.z,
            },
            rotation: Quaternion {
                x: q.i,
                y: q.j,
                z: q.k,
                w: q.w,
            },
        }
    }

    /// `T_parent_child`, or `None` when a value is not finite or the quaternion is far from unit
    /// length (|q| outside 0.99…1.01: a publisher's bug, not rounding).
    pub fn to_pose(&self) -> Option<Pose> {
        let (t, r) = (self.translation, self.rotation);
        let q = NaQuaternion::new(r.w, r.x, r.y, r.z);
        let norm = q.norm();
        let finite = [t.x, t.y, t.z, r.x, r.y, r.z, r.w]
            .iter()
            .all(|v| v.is_finite());
        if !finite || !(0.99..=1.01).contains(&norm) {
            return None;
        }
        Some(Pose::from_parts(
            Translation3::new(t.x, t.y, t.z),
            UnitQuaternion::from_quaternion(q),
        ))
    }
}

/// geometry_msgs/TransformStamped.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TransformStamped {
    /// Stamp and parent frame.
    pub header: Header,
    /// The child frame.
    pub child_frame_id: String,
    /// `T_parent_child`.
    pub transform: Transform,
}

/// tf2_msgs/TFMessage: what `/tf` and `/tf_static` carry.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct TfMessage {
    /// The transforms.
    pub transforms: Vec<TransformStamped>,
}
ros_type!(TfMessage, "tf2_msgs", "TFMessage");

/// sensor_msgs/JointState.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct JointState {
    /// Measurement time.
    pub header: Header,
    /// Joint names.
    pub name: Vec<String>,
    /// Positions, rad.
    pub position: Vec<f64>,
    /// Speeds, rad/s (may be empty).
    pub velocity: Vec<f64>,
    /// Efforts (may be empty).
    pub effort: Vec<f64>,
}
ros_type!(JointState, "sensor_msgs", "JointState");

/// sensor_msgs/Image. The pixels are owned (`Image`, the default) or lent by the message being
/// decoded (`Image<&[u8]>`, through [`crate::cdr::decode`]: no copy of the frame, for a reader
/// that looks at the pixels before deciding to keep them).
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(bound(serialize = "Data: AsRef<[u8]>", deserialize = "Data: Octets<'de>"))]
pub struct Image<Data = Vec<u8>> {
    /// Exposure time and the camera's optical frame.
    pub header: Header,
    /// Rows.
    pub height: u32,
    /// Columns.
    pub width: u32,
    /// `mono8`, `mono16`, `rgb8`, `bgr8`, `bayer_rggb8`, ...
    pub encoding: String,
    /// 1 when multi-byte pixels are big-endian.
    pub is_bigendian: u8,
    /// Bytes per row.
    pub step: u32,
    /// The pixels.
    #[serde(
        serialize_with = "octets::serialize",
        deserialize_with = "Octets::deserialize"
    )]
    pub data: Data,
}
ros_type!(Image, "sensor_msgs", "Image");
ros_type!(Image<&[u8]>, "sensor_msgs", "Image");

/// sensor_msgs/CompressedImage.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct CompressedImage {
    /// Exposure time and the camera's optical frame.
    pub header: Header,
    /// `jpeg`, `png` (image_transport adds the raw encoding: `bgr8; jpeg compressed bgr8`).
    pub format: String,
    /// The compressed file's bytes.
    #[serde(
        serialize_with = "octets::serialize",
        deserialize_with = "Octets::deserialize"
    )]
    pub data: Vec<u8>,
}
ros_type!(CompressedImage, "sensor_msgs", "CompressedImage");

/// sensor_msgs/RegionOfInterest.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct RegionOfInterest {
    /// Left column.
    pub x_offset: u32,
    /// Top row.
    pub y_offset: u32,
    /// Rows.
    pub height: u32,
    /// Columns.
    pub width: u32,
    /// Whether the region was rectified.
    pub do_rectify: bool,
}

/// sensor_msgs/CameraInfo.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct CameraInfo {
    /// Stamp and the camera's optical frame.
    pub header: Header,
    /// Rows.
    pub height: u32,
    /// Columns.
    pub width: u32,
    /// `plumb_bob`, `rational_polynomial`, `equidistant`.
    pub distortion_model: String,
    /// Distortion coefficients.
    pub d: Vec<f64>,
    /// Intrinsic matrix, row-major.
    pub k: [f64; 9],
    /// Rectification rotation, row-major.
    pub r: [f64; 9],
    /// Projection matrix, row-major.
    pub p: [f64; 12],
    /// Binning in x.
    pub binning_x: u32,
    /// Binning in y.
    pub binning_y: u32,
    /// Region of interest.
    pub roi: RegionOfInterest,
}
ros_type!(CameraInfo, "sensor_msgs", "CameraInfo");

impl CameraInfo {
    /// handeye's camera model of this camera, for bags and the live graph: its distortion and
    /// camera matrix read as a `camera_info` file's are (`Distortion::from_model_name`,
    /// `CameraModel::from_camera_matrix`: `plumb_bob`, `equidistant` or none; skew refused);
    /// binning and a region of interest smaller than the image are refused (the images would
    /// not be the calibrated ones), with the reason; so are intrinsics the model's checks refuse.
    pub fn camera_model(&self) -> Result<CameraModel, String> {
        let binned = |b: u32| b > 1;
        if binned(self.binning_x) || binned(self.binning_y) {
            return Err(format!(
                "binning {}x{} is not supported (calibrate at full resolution)",
                self.binning_x, self.binning_y
            ));
        }
        let roi = &self.roi;
        if roi.height != 0 && roi.width != 0 && (roi.height, roi.width) != (self.height, self.width)
        {
            return Err(format!(
                "a region of interest ({}x{} at {}, {}) is not supported",
                roi.width, roi.height, roi.x_offset, roi.y_offset
            ));
        }
        // The reason only: what to do instead is the caller's (a bag import's flag, a live
        // cell's `intrinsics:`).
        let distortion = Distortion::from_model_name(&self.distortion_model, &self.d)
            .map_err(|e| e.to_string())?;
        let k = self.k;
        let model = CameraModel::from_camera_matrix((self.width, self.height), &k, distortion)
            .ok_or_else(|| {
                format!("K {k:?} is not supported: skew, or not [fx, 0, cx, 0, fy, cy, 0, 0, 1]")
            })?;
        model
            .validate(std::path::Path::new("camera_info"))
            .map_err(|e| format!("K {:?}, D {:?}: {e}", k, self.d))?;
        Ok(model)
    }
}

/// trajectory_msgs/JointTrajectoryPoint.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct JointTrajectoryPoint {
    /// Positions, rad.
    pub positions: Vec<f64>,
    /// Speeds, rad/s (empty: the controller interpolates).
    pub velocities: Vec<f64>,
    /// Accelerations, rad/s² (may be empty).
    pub accelerations: Vec<f64>,
    /// Efforts (may be empty).
    pub effort: Vec<f64>,
    /// When to be there, from the trajectory's start.
    pub time_from_start: Duration,
}

/// trajectory_msgs/JointTrajectory.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct JointTrajectory {
    /// Start time (zero: now).
    pub header: Header,
    /// Joint names, in the order of every point's values.
    pub joint_names: Vec<String>,
    /// The waypoints.
    pub points: Vec<JointTrajectoryPoint>,
}

/// geometry_msgs/Twist.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct Twist {
    /// m/s.
    pub linear: Vector3,
    /// rad/s.
    pub angular: Vector3,
}

/// trajectory_msgs/MultiDOFJointTrajectoryPoint.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct MultiDofJointTrajectoryPoint {
    /// Transforms.
    pub transforms: Vec<Transform>,
    /// Speeds.
    pub velocities: Vec<Twist>,
    /// Accelerations.
    pub accelerations: Vec<Twist>,
    /// When to be there.
    pub time_from_start: Duration,
}

/// trajectory_msgs/MultiDOFJointTrajectory (handeye sends it empty).
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct MultiDofJointTrajectory {
    /// Start time.
    pub header: Header,
    /// Joint names.
    pub joint_names: Vec<String>,
    /// Waypoints.
    pub points: Vec<MultiDofJointTrajectoryPoint>,
}

/// control_msgs/JointTolerance.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct JointTolerance {
    /// Joint name.
    pub name: String,
    /// rad (0: the controller's default, -1: none).
    pub position: f64,
    /// rad/s.
    pub velocity: f64,
    /// rad/s².
    pub acceleration: f64,
}

/// control_msgs/JointComponentTolerance.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct JointComponentTolerance {
    /// Joint name.
    pub joint_name: String,
    /// Which component (X_AXIS = 1, ...).
    pub component: u16,
    /// Position tolerance.
    pub position: f64,
    /// Speed tolerance.
    pub velocity: f64,
    /// Acceleration tolerance.
    pub acceleration: f64,
}

/// control_msgs/action/FollowJointTrajectory goal (control_msgs 4.x and later: Humble, Jazzy).
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct FollowJointTrajectoryGoal {
    /// The joint trajectory.
    pub trajectory: JointTrajectory,
    /// Unused (empty).
    pub multi_dof_trajectory: MultiDofJointTrajectory,
    /// Per-joint path tolerances (empty: the controller's).
    pub path_tolerance: Vec<JointTolerance>,
    /// Unused (empty).
    pub component_path_tolerance: Vec<JointComponentTolerance>,
    /// Per-joint goal tolerances (empty: the controller's).
    pub goal_tolerance: Vec<JointTolerance>,
    /// Unused (empty).
    pub component_goal_tolerance: Vec<JointComponentTolerance>,
    /// How late the arm may arrive.
    pub goal_time_tolerance: Duration,
}

/// control_msgs/action/FollowJointTrajectory result.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct FollowJointTrajectoryResult {
    /// 0 on success, negative codes: [`follow_joint_trajectory_error`].
    pub error_code: i32,
    /// The controller's words.
    pub error_string: String,
}

/// control_msgs/action/FollowJointTrajectory feedback.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct FollowJointTrajectoryFeedback {
    /// Stamp.
    pub header: Header,
    /// Joint names.
    pub joint_names: Vec<String>,
    /// Where the arm should be.
    pub desired: JointTrajectoryPoint,
    /// Where it is.
    pub actual: JointTrajectoryPoint,
    /// The difference.
    pub error: JointTrajectoryPoint,
    /// Unused.
    pub multi_dof_joint_names: Vec<String>,
    /// Unused.
    pub multi_dof_desired: MultiDofJointTrajectoryPoint,
    /// Unused.
    pub multi_dof_actual: MultiDofJointTrajectoryPoint,
    /// Unused.
    pub multi_dof_error: MultiDofJointTrajectoryPoint,
}

/// What a FollowJointTrajectory result's `error_code` means, in words a person can act on.
pub fn follow_joint_trajectory_error(code: i32) -> &'static str {
    match code {
        0 => "successful",
        -1 => "INVALID_GOAL: the controller rejected the trajectory (joint names, sizes or times)",
        -2 => "INVALID_JOINTS: the joint names do not match the controller's joints",
        -3 => "OLD_HEADER_TIMESTAMP: the trajectory's start time is in the past",
        -4 => {
            "PATH_TOLERANCE_VIOLATED: the arm left the path tolerance (collision, payload, limits)"
        }
        -5 => "GOAL_TOLERANCE_VIOLATED: the arm did not reach the goal within its tolerance",
        _ => "an error code control_msgs does not define",
    }
}

/// std_msgs/Bool.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct Bool {
    /// The value.
    pub data: bool,
}
ros_type!(Bool, "std_msgs", "Bool");

/// `SwitchController.strictness`: fail if any controller cannot be switched.
pub const SWITCH_STRICT: i32 = 2;

/// controller_manager_msgs/SwitchController request as Humble's ros2_control (2.x) lays it out:
/// the deprecated `start`/`stop` lists and `start_asap` sit among the fields, so it differs on
/// the wire from Jazzy's ([`SwitchControllerJazzy`]).
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct SwitchControllerHumble {
    /// Controllers to activate.
    pub activate_controllers: Vec<String>,
    /// Controllers to deactivate.
    pub deactivate_controllers: Vec<String>,
    /// Deprecated; empty.
    pub start_controllers: Vec<String>,
    /// Deprecated; empty.
    pub stop_controllers: Vec<String>,
    /// [`SWITCH_STRICT`].
    pub strictness: i32,
    /// Deprecated; false.
    pub start_asap: bool,
    /// Activate as soon as the hardware is ready.
    pub activate_asap: bool,
    /// Zero: no timeout.
    pub timeout: Duration,
}

/// controller_manager_msgs/SwitchController request as Jazzy's ros2_control (4.x) lays it out.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct SwitchControllerJazzy {
    /// Controllers to activate.
    pub activate_controllers: Vec<String>,
    /// Controllers to deactivate.
    pub deactivate_controllers: Vec<String>,
    /// [`SWITCH_STRICT`].
    pub strictness: i32,
    /// Activate as soon as the hardware is ready.
    pub activate_asap: bool,
    /// Zero: no timeout.
    pub timeout: Duration,
}

/// controller_manager_msgs/SwitchController response: `ok` (newer releases add a message after
/// it, which is not read: a CDR reader stops at the fields it knows).
#[derive(Debug, Clone, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct SwitchControllerResponse {
    /// Whether the controllers were switched.
    pub ok: bool,
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Vector3 as NaVector3;

    #[test]
    fn a_transform_round_trips_a_pose() {
        let pose = Pose::new(
            NaVector3::new(0.1, -0.2, 0.3),
            NaVector3::new(0.4, 0.5, -0.6),
        );
        let back = Transform::from_pose(&pose).to_pose().unwrap();
        assert!((back.translation.vector - pose.translation.vector).norm() < 1e-15);
        assert!(back.rotation.angle_to(&pose.rotation) < 1e-12);
    }

    #[test]
    fn a_bad_quaternion_is_refused() {
        let mut t = Transform::from_pose(&Pose::identity());
        t.rotation.w = 2.0;
        assert!(t.to_pose().is_none());
        t.rotation.w = f64::NAN;
        assert!(t.to_pose().is_none());
    }

    #[test]
    fn camera_info_becomes_a_camera_model_or_says_why_not() {
        let mut info = CameraInfo {
            width: 640,
            height: 480,
            distortion_model: "plumb_bob".into(),
            d: vec![-0.1, 0.01, 0.001, 0.002, 0.0],
            k: [600.0, 0.0, 320.0, 0.0, 601.0, 240.0, 0.0, 0.0, 1.0],
            ..CameraInfo::default()
        };
        let model = info.camera_model().unwrap();
        assert_eq!(
            (model.fx, model.fy, model.cx, model.cy, model.width),
            (600.0, 601.0, 320.0, 240.0, 640)
        );
        assert!(matches!(model.distortion, Distortion::RadTan { k1, .. } if k1 == -0.1));
        info.distortion_model = "rational_polynomial".into();
        let unknown = info.camera_model().unwrap_err();
        assert!(unknown.contains("rational_polynomial"), "{unknown}");
        // The reason only: a live cell and a bag import each say what to do instead.
        assert!(!unknown.contains("--camera-info"), "{unknown}");
        // A fisheye driver's message reads as its camera_info file does.
        info.distortion_model = "equidistant".into();
        info.d = vec![0.1, -0.02, 0.003, -0.0004];
        assert!(matches!(
            info.camera_model().unwrap().distortion,
            Distortion::Equidistant { k4, .. } if k4 == -0.0004
        ));
        info.d.push(0.0);
        assert!(info.camera_model().unwrap_err().contains("expected 4"));
        info.d = vec![-0.1, 0.01, 0.001, 0.002, 0.0];
        info.distortion_model = "plumb_bob".into();
        info.binning_x = 2;
        assert!(info.camera_model().unwrap_err().contains("binning 2x0"));
        info.binning_x = 0;
        info.roi.width = 320;
        info.roi.height = 240;
        assert!(info
            .camera_model()
            .unwrap_err()
            .contains("region of interest"));
        info.roi = RegionOfInterest::default();
        info.k[1] = 0.5;
        assert!(info.camera_model().unwrap_err().contains("skew"));
    }

    #[test]
    fn times_and_durations_convert() {
        let t = Time {
            sec: 1_700_000_000,
            nanosec: 5,
        };
        assert_eq!(Time::from_system(t.to_system()), t);
        assert_eq!(Duration::from_secs_f64(1.5).nanosec, 500_000_000);
        assert_eq!(Duration::from_secs_f64(-1.0), Duration::default());
        assert!(follow_joint_trajectory_error(-4).starts_with("PATH_TOLERANCE"));
    }
}
