//! The recorded robot: replays the flange poses a real arm measured during a calibration recorded
//! elsewhere (another robot, another tool), so those frames and poses run through the same
//! session code. It never moves anything.
//!
//! The poses file (`robot: {backend: recorded, poses: poses.yaml}` in a cell config):
//! ```yaml
//! # T_base_flange as the robot measured it at each frame, in frame order (m, rad)
//! T_base_flange:
//!   - {translation: [0.72, -0.03, 0.41], rotation_vector: [3.06, 0.004, 0.105]}
//!   - {translation: [..], quaternion: {w: .., x: .., y: .., z: ..}}
//! ```
//! Poses use the YAML pose form of `geometry::yaml`. A recorded arm has no joints: the plan of a
//! recorded cell is the recorded poses themselves and its "joints" are [`plan_joints`]`(i)`, which
//! carry the pose number in joint 0 (as `i` degrees, so plan tables and session manifests show
//! the pose number) so a move (or a retry) to plan pose `i` reports pose `i`.
//! Depends on `robot`, `geometry` and `yaml_file` only.

use std::path::Path;

use serde::{Deserialize, Serialize};

use handeye_core::atomic_file::write_atomic;
use handeye_core::geometry::{translation_distance, Pose, PoseYaml};
use handeye_core::yaml_file::{read_yaml, FileError};

use super::{Joints, MotionLimits, Robot, RobotError, RobotStatus};

/// The recorded-poses file as written.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RecordedPosesYaml {
    /// The measured flange poses, in frame order.
    #[serde(rename = "T_base_flange")]
    pub base_from_flange: Vec<PoseYaml>,
}

/// Reads a recorded-poses file.
pub fn load_recorded_poses(path: &Path) -> Result<Vec<Pose>, FileError> {
    let raw: RecordedPosesYaml = read_yaml(path)?;
    if raw.base_from_flange.is_empty() {
        return Err(FileError::Value {
            path: path.to_path_buf(),
            yaml_path: "T_base_flange".into(),
            problem: "no poses".into(),
        });
    }
    raw.base_from_flange
        .iter()
        .enumerate()
        .map(|(i, p)| {
            p.to_pose(&format!("T_base_flange[{i}]"))
                .map_err(|problem| FileError::Pose {
                    path: path.to_path_buf(),
                    problem,
                })
        })
        .collect()
}

/// Writes a recorded-poses file (atomically), with a comment saying what it holds.
pub fn save_recorded_poses(poses: &[Pose], path: &Path) -> Result<(), FileError> {
    let raw = RecordedPosesYaml {
        base_from_flange: poses.iter().map(PoseYaml::from_pose).collect(),
    };
    let text = format!(
        "# T_base_flange as the robot measured it at each frame, in frame order (m, rad)\n{}",
        serde_yaml_ng::to_string(&raw).expect("poses serialise")
    );
    write_atomic(path, text.as_bytes()).map_err(|source| FileError::Write {
        path: path.to_path_buf(),
        source,
    })
}

/// The plan "joints" of recorded pose `index`: `index` degrees in joint 0, zeros elsewhere.
pub fn plan_joints(index: usize) -> Joints {
    Joints::from([(index as f64).to_radians(), 0.0, 0.0, 0.0, 0.0, 0.0])
}

/// The recorded pose a [`plan_joints`] value names, if it names one.
fn pose_index(joints: &Joints) -> Option<usize> {
    let degrees = joints[0].to_degrees();
    let index = degrees.round();
    (index >= 0.0 && (degrees - index).abs() < 1e-6 && joints[1..].iter().all(|q| *q == 0.0))
        .then_some(index as usize)
}

/// A robot that reports recorded flange poses.
#[derive(Debug, Clone)]
pub struct RecordedRobot {
    poses: Vec<Pose>,
    current: Option<usize>,
}

impl RecordedRobot {
    /// A recorded robot over `poses` (frame order); it starts at no pose.
    pub fn new(poses: Vec<Pose>) -> RecordedRobot {
        RecordedRobot {
            poses,
            current: None,
        }
    }

    /// The pose it is at, if any move happened.
    pub fn current(&self) -> Option<usize> {
        self.current
    }
}

impl Robot for RecordedRobot {
    fn base_from_flange(&mut self) -> Result<Pose, RobotError> {
        self.current.map(|i| self.poses[i]).ok_or_else(|| {
            RobotError::Unreachable(
                "the recorded robot is at no recorded pose yet (no move)".into(),
            )
        })
    }

    fn joint_positions(&mut self) -> Result<Joints, RobotError> {
        Ok(plan_joints(self.current.unwrap_or(0)))
    }

    fn move_linear(
        &mut self,
        base_from_flange: &Pose,
        _limits: &MotionLimits,
    ) -> Result<(), RobotError> {
        // Only a recorded pose can be "reached": the one with the same pose (to 1 µm / 1 µrad).
        let index = self.poses.iter().position(|p| {
            translation_distance(p, base_from_flange) < 1e-6
                && p.rotation.angle_to(&base_from_flange.rotation) < 1e-6
        });
        match index {
            Some(i) => {
                self.current = Some(i);
                Ok(())
            }
            None => Err(RobotError::Unreachable(
                "the recorded robot can only visit its recorded poses".into(),
            )),
        }
    }

    fn move_joints(&mut self, joints: &Joints, _limits: &MotionLimits) -> Result<(), RobotError> {
        match pose_index(joints).filter(|i| *i < self.poses.len()) {
            Some(index) => {
                self.current = Some(index);
                Ok(())
            }
            None => Err(RobotError::Unreachable(format!(
                "the recorded robot holds {} poses; joints {joints:?} rad do not name one (expected [i°, 0, 0, 0, 0, 0])",
                self.poses.len()
            ))),
        }
    }

    fn stop(&mut self) -> Result<(), RobotError> {
        Ok(())
    }

    fn status(&mut self) -> Result<RobotStatus, RobotError> {
        Ok(RobotStatus::Ready)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Vector3;

    #[test]
    fn replays_recorded_poses_by_plan_index() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("poses.yaml");
        let poses: Vec<Pose> = (0..3)
            .map(|k| {
                handeye_core::geometry::pose_from_rotvec(
                    Vector3::new(0.1 * k as f64, 0.2, 0.3),
                    Vector3::new(0.0, 0.1 * k as f64, 3.0),
                )
            })
            .collect();
        save_recorded_poses(&poses, &path).unwrap();
        let loaded = load_recorded_poses(&path).unwrap();
        let mut robot = RecordedRobot::new(loaded);
        assert!(robot.base_from_flange().is_err(), "no pose before a move");
        let limits = MotionLimits::default();
        for k in [2, 0, 2] {
            robot.move_joints(&plan_joints(k), &limits).unwrap();
            let got = robot.base_from_flange().unwrap();
            assert!((got.translation.vector - poses[k].translation.vector).norm() < 1e-12);
            assert!(got.rotation.angle_to(&poses[k].rotation) < 1e-12);
        }
        assert!(robot.move_joints(&plan_joints(3), &limits).is_err());
        assert!(robot
            .move_joints(&Joints::from([0.5, 0.0, 0.0, 0.0, 0.0, 0.0]), &limits)
            .is_err());

        std::fs::write(
            &path,
            "T_base_flange:\n  - {translation: [0, 0], rotation_vector: [0, 0, 0]}\n",
        )
        .unwrap();
        let e = load_recorded_poses(&path).unwrap_err().to_string();
        assert!(
            e.contains("poses.yaml") && e.contains("T_base_flange[0]"),
            "{e}"
        );
    }
}
