//! Data in and results out in other tools' forms: importers (ViSP, MoveIt Calibration, CSV) that
//! produce our pose pairs, and exporters (ROS 2, URDF, UR, JSON, OpenCV) of a solved result,
//! and the arm's estimated model as ur_robot_driver's calibration file (`ur_calibration`), a DH
//! table and a URDF of its chain (`arm_model`).
//! Each importer's module docs state which transform its source holds and in which direction.
//! Sits above `handeye-session`: it uses `geometry`, `solve`, `dataset`, `result`,
//! `camera_model` and `target` (to detect boards in imported images), never a hardware backend. `bag` writes a
//! ROS 2 bag as a session; reading the bag is `handeye-ros2-bag`'s.

pub mod arm_model;
pub mod bag;
pub mod export;
pub mod import;
pub mod ros2_launch;
pub mod ur_calibration;

pub use export::{export, validate_frame_id, ExportError, ExportFormat, FrameIds};
pub use import::ImportError;
