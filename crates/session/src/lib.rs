//! handeye's run: what to visit, what the files hold, and the run itself — the only layer with
//! time, hardware and disk.
//!
//! - [`plan`]: scripted and generated plans, their checks before the arm moves, next-best view;
//! - [`config`]: the cell config (`schema` shapes, `validate` ranges);
//! - [`dataset`], [`result`]: pose-pair datasets and the result file;
//! - [`session`]: the session folder (a write-ahead log with a lock and input hashes), the driver
//!   that visits poses, adaptive and hand-guided capture, replay and the session solve;
//! - [`cell`]: a cell prepared from its config and a run of it end to end;
//! - [`verify`]: held-out checks of a result.

pub mod cell;
pub mod config;
pub mod dataset;
pub mod plan;
pub mod result;
pub mod session;
pub mod verify;
