//! handeye: hand-eye (camera ↔ flange) and base-world (base ↔ target) calibration for robot
//! cells. See `DESIGN.md` in the shared folder and the README for the frame convention
//! (`T_a_b` maps points in frame `b` into frame `a`; `a_from_b` in code), and ARCHITECTURE.md
//! for the crates and layers.
//!
//! This crate is the top of the workspace: the outputs (the live console, the report, the file
//! formats in and out) and the `handeye` binary. It re-exports nothing: a caller names the crate
//! it uses (`handeye_core::geometry`, `handeye_solve::verdict`, …).

pub mod report;
