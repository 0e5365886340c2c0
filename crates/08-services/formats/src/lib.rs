//! Data in and results out in other tools' forms: importers (ViSP, MoveIt Calibration, CSV) that
//! produce our pose pairs, and exporters (ROS 2, URDF, UR, JSON, OpenCV) of a solved result,
//! and the arm's estimated model as ur_robot_driver's calibration file (`ur_calibration`), a DH
//! table and a URDF of its chain (`arm_model`).
//! Each importer's module docs state which transform its source holds and in which direction.
//! It uses `geometry`, `dataset`, `result`, `camera_model` and `target` (to detect boards in
//! imported images), never a hardware backend or a run (a ROS 2 bag imported as a session is the
//! run layer's `handeye_session::cell::bag`).

pub mod arm_model;
pub mod export;
pub mod import;
pub mod ros2_launch;
pub mod ur_calibration;

pub use export::{export, validate_frame_id, ExportError, ExportFormat, FrameIds};
pub use import::ImportError;
