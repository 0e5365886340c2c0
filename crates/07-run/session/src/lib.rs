//! handeye's run: a cell prepared from its config and driven end to end — the only layer with
//! time and hardware. Below it, `handeye-plan` (where the arm goes), `handeye-config` (what the
//! cell is) and `handeye-records` (what a session folder holds, and its solve).
//!
//! - [`driver`]: the pose loop that visits a validated plan on a robot and its cameras and
//!   records every sample as it is taken. Per pose: move (joint move to the validated joint
//!   solution) → settle → grab a frame newer than the settle instant → read the measured
//!   `T_base_flange` → hand the frame to the detection threads, which detect, estimate
//!   `T_camera_target` and write the records while the arm is already moving to the next pose.
//!   It sees the `Robot` and `Camera` traits, never a backend;
//! - [`adaptive`], [`manual`]: plans that grow as the run goes (next-best view) and hand-guided
//!   capture;
//! - [`cell`]: a cell prepared from its config, its hardware opened, and a run of it end to end
//!   (and `cell::replay`: a recorded session's frames detected again and solved);
//! - [`verify`]: held-out checks of a result.

pub mod adaptive;
pub mod cell;
pub mod driver;
pub mod manual;
pub mod verify;

pub use adaptive::{run_adaptive_session, CellPlanner, PlanSource};
pub use driver::{
    run_session, CameraFailure, FrameRecorder, PoseLoop, SessionCamera, SessionEvent,
    SessionOutcome, SessionSetup, SharedFrame,
};
pub use manual::{run_manual_session, ManualCommand, ManualControl, ManualEvent, ManualOptions};
