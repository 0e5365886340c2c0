//! The adaptive plan of a cell with several cameras: the next-best pose scored over every
//! camera, and a stop that waits for every camera.
//!
//! Each camera has its own next-best-view model (`plan::nbv::AdaptivePlanner`: its setup, its
//! mount and board as solved from its own samples so far, its noise) over the one candidate set
//! (the planner camera's checked candidates). A candidate's score is the sum, over the cameras
//! not yet good enough that are expected to see their board there (by the nominal cell), of each
//! one's expected information gain `ln(score now / score after)`, per second of arm time (the
//! move from where the arm stands, as for one camera). The run stops when every camera has met
//! the target 1-sigma with the stop check's agreement (held-out error, rotation spread: what its
//! verdict would call GOOD), at the plan's most poses, or when the candidates run out.

use handeye_core::geometry::Pose;
use handeye_core::setup::PosePair;
use handeye_robot::Joints;

use crate::PlanSource;
use handeye_plan::nbv::{AdaptivePlanner, AdaptiveStep};

/// The next-best pose over several cameras.
pub struct RigPlanner {
    /// One model per camera, the planner camera's first (its log is the run's), over the same
    /// candidates.
    planners: Vec<AdaptivePlanner>,
    /// Per camera, per candidate: whether it is expected to see its board there.
    sees: Vec<Vec<bool>>,
    /// The most poses the plan may take.
    max_poses: usize,
}

impl RigPlanner {
    /// A planner over the cameras' `planners` (the planner camera's first, each over the same
    /// candidates, in the session's camera order) with, per camera and candidate, whether it
    /// sees its board there.
    pub fn new(
        planners: Vec<AdaptivePlanner>,
        sees: Vec<Vec<bool>>,
        max_poses: usize,
    ) -> RigPlanner {
        RigPlanner {
            planners,
            sees,
            max_poses,
        }
    }

    /// The planner camera's model (its log holds the run's choices).
    pub fn primary(&self) -> &AdaptivePlanner {
        &self.planners[0]
    }

    /// Whether every camera met its target.
    pub fn reached_target(&self) -> bool {
        self.planners.iter().all(AdaptivePlanner::reached_target)
    }
}

impl PlanSource for RigPlanner {
    fn next_pose(&mut self, all: &[Vec<PosePair>]) -> Option<(Pose, Joints)> {
        let assessed: Vec<(bool, Option<f64>)> = self
            .planners
            .iter_mut()
            .zip(all)
            .map(|(planner, samples)| planner.assess(samples))
            .collect();
        let done = self.reached_target() || self.planners[0].taken() >= self.max_poses;
        let choice = if done {
            None
        } else {
            // Only the cameras still short of their target weigh in.
            let gains: Vec<Vec<Option<f64>>> = self
                .planners
                .iter()
                .zip(all)
                .map(|(planner, samples)| {
                    if planner.reached_target() {
                        Vec::new()
                    } else {
                        planner.gains(samples)
                    }
                })
                .collect();
            let primary = &self.planners[0];
            (0..primary.candidates().len())
                .filter_map(|i| {
                    if !primary.is_free(i) {
                        return None;
                    }
                    let gain: f64 = gains
                        .iter()
                        .zip(&self.sees)
                        .filter(|(_, sees)| sees.get(i).copied().unwrap_or(false))
                        .filter_map(|(g, _)| g.get(i).copied().flatten())
                        .sum();
                    Some((i, gain / primary.seconds(i).max(1e-3)))
                })
                .max_by(|a, b| a.1.total_cmp(&b.1))
                .map(|(i, _)| i)
        };
        self.planners[0].log.push(AdaptiveStep {
            samples: all.first().map_or(0, Vec::len),
            solved_sigma_mm: assessed[0].1,
            chose: choice,
            predicted_sigma_mm: None,
        });
        let index = choice?;
        let mut pose = None;
        for planner in &mut self.planners {
            pose = Some(planner.take(index));
        }
        pose
    }

    fn visited(&mut self, poses: &[Pose]) {
        for planner in &mut self.planners {
            planner.mark_visited(poses);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use handeye_core::geometry::pose_from_rotvec;
    use handeye_core::setup::Setup;
    use handeye_solve::SolveOptions;
    use nalgebra::Vector3;

    /// A candidate seen by two cameras gains for both: with the same model for each, the
    /// choice over the cameras goes to the candidate the second camera alone sees, whichever
    /// the first camera alone would take; with the second camera blind everywhere, the choice
    /// is the first camera's own.
    #[test]
    fn the_choice_sums_the_gains_of_the_cameras_that_see_their_board() {
        let camera_mount =
            pose_from_rotvec(Vector3::new(0.03, -0.07, 0.04), Vector3::new(0.0, 0.0, 1.5));
        let target_mount = pose_from_rotvec(Vector3::new(0.6, 0.0, 0.0), Vector3::zeros());
        let down = pose_from_rotvec(
            Vector3::zeros(),
            Vector3::new(std::f64::consts::PI, 0.0, 0.0),
        );
        let at = |x: f64, rotation: Vector3<f64>| {
            pose_from_rotvec(Vector3::new(x, 0.0, 0.5), rotation) * down
        };
        let candidates: Vec<(Pose, Joints)> = [
            at(0.5, Vector3::new(0.0, 0.0, 1.0)),
            at(0.45, Vector3::new(0.5, 0.0, 0.0)),
            at(0.55, Vector3::new(0.0, 0.4, 0.2)),
        ]
        .into_iter()
        .map(|pose| (pose, Joints::zeros(6)))
        .collect();
        let planner = || {
            AdaptivePlanner::new(
                Setup::EyeInHand,
                camera_mount,
                target_mount,
                candidates.clone(),
                SolveOptions::default(),
                0.1,
                usize::MAX,
            )
        };
        let alone = planner().next(&[]).expect("a first pose");
        let first_alone = candidates
            .iter()
            .position(|(pose, _)| *pose == alone.0)
            .unwrap();
        let other = (first_alone + 1) % candidates.len();
        let choose = |second_sees: Vec<bool>| {
            let mut rig = RigPlanner::new(
                vec![planner(), planner()],
                vec![vec![true; 3], second_sees],
                10,
            );
            let (pose, _) = rig.next_pose(&[vec![], vec![]]).expect("a first pose");
            candidates.iter().position(|(p, _)| *p == pose).unwrap()
        };
        let mut only_other = vec![false; 3];
        only_other[other] = true;
        assert_eq!(choose(only_other), other, "the second camera's gain counts");
        assert_eq!(
            choose(vec![false; 3]),
            first_alone,
            "a blind camera adds nothing"
        );
    }
}
