//! The robot arm contract: [`Robot`] and its error. Backends live in `robot/` (the simulated arm,
//! the recorded arm that replays measured poses, and the Universal Robots arm through ur_rtde
//! behind the `ur-rtde` feature); the session sees
//! only this trait.
//!
//! Frames: every pose here is `T_base_flange` (the tool flange, tool0, with no TCP offset) in the
//! robot's base frame; metres and radians. Joint positions are radians, base joint first ([`Joints`]: six on a UR, up to seven on an arm
//! driven over ROS 2).

pub mod arm_errors;
pub mod joints;
pub mod kinematics;
pub mod recorded;
pub mod sim;
// ur_rtde's C++ through its C shim: the crate's one module with `unsafe`.
#[cfg(feature = "ur-rtde")]
#[allow(unsafe_code)]
pub mod ur;

use std::sync::atomic::AtomicBool;
use std::sync::Arc;
use std::time::Duration;

use nalgebra::Vector3;

use handeye_core::geometry::Pose;

pub use joints::{JointCountError, Joints, MAX_JOINTS};

/// `joints` as a six-joint arm's, or [`RobotError::JointCount`]: the check a UR backend makes
/// before it moves.
pub fn six_joints(joints: &Joints) -> Result<[f64; 6], RobotError> {
    joints.six().ok_or(RobotError::JointCount {
        arm: 6,
        asked: joints.len(),
    })
}

/// Speed and acceleration caps for a move. Backends never exceed these; the session takes them
/// from the cell config.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MotionLimits {
    /// Linear tool speed for linear moves, m/s.
    pub linear_speed: f64,
    /// Linear tool acceleration, m/s².
    pub linear_acceleration: f64,
    /// Joint speed for joint moves, rad/s.
    pub joint_speed: f64,
    /// Joint acceleration, rad/s².
    pub joint_acceleration: f64,
}

impl Default for MotionLimits {
    /// Conservative limits for calibration moves near people: 0.1 m/s, 30 °/s.
    fn default() -> Self {
        MotionLimits {
            linear_speed: 0.10,
            linear_acceleration: 0.5,
            joint_speed: 30f64.to_radians(),
            joint_acceleration: 60f64.to_radians(),
        }
    }
}

impl MotionLimits {
    /// Rejects caps that are not finite and positive, naming the field, its value and unit.
    pub fn check(&self) -> Result<(), RobotError> {
        let fields = [
            ("linear_speed", self.linear_speed, "m/s"),
            ("linear_acceleration", self.linear_acceleration, "m/s^2"),
            ("joint_speed", self.joint_speed, "rad/s"),
            ("joint_acceleration", self.joint_acceleration, "rad/s^2"),
        ];
        for (name, value, unit) in fields {
            if !(value.is_finite() && value > 0.0) {
                return Err(RobotError::Backend(
                    format!("motion limit {name} = {value} {unit} must be finite and > 0").into(),
                ));
            }
        }
        Ok(())
    }

    /// Duration of a joint move `from` → `to` as a UR controller runs a `moveJ` at these
    /// limits, s: the joints move in sync, so the joint with the longest travel sets the time,
    /// on a trapezoidal speed profile (accelerate at `joint_acceleration` to `joint_speed`, cruise,
    /// decelerate; a triangle when the travel is too short to reach the speed).
    pub fn joint_move_time(&self, from: &Joints, to: &Joints) -> f64 {
        trapezoid_time(
            leading_travel(from, to),
            self.joint_speed,
            self.joint_acceleration,
        )
    }
}

/// The travel of the joint that moves furthest from `from` to `to`, rad: the one that sets a
/// synchronised joint move's time and profile.
pub fn leading_travel(from: &Joints, to: &Joints) -> f64 {
    from.iter()
        .zip(to)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0, f64::max)
}

/// Time to travel `distance` from rest to rest at most at `speed` with `acceleration`, s.
pub fn trapezoid_time(distance: f64, speed: f64, acceleration: f64) -> f64 {
    let (d, v, a) = (distance.abs(), speed, acceleration);
    if d <= v * v / a {
        2.0 * (d / a).sqrt()
    } else {
        d / v + v / a
    }
}

/// Position (fraction of `distance` covered) and speed (units of `distance` per s) at `t`
/// seconds into a rest-to-rest trapezoidal move taking [`trapezoid_time`]; the profile of the
/// leading joint, which every other joint of a synchronised move follows scaled.
pub fn trapezoid_at(distance: f64, speed: f64, acceleration: f64, t: f64) -> (f64, f64) {
    let d = distance.abs();
    if d == 0.0 {
        return (1.0, 0.0);
    }
    let total = trapezoid_time(d, speed, acceleration);
    let t = t.clamp(0.0, total);
    // Peak speed reached: `speed`, or less on a triangle.
    let peak = speed.min((d * acceleration).sqrt());
    let ramp = peak / acceleration;
    let (s, v) = if t < ramp {
        (0.5 * acceleration * t * t, acceleration * t)
    } else if t <= total - ramp {
        (0.5 * peak * ramp + peak * (t - ramp), peak)
    } else {
        let left = total - t;
        (d - 0.5 * acceleration * left * left, acceleration * left)
    };
    ((s / d).clamp(0.0, 1.0), v)
}

/// When the arm counts as standing still: every reported joint speed below `max_joint_speed`
/// for at least `window` without a break.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SettleBySpeed {
    /// Largest joint speed of an arm at rest, rad/s.
    pub max_joint_speed: f64,
    /// How long the speeds must stay below it (longer than half a period of the arm's ringing,
    /// so a zero crossing of the oscillation does not count as rest).
    pub window: Duration,
    /// An arm still moving this long after a move ends the run with an error.
    pub timeout: Duration,
}

/// An axis-aligned box in the base frame that the flange origin must stay inside, in metres.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WorkspaceBox {
    /// Lower corner (x, y, z), m.
    pub min: Vector3<f64>,
    /// Upper corner (x, y, z), m.
    pub max: Vector3<f64>,
}

impl WorkspaceBox {
    /// Whether the flange origin of `base_from_flange` lies inside the box (bounds included).
    pub fn contains(&self, base_from_flange: &Pose) -> bool {
        let p = base_from_flange.translation.vector;
        (0..3).all(|i| p[i] >= self.min[i] && p[i] <= self.max[i])
    }
}

/// What the controller says about its ability to move.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RobotStatus {
    /// Powered, no stop active, ready to take a move.
    Ready,
    /// A protective stop is active (collision or limit): needs a person to clear it.
    ProtectiveStop,
    /// An emergency stop is active.
    EmergencyStop,
    /// The controller is not in a state to run programs (powered off, in local mode, ...).
    NotReady,
}

/// Why a robot call failed. After any error the arm is stopped or was never moving; the session
/// turns these into a clean stop that keeps every recorded sample.
#[derive(Debug, thiserror::Error)]
pub enum RobotError {
    /// Could not reach the controller within the timeout.
    #[error("cannot connect to the robot at {address} within {timeout:?}: {reason}")]
    Connect {
        /// Host or address that was tried.
        address: String,
        /// Timeout that ran out, or the time the attempt took.
        timeout: Duration,
        /// What the transport said.
        reason: String,
    },
    /// The connection dropped during a call.
    #[error("lost the connection to the robot: {0}")]
    ConnectionLost(String),
    /// A protective stop interrupted or prevented the move.
    #[error("protective stop on the robot: clear it on the teach pendant, then resume")]
    ProtectiveStop,
    /// An emergency stop interrupted or prevented the move.
    #[error("emergency stop on the robot: release it and re-enable the arm, then resume")]
    EmergencyStop,
    /// The target lies outside the configured workspace box; nothing was sent.
    #[error("target flange position [{x:.4}, {y:.4}, {z:.4}] m is outside the workspace box; nothing was sent")]
    OutsideWorkspace {
        /// Target x, m.
        x: f64,
        /// Target y, m.
        y: f64,
        /// Target z, m.
        z: f64,
    },
    /// No joint solution within the joint limits reaches the target.
    #[error("target pose is not reachable within the joint limits: {0}")]
    Unreachable(String),
    /// A joint move names another number of joints than the arm has (a seven-joint arm's taught
    /// plan replayed on a UR, say). Nothing moved.
    #[error("the arm has {arm} joints but the move names {asked}; a plan taught on one arm replays only on an arm with the same joints")]
    JointCount {
        /// The arm's joints.
        arm: usize,
        /// The joints the move named.
        asked: usize,
    },
    /// A move did not finish in time.
    #[error("move did not finish within {0:?}; the arm was stopped")]
    MoveTimeout(Duration),
    /// The interrupt flag was set during the move: the arm was stopped where it was.
    #[error("the move was stopped on request; the arm decelerated and stands where it stopped")]
    Interrupted,
    /// This backend cannot do what was asked (switch freedrive over ROS 2, say); the message
    /// says what to do instead. Nothing was changed on the arm.
    #[error("{0}")]
    NotAvailable(String),
    /// Anything else the backend reports.
    #[error("robot backend error")]
    Backend(#[source] Box<dyn std::error::Error + Send + Sync>),
}

/// A robot arm. All calls block until done (a move returns when the arm has arrived and
/// stopped); a blocking driver therefore runs on a thread of its own in the session.
pub trait Robot: Send {
    /// The current flange pose `T_base_flange` as the controller measures it.
    fn base_from_flange(&mut self) -> Result<Pose, RobotError>;
    /// The current joint positions, radians.
    fn joint_positions(&mut self) -> Result<Joints, RobotError>;
    /// Moves the flange along a straight line to `base_from_flange`, within `limits`; returns when
    /// the arm has stopped there.
    fn move_linear(
        &mut self,
        base_from_flange: &Pose,
        limits: &MotionLimits,
    ) -> Result<(), RobotError>;
    /// Moves in joint space to `joints`, within `limits`; returns when the arm has stopped there.
    fn move_joints(&mut self, joints: &Joints, limits: &MotionLimits) -> Result<(), RobotError>;
    /// Stops any motion now (decelerating within the controller's limits).
    fn stop(&mut self) -> Result<(), RobotError>;
    /// A flag that, once set (by Ctrl-C, say), stops a move in progress — the arm decelerates
    /// where it is — and makes that move return [`RobotError::Interrupted`]. Moves started
    /// while it is set return that at once, without moving. Backends whose moves take no time
    /// may ignore it.
    fn set_interrupt(&mut self, _flag: Arc<AtomicBool>) {}
    /// The controller's safety and readiness state.
    fn status(&mut self) -> Result<RobotStatus, RobotError>;
    /// Freedrive (UR teach mode) on or off: while on, a person can move the arm by hand, and
    /// the arm holds where it is let go; off, it holds its position under control again. Backends
    /// that cannot switch it return [`RobotError::NotAvailable`] saying how to hand-guide instead.
    fn set_freedrive(&mut self, _on: bool) -> Result<(), RobotError> {
        Err(RobotError::NotAvailable(
            "freedrive is not available with this robot backend (only a real UR arm has it)".into(),
        ))
    }
    /// The joint speeds the controller measures now, rad/s (RTDE `actual_qd` on a UR), or
    /// `None` when this backend measures none (nothing moves, e.g. a recorded arm): the session
    /// then settles by its fixed wait only. An arm that has just arrived still moves a little
    /// (it rings down); the session waits for these speeds to stay low before it captures.
    fn joint_speeds(&mut self) -> Result<Option<Joints>, RobotError> {
        Ok(None)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bad_limits_are_clear_errors() {
        let negative = MotionLimits {
            linear_speed: -0.1,
            ..MotionLimits::default()
        };
        match negative.check() {
            Err(RobotError::Backend(e)) => assert_eq!(
                e.to_string(),
                "motion limit linear_speed = -0.1 m/s must be finite and > 0"
            ),
            other => panic!("expected a backend error, got {other:?}"),
        }
        let nan = MotionLimits {
            joint_acceleration: f64::NAN,
            ..MotionLimits::default()
        };
        assert!(nan.check().is_err());
        let zero = MotionLimits {
            joint_speed: 0.0,
            ..MotionLimits::default()
        };
        assert!(zero.check().is_err());
        assert!(MotionLimits::default().check().is_ok());
    }
}
