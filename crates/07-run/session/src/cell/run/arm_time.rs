//! Arm time: what a run spent moving and settling, against what the full plan in its given
//! order would have cost; kept in the session folder for the report.

use crate::SessionOutcome;

use super::PreparedCell;

/// The arm time of a run (the time the cell is out of production for the arm's sake: moving
/// and settling), and an estimate of what the full plan in its given order would have taken.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ArmTime {
    /// Poses visited in this run.
    pub poses: usize,
    /// Time in moves, s (measured).
    pub moving_s: f64,
    /// Time settling after moves until the frame's exposure, s (measured).
    pub settling_s: f64,
    /// Poses of the full plan (every pose that passes its checks).
    pub full_plan_poses: usize,
    /// The full plan in its given order: its moves at the configured limits (scaled by
    /// `move_time_scale`) plus this run's mean settling per pose for each of its poses, s (an
    /// estimate).
    pub full_plan_estimate_s: f64,
    /// How this arm's moves compare with the move-time model at the configured limits: this
    /// run's measured move time over the model's time for the same moves (1 when the arm moves
    /// as modelled; a simulated arm with a fixed `move_duration_s` differs). The full plan's
    /// moves are estimated with it, so the saving compares like with like.
    #[serde(default = "one")]
    pub move_time_scale: f64,
}

fn one() -> f64 {
    1.0
}

/// Whether `poses` moves that took `spent_s` in all were measured (see [`ArmTime::measured`]).
fn moves_measured(poses: usize, spent_s: f64) -> bool {
    poses == 0 || spent_s >= 0.01 * poses as f64
}

impl ArmTime {
    /// Moving plus settling, s.
    pub fn spent_s(&self) -> f64 {
        self.moving_s + self.settling_s
    }

    /// Estimated arm time saved against the full plan in its given order, s (negative: lost).
    pub fn saved_s(&self) -> f64 {
        self.full_plan_estimate_s - self.spent_s()
    }

    /// Whether arm time was measured: a simulated arm that moves instantly
    /// (`robot.move_duration_s: 0`) spends none — only the microseconds of the loop itself,
    /// under 10 ms a pose — and then nothing was saved either. (A real arm's move and settle
    /// take a second or more.)
    pub fn measured(&self) -> bool {
        moves_measured(self.poses, self.spent_s())
    }

    /// The file in a session folder that keeps it (written after the run, read by the report).
    pub const FILE: &'static str = "arm_time.yaml";

    /// The arm time a session folder at `root` kept, if it kept one that reads.
    pub fn load(root: &std::path::Path) -> Option<ArmTime> {
        let text = std::fs::read_to_string(root.join(Self::FILE)).ok()?;
        serde_yaml_ng::from_str(&text).ok()
    }
}

impl std::fmt::Display for ArmTime {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        if !self.measured() {
            return write!(
                f,
                "arm time: not measured, the {} moves took no time (a simulated arm with robot.move_duration_s: 0); the full {}-pose plan in its given order takes about {:.1} s at the configured limits",
                self.poses, self.full_plan_poses, self.full_plan_estimate_s
            );
        }
        write!(
            f,
            "arm time: {:.1} s for {} poses ({:.1} s moving, {:.1} s settling); the full {}-pose plan in its given order: about {:.1} s{}, so {}",
            self.spent_s(),
            self.poses,
            self.moving_s,
            self.settling_s,
            self.full_plan_poses,
            self.full_plan_estimate_s,
            if (self.move_time_scale - 1.0).abs() > 0.1 {
                format!(
                    " (its moves at {:.2}x the modelled time, as this arm's moves took)",
                    self.move_time_scale
                )
            } else {
                String::new()
            },
            {
                let percent = if self.full_plan_estimate_s > 0.0 {
                    100.0 * self.saved_s() / self.full_plan_estimate_s
                } else {
                    0.0
                };
                if self.saved_s() >= 0.0 {
                    format!("{:.1} s saved ({percent:.0} %)", self.saved_s())
                } else {
                    format!(
                        "{:.1} s more than the full plan ({:.0} %): the poses chosen were far apart, or the run retried some",
                        -self.saved_s(),
                        -percent
                    )
                }
            }
        )
    }
}

/// The run's arm time against the full plan in its given order.
pub(super) fn arm_time(cell: &PreparedCell, outcome: &SessionOutcome) -> ArmTime {
    let report = &cell.report;
    let full: Vec<&handeye_plan::check::PoseCheck> = report
        .poses
        .iter()
        .filter(|p| p.problems.is_empty())
        .collect();
    let given_moves_s = report
        .given_order_move_time_s
        .unwrap_or_else(|| report.total_move_time_s());
    // How this arm moves against the model (a real UR follows it closely; a simulated arm
    // with a fixed move time does not): the full plan's moves are estimated at that pace.
    // (Instant simulated moves measure nothing: the model's own times stand then.)
    let measured = moves_measured(outcome.visited_now, outcome.arm_time_s());
    let move_time_scale = if measured && outcome.modelled_moving_s > 1e-3 {
        outcome.moving_modelled_s / outcome.modelled_moving_s
    } else {
        1.0
    };
    let settle_per_pose = if outcome.visited_now > 0 {
        outcome.settling_s / outcome.visited_now as f64
    } else {
        0.0
    };
    ArmTime {
        poses: outcome.visited_now,
        moving_s: outcome.moving_s,
        settling_s: outcome.settling_s,
        full_plan_poses: full.len(),
        full_plan_estimate_s: given_moves_s * move_time_scale + settle_per_pose * full.len() as f64,
        move_time_scale,
    }
}

#[cfg(test)]
mod tests {
    use super::ArmTime;

    #[test]
    fn instant_moves_claim_no_saving() {
        let instant = ArmTime {
            poses: 8,
            moving_s: 0.0,
            settling_s: 0.0,
            full_plan_poses: 20,
            full_plan_estimate_s: 28.6,
            move_time_scale: 1.0,
        };
        let text = instant.to_string();
        assert!(!instant.measured());
        assert!(
            text.contains("not measured") && !text.contains("saved"),
            "{text}"
        );
        // What the demo's instant moves really measure: the loop's own few milliseconds.
        let loop_only = ArmTime {
            moving_s: 0.0004,
            settling_s: 0.0031,
            ..instant
        };
        assert!(!loop_only.measured(), "{loop_only}");
        let real = ArmTime {
            moving_s: 9.0,
            settling_s: 1.0,
            ..instant
        };
        assert!(real.measured());
        assert!(real.to_string().contains("18.6 s saved"), "{real}");
        // Spending more than the estimate is said as such, not as a negative saving.
        let slower = ArmTime {
            moving_s: 30.0,
            settling_s: 8.0,
            ..instant
        };
        let text = slower.to_string();
        assert!(
            text.contains("9.4 s more than the full plan (33 %)") && !text.contains("saved"),
            "{text}"
        );
    }
}
