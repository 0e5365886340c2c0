//! handeye's integration tests, one binary (it links handeye once instead of once per file):
//! one module per area, the shared helpers in `tests/util/`. Run one area with
//! `cargo test --test it AREA::` (e.g. `cargo test --test it console::`).

// The function-length limit (clippy.toml) is for the code a reader maintains in src/ and
// crates/; a test reads top to bottom as its scenario, every step asserted where it happens.
#![allow(clippy::too_many_lines)]

#[path = "../util/mod.rs"]
mod util;

mod adaptive;
mod advice;
mod aprilgrid_photos;
mod armtime;
mod bag_import;
mod boards;
mod cameras;
mod cell_model;
mod cell_model_run;
mod cellkit;
mod cli_names;
mod cli_run;
mod closed_forms;
mod config;
mod console;
mod crash;
mod dataset;
mod driver;
mod driver_calibration;
mod formats;
mod friction;
mod fuzz;
mod hardening;
mod kalibr_print;
mod kinematics;
mod layers;
mod live;
mod manual;
mod memory;
mod noise;
mod plausibility;
mod report;
mod reprojection;
mod ros2_export;
#[cfg(feature = "ros2")]
mod ros2_live;
mod session;
mod solve;
mod uncertainty;
mod ur_rtde;
mod ur_session;
mod verdict;
mod verify;
mod vision;
