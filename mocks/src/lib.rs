//! Stand-ins for handeye's hardware that speak the real wire protocols, so the real client
//! libraries can be tested over loopback without a robot: [`ur::MockUr`], a mock Universal Robots
//! controller (RTDE on 30004, dashboard on 29999, script receiver on 30003).
//!
//! This crate depends on `handeye` only for the arm kinematics; `handeye` never depends on it.
#![warn(missing_docs)]

pub mod ur;

pub use ur::{ControllerVersion, MockFaults, MockUr, MockUrConfig, MockUrError, MockUrPorts};
