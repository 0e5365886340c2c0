//! ROS 2 for handeye without a ROS installation. [`msg`] holds the ROS 2 messages handeye reads
//! and writes (serde structs in `.msg` field order, always built), [`cdr`] their serialised form
//! (the `cdr-encoding` codec RustDDS uses), [`image`] their pixels as grey and
//! [`msg::CameraInfo::camera_model`] their intrinsics: one model for bags (`handeye-ros2-bag`,
//! beside this crate) and the live graph. With the `dds` feature,
//! [`link`] is one DDS participant and node (ros2-client on RustDDS: pure Rust, no ROS, no
//! Cyclone/Fast DDS library) and [`tf_static`] publishes transforms the way
//! `static_transform_publisher` does.
//!
//! Frames: a transform on the wire is `T_parent_child` (header frame, child frame); units metres
//! and radians. This crate sits beside the robot and camera crates and uses their traits; the
//! session opens it, nothing below names it.

pub mod cdr;
pub mod image;
pub mod listen;
pub mod msg;

#[cfg(feature = "dds")]
pub mod arm;
#[cfg(feature = "dds")]
pub mod camera;
#[cfg(feature = "dds")]
pub mod freedrive;
#[cfg(feature = "dds")]
pub mod link;
#[cfg(feature = "dds")]
pub mod tf_static;

/// Why a ROS 2 call failed: what was tried, on which topic or action, and what came back.
#[derive(Debug, thiserror::Error)]
pub enum Ros2Error {
    /// The DDS participant, node, topic, reader or writer could not be made.
    #[error("cannot set up ROS 2 {what}: {reason}")]
    Setup {
        /// What was being made (`the DDS participant on domain 0`, `a reader of /tf`, ...).
        what: String,
        /// What the DDS layer said.
        reason: String,
    },
    /// A topic or frame name is not a valid ROS 2 name.
    #[error("{name:?} is not a valid ROS 2 {kind} name: {reason}")]
    Name {
        /// `topic`, `action`, `node`.
        kind: &'static str,
        /// The name as configured.
        name: String,
        /// Why.
        reason: String,
    },
    /// Writing a message failed.
    #[error("cannot publish on {topic}: {reason}")]
    Publish {
        /// The topic.
        topic: String,
        /// What the DDS layer said.
        reason: String,
    },
}
