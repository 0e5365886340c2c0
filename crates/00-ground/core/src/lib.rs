//! handeye's ground floor: the vocabulary every other crate shares and nothing below it.
//!
//! - [`geometry`]: poses (`Pose` = `T_a_b`, `a_from_b` in code), rotation helpers and the pose
//!   YAML forms of DESIGN.md;
//! - [`camera_model`]: the pinhole camera with its distortion models and the intrinsics files
//!   (ROS camera_info, Kalibr camchain), validated on load;
//! - [`setup`]: eye-in-hand / eye-to-hand, the two unknowns of a cell, a pose pair, a corner
//!   observation;
//! - [`notice`]: typed messages with a severity;
//! - [`memory`]: the memory limits the process runs under (`ulimit -v`, the cgroup's), and the
//!   check that a step fits them;
//! - [`atomic_file`], [`yaml_file`]: files written whole or not at all, YAML read with errors that
//!   name the file, the key and the line.

pub mod atomic_file;
pub mod camera_model;
pub mod error_text;
pub mod geometry;
pub mod memory;
pub mod notice;
pub mod setup;
pub mod yaml_file;
