//! Waiting for the arm to stand still: the joint speeds it reports stay below a threshold for a
//! window (after a move, and before a hand-guided capture while a person may still hold it).

use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;

use handeye_robot::{Robot, RobotError, SettleBySpeed};

use super::SETTLE_POLL;

/// Why [`wait_until_still`] found no still arm.
pub(crate) enum NotStill {
    /// The arm's own error, or [`RobotError::Interrupted`] when a stop was requested.
    Robot(RobotError),
    /// A joint still moved at `fastest` rad/s when the rule's timeout ran out.
    Moving {
        /// The fastest joint speed of the last reading above the threshold, rad/s.
        fastest: f64,
    },
}

impl NotStill {
    /// What the rule's numbers say about an arm that did not settle.
    pub(crate) fn moving_message(fastest: f64, rule: &SettleBySpeed) -> String {
        format!(
            "a joint still moved at {:.2}°/s {:.1} s on (session.settle_speed_deg_s = {:.2}°/s for session.settle_window_s = {:.2} s)",
            fastest.to_degrees(),
            rule.timeout.as_secs_f64(),
            rule.max_joint_speed.to_degrees(),
            rule.window.as_secs_f64()
        )
    }

    /// As a robot error of a move that did not settle.
    pub(crate) fn into_robot_error(self, rule: &SettleBySpeed) -> RobotError {
        match self {
            NotStill::Robot(e) => e,
            NotStill::Moving { fastest } => RobotError::Backend(
                format!(
                    "the arm did not settle after the move: {}",
                    Self::moving_message(fastest, rule)
                )
                .into(),
            ),
        }
    }
}

/// Waits until every joint speed the arm reports has stayed below the rule's threshold for the
/// rule's window; returns the start of that quiet window (a frame exposed from then on shows the
/// arm at rest). Returns at once when the arm reports no speeds. Fails when the arm is still
/// moving `timeout` after `since` (the end of a move, or a hand-guided capture's request), or
/// when a stop is requested.
pub(crate) fn wait_until_still(
    robot: &mut dyn Robot,
    rule: &SettleBySpeed,
    since: Instant,
    stop: &AtomicBool,
) -> Result<Instant, NotStill> {
    let mut quiet_since: Option<Instant> = None;
    let mut fastest = 0.0f64;
    loop {
        let Some(speeds) = robot.joint_speeds().map_err(NotStill::Robot)? else {
            return Ok(Instant::now());
        };
        // Taken after the reading: the reading shows the arm no later than this.
        let now = Instant::now();
        let top = speeds.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        if top.is_nan() || top >= rule.max_joint_speed {
            quiet_since = None;
            fastest = if top.is_nan() { f64::INFINITY } else { top };
        } else {
            let quiet = *quiet_since.get_or_insert(now);
            if now.duration_since(quiet) >= rule.window {
                return Ok(quiet);
            }
        }
        if stop.load(Ordering::SeqCst) {
            return Err(NotStill::Robot(RobotError::Interrupted));
        }
        if now.duration_since(since) > rule.timeout {
            return Err(NotStill::Moving { fastest });
        }
        std::thread::sleep(SETTLE_POLL);
    }
}
