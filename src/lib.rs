//! handeye: hand-eye (camera ↔ flange) and base-world (base ↔ target) calibration for robot
//! cells. See `DESIGN.md` in the shared folder and the README for the frame convention
//! (`T_a_b` maps points in frame `b` into frame `a`; `a_from_b` in code), and ARCHITECTURE.md
//! for the crates and layers.
//!
//! This crate is the top of the workspace: the outputs (the live console, the report, the file
//! formats in and out) and the `handeye` binary. It re-exports the layers below under the module
//! names the project has always used (`handeye::geometry`, `handeye::solve`, …), so a caller
//! needs one dependency.

pub mod console;
pub mod formats;
pub mod report;

pub use handeye_camera as camera;
pub use handeye_core::{atomic_file, camera_model, error_text, geometry, notice, setup, yaml_file};
pub use handeye_robot as robot;
pub use handeye_ros2 as ros2;
pub use handeye_session::{cell, config, dataset, plan, result, session, verify};
pub use handeye_solve as solve;
pub use handeye_solve::verdict;
pub use handeye_vision as vision;
