//! handeye: hand-eye (camera ↔ flange) and base-world (base ↔ target) calibration for robot
//! cells. See `DESIGN.md` in the shared folder and the README for the frame convention
//! (`T_a_b` maps points in frame `b` into frame `a`; `a_from_b` in code) and the layers.
#![warn(missing_docs)]

pub mod atomic_file;
pub mod camera;
pub mod camera_model;
pub mod cell;
pub mod config;
pub mod console;
pub mod dataset;
pub mod formats;
pub mod geometry;
pub mod notice;
pub mod plan;
pub mod report;
pub mod result;
pub mod robot;
pub mod session;
pub mod setup;
pub mod solve;
pub mod verdict;
pub mod verify;
pub mod vision;
pub mod yaml_file;
