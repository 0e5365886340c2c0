//! Pose plans: where the arm goes to take each calibration frame.
//!
//! A plan is a list of waypoints, each a flange pose (`T_base_flange`), a joint configuration, or a
//! [`LookAt`] view relative to the board. Plans are scripted in YAML or generated on a spherical cap
//! around the board ([`generate`]); [`check`] validates a plan before anything moves.
//!
//! Frames: look-at views give `T_target_camera`; with the cell's nominal (expected) transforms they
//! become flange poses through the setup's chain (see [`CellTransforms`]).

pub mod check;
pub mod generate;
pub mod lookat;
pub mod nbv;
pub mod order;

use std::path::{Path, PathBuf};

use nalgebra::Point3;
use serde::{Deserialize, Serialize};

use handeye_core::geometry::{Pose, PoseError, PoseYaml};
use handeye_core::setup::CellTransforms;
use handeye_core::yaml_file::{parse_yaml, read_text, FileError};
use handeye_robot::{Joints, MAX_JOINTS};

pub use generate::{generate, GenerateSpec, GenerateSpecError};

/// The most poses a plan may have (scripted or generated): a thorough calibration takes tens;
/// more is a typo, and every pose is checked, planned and (in the sim) rendered.
pub const MAX_PLAN_POSES: usize = 1000;
pub use lookat::LookAt;

/// One place to take a frame.
#[derive(Debug, Clone, PartialEq)]
pub enum Waypoint {
    /// A flange pose in the base frame.
    FlangePose(Pose),
    /// A joint configuration, radians.
    Joints(Joints),
    /// A taught pose: the joints a person guided the arm to (radians) and the flange pose
    /// `T_base_flange` the arm reported there (TF on ROS 2). The arm moves to the joints; the
    /// plan check uses the taught pose, so an arm with no kinematics handeye knows can replay
    /// it. YAML: `joints_deg` and `T_base_flange` together.
    Taught {
        /// The joints, radians.
        joints: Joints,
        /// `T_base_flange` as the arm reported it at those joints.
        base_from_flange: Pose,
    },
    /// A view of the board.
    LookAt(LookAt),
}

/// A scripted plan: the waypoints in order.
#[derive(Debug, Clone, PartialEq)]
pub struct Plan {
    /// Waypoints in the order the arm visits them.
    pub waypoints: Vec<Waypoint>,
}

/// Why a plan could not be read or is not safe to run.
#[derive(Debug, thiserror::Error)]
pub enum PlanError {
    /// The plan file could not be read, or its YAML does not have the plan's shape.
    #[error(transparent)]
    File(#[from] FileError),
    /// A waypoint's values are wrong.
    #[error("{file}: {path}: {problem}")]
    Waypoint {
        /// The plan file.
        file: PathBuf,
        /// YAML path of the waypoint.
        path: String,
        /// What is wrong.
        problem: String,
    },
    /// A flange pose in the plan is malformed.
    // The pose problem is the message itself, so it is not also a `#[source]` (a `{:#}` chain
    // would print it twice).
    #[error("{}: {problem}", file.display())]
    Pose {
        /// The plan file.
        file: PathBuf,
        /// The pose problem, with its YAML path.
        problem: PoseError,
    },
    /// The plan has no waypoints.
    #[error("{0}: the plan has no waypoints (expected a list under `waypoints`)")]
    Empty(PathBuf),
    /// The plan has more waypoints than [`MAX_PLAN_POSES`].
    #[error("{}: waypoints: expected at most {max} waypoints, found {found}", file.display())]
    TooLarge {
        /// The plan file.
        file: PathBuf,
        /// How many it has.
        found: usize,
        /// The limit.
        max: usize,
    },
    /// Writing the plan failed.
    #[error("cannot write plan {file}")]
    Write {
        /// The destination.
        file: PathBuf,
        /// The I/O error.
        #[source]
        source: std::io::Error,
    },
}

#[derive(Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct PlanFile {
    waypoints: Vec<WaypointYaml>,
}

#[derive(Debug, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct WaypointYaml {
    #[serde(
        rename = "T_base_flange",
        default,
        skip_serializing_if = "Option::is_none"
    )]
    base_from_flange: Option<PoseYaml>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    joints_deg: Option<Vec<f64>>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    look_at: Option<LookAt>,
}

impl Plan {
    /// Reads a scripted plan from YAML, naming file and YAML path in every error.
    pub fn load(file: &Path) -> Result<Plan, PlanError> {
        Self::parse(&read_text(file)?, file)
    }

    /// Parses plan YAML; `file` is used in messages only.
    pub fn parse(text: &str, file: &Path) -> Result<Plan, PlanError> {
        let raw: PlanFile = parse_yaml(text, file)?;
        if raw.waypoints.is_empty() {
            return Err(PlanError::Empty(file.to_path_buf()));
        }
        if raw.waypoints.len() > MAX_PLAN_POSES {
            return Err(PlanError::TooLarge {
                file: file.to_path_buf(),
                found: raw.waypoints.len(),
                max: MAX_PLAN_POSES,
            });
        }
        let waypoints = raw
            .waypoints
            .iter()
            .enumerate()
            .map(|(i, w)| w.to_waypoint(&format!("waypoints[{i}]"), file))
            .collect::<Result<Vec<_>, _>>()?;
        Ok(Plan { waypoints })
    }

    /// The plan as plan-file YAML ([`Plan::load`] reads it back).
    pub fn to_yaml(&self) -> String {
        let raw = PlanFile {
            waypoints: self
                .waypoints
                .iter()
                .map(WaypointYaml::from_waypoint)
                .collect(),
        };
        serde_yaml_ng::to_string(&raw).expect("plan serialises")
    }

    /// Writes the plan as YAML (atomically).
    pub fn save(&self, file: &Path) -> Result<(), PlanError> {
        let text = self.to_yaml();
        handeye_core::atomic_file::write_atomic(file, text.as_bytes()).map_err(|source| {
            PlanError::Write {
                file: file.to_path_buf(),
                source,
            }
        })
    }
}

/// `joints_deg` as radians, or what is wrong with it (its key first).
fn joints_from_degrees(joints: &[f64]) -> Result<Joints, String> {
    if !(1..=MAX_JOINTS).contains(&joints.len()) {
        return Err(format!(
            "joints_deg: expected one angle in degrees per joint of the arm (six on a UR, seven on a Franka or a KUKA iiwa), found {}",
            joints.len()
        ));
    }
    // Joints turn ±360° at most; anything else is a typo or radians mistaken for degrees.
    if let Some((i, bad)) = joints
        .iter()
        .enumerate()
        .find(|(_, v)| !(v.is_finite() && v.abs() <= 360.0))
    {
        return Err(format!(
            "joints_deg[{i}]: expected a value in [-360, 360] °, found {bad}"
        ));
    }
    Ok(Joints::from_fn(joints.len(), |i| joints[i].to_radians()))
}

impl WaypointYaml {
    fn to_waypoint(&self, path: &str, file: &Path) -> Result<Waypoint, PlanError> {
        let problem = |problem: String| PlanError::Waypoint {
            file: file.to_path_buf(),
            path: path.to_string(),
            problem,
        };
        let given = [
            self.base_from_flange.is_some(),
            self.joints_deg.is_some(),
            self.look_at.is_some(),
        ]
        .iter()
        .filter(|g| **g)
        .count();
        let taught = self.base_from_flange.is_some() && self.joints_deg.is_some();
        if given != 1 && !(given == 2 && taught) {
            return Err(problem(format!(
                "expected exactly one of `T_base_flange`, `joints_deg`, `look_at` (or `joints_deg` with the `T_base_flange` taught there); found {given}"
            )));
        }
        let base_from_flange = self
            .base_from_flange
            .as_ref()
            .map(|pose| {
                pose.to_pose(&format!("{path}.T_base_flange"))
                    .map_err(|problem| PlanError::Pose {
                        file: file.to_path_buf(),
                        problem,
                    })
            })
            .transpose()?;
        let joints = self
            .joints_deg
            .as_deref()
            .map(|joints| joints_from_degrees(joints).map_err(problem))
            .transpose()?;
        match (joints, base_from_flange) {
            (Some(joints), Some(base_from_flange)) => {
                return Ok(Waypoint::Taught {
                    joints,
                    base_from_flange,
                })
            }
            (Some(joints), None) => return Ok(Waypoint::Joints(joints)),
            (None, Some(pose)) => return Ok(Waypoint::FlangePose(pose)),
            (None, None) => {}
        }
        let Some(view) = self.look_at else {
            return Err(problem(
                "expected exactly one of `joints_deg` or `look_at`".to_string(),
            ));
        };
        view.validate()
            .map_err(|m| problem(format!("look_at: {m}")))?;
        Ok(Waypoint::LookAt(view))
    }

    fn from_waypoint(waypoint: &Waypoint) -> Self {
        match waypoint {
            Waypoint::FlangePose(p) => WaypointYaml {
                base_from_flange: Some(PoseYaml::from_pose(p)),
                ..Default::default()
            },
            Waypoint::Joints(q) => WaypointYaml {
                joints_deg: Some(q.iter().map(|v| v.to_degrees()).collect()),
                ..Default::default()
            },
            Waypoint::Taught {
                joints,
                base_from_flange,
            } => WaypointYaml {
                base_from_flange: Some(PoseYaml::from_pose(base_from_flange)),
                joints_deg: Some(joints.iter().map(|v| v.to_degrees()).collect()),
                ..Default::default()
            },
            Waypoint::LookAt(v) => WaypointYaml {
                look_at: Some(*v),
                ..Default::default()
            },
        }
    }
}

impl Waypoint {
    /// The flange pose `T_base_flange` this waypoint asks for in `cell` (joint waypoints go
    /// through forward kinematics — `None` when `forward` has none —, look-at views through the
    /// cell's nominal transforms, taught ones are where the arm reported it stood).
    pub fn flange_pose(
        &self,
        cell: &CellTransforms,
        board_centre: &Point3<f64>,
        forward: impl Fn(&Joints) -> Option<Pose>,
    ) -> Option<Pose> {
        Some(match self {
            Waypoint::FlangePose(p) => *p,
            Waypoint::Taught {
                base_from_flange, ..
            } => *base_from_flange,
            Waypoint::Joints(q) => forward(q)?,
            Waypoint::LookAt(view) => {
                cell.base_from_flange_for_view(&view.target_from_camera(board_centre))
            }
        })
    }

    /// The joints this waypoint names (joint and taught waypoints), radians.
    pub fn joints(&self) -> Option<Joints> {
        match self {
            Waypoint::Joints(q) | Waypoint::Taught { joints: q, .. } => Some(*q),
            Waypoint::FlangePose(_) | Waypoint::LookAt(_) => None,
        }
    }

    /// What an arm without kinematics cannot run of this waypoint (its YAML key and why), or
    /// `None` for a taught waypoint.
    pub fn needs_kinematics(&self) -> Option<(&'static str, &'static str)> {
        match self {
            Waypoint::Taught { .. } => None,
            Waypoint::Joints(_) => Some((
                "T_base_flange",
                "a joint waypoint needs the flange pose taught with it (`T_base_flange` beside `joints_deg`): without the arm's kinematics the plan check cannot know where these joints put the flange",
            )),
            Waypoint::FlangePose(_) => Some((
                "joints_deg",
                "a flange pose needs the arm's kinematics to become joints: give the joints taught there (`joints_deg` beside `T_base_flange`)",
            )),
            Waypoint::LookAt(_) => Some((
                "look_at",
                "a look-at view needs the arm's kinematics to become joints: teach the view by hand (`handeye console`) and use the session's taught plan",
            )),
        }
    }
}

impl Plan {
    /// A taught plan: each (flange pose, joints) a hand-guided session captured, in order.
    pub fn taught(poses: &[(Pose, Joints)]) -> Plan {
        Plan {
            waypoints: poses
                .iter()
                .map(|(base_from_flange, joints)| Waypoint::Taught {
                    joints: *joints,
                    base_from_flange: *base_from_flange,
                })
                .collect(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use handeye_core::setup::Setup;
    use nalgebra::{Translation3, UnitQuaternion};

    fn parse(text: &str) -> Result<Plan, PlanError> {
        Plan::parse(text, Path::new("plan.yaml"))
    }

    #[test]
    fn reads_all_waypoint_kinds_and_round_trips() {
        let plan = parse(
            "waypoints:\n\
             - T_base_flange: {translation: [0.4, 0.1, 0.5], rotation_vector: [3.1, 0.1, 0]}\n\
             - joints_deg: [0, -90, 90, -90, -90, 0]\n\
             - look_at: {distance: 0.6, azimuth_deg: 30, elevation_deg: 70, roll_deg: 10}\n",
        )
        .unwrap();
        assert_eq!(plan.waypoints.len(), 3);
        let dir = tempfile::tempdir().unwrap();
        let file = dir.path().join("plan.yaml");
        plan.save(&file).unwrap();
        let back = Plan::load(&file).unwrap();
        match (&plan.waypoints[0], &back.waypoints[0]) {
            (Waypoint::FlangePose(a), Waypoint::FlangePose(b)) => {
                assert!(a.rotation.angle_to(&b.rotation) < 1e-12)
            }
            _ => panic!("kind changed"),
        }
        match (&plan.waypoints[1], &back.waypoints[1]) {
            (Waypoint::Joints(a), Waypoint::Joints(b)) => {
                assert!(a.iter().zip(b).all(|(x, y)| (x - y).abs() < 1e-12))
            }
            _ => panic!("kind changed"),
        }
        assert_eq!(plan.waypoints[2], back.waypoints[2]);
    }

    #[test]
    fn taught_waypoints_read_and_round_trip_and_say_what_needs_kinematics() {
        let plan = parse(
            "waypoints:\n\
             - joints_deg: [10, -80, 95, -100, -90, 5]\n  \
               T_base_flange: {translation: [0.4, 0.1, 0.5], rotation_vector: [3.1, 0.1, 0]}\n",
        )
        .unwrap();
        let Waypoint::Taught {
            joints,
            base_from_flange,
        } = plan.waypoints[0]
        else {
            panic!("not taught: {:?}", plan.waypoints[0])
        };
        assert!((joints[1] - (-80f64).to_radians()).abs() < 1e-12);
        assert!((base_from_flange.translation.vector.x - 0.4).abs() < 1e-12);
        assert_eq!(plan.waypoints[0].needs_kinematics(), None);
        let back = parse(&Plan::taught(&[(base_from_flange, joints)]).to_yaml()).unwrap();
        let Waypoint::Taught {
            joints: joints_back,
            base_from_flange: pose_back,
        } = back.waypoints[0]
        else {
            panic!("not taught after a round trip: {:?}", back.waypoints[0])
        };
        assert!(joints
            .iter()
            .zip(&joints_back)
            .all(|(a, b)| (a - b).abs() < 1e-12));
        assert!((pose_back.to_homogeneous() - base_from_flange.to_homogeneous()).norm() < 1e-12);
        let bad = parse(
            "waypoints:\n- {joints_deg: [0, 0, 0, 0, 0, 0, 0, 0], T_base_flange: {translation: [0, 0, 0], rotation_vector: [0, 0, 0]}}\n",
        )
        .unwrap_err()
        .to_string();
        assert!(
            bad.contains("waypoints[0]: joints_deg: expected one angle in degrees per joint of the arm (six on a UR, seven on a Franka or a KUKA iiwa), found 8"),
            "{bad}"
        );
        let joints_only = parse("waypoints:\n- {joints_deg: [0, -90, 90, -90, -90, 0]}\n").unwrap();
        assert_eq!(
            joints_only.waypoints[0]
                .needs_kinematics()
                .map(|(key, _)| key),
            Some("T_base_flange")
        );
    }

    #[test]
    fn a_seven_joint_taught_plan_reads_and_round_trips() {
        let plan = parse(
            "waypoints:\n- joints_deg: [0, -30, 0, -120, 0, 90, 45]\n  T_base_flange: {translation: [0.4, 0, 0.5], rotation_vector: [3.14, 0, 0]}\n",
        )
        .unwrap();
        let joints = plan.waypoints[0].joints().unwrap();
        assert_eq!(joints.len(), 7);
        assert!((joints[6] - 45f64.to_radians()).abs() < 1e-12);
        let back = parse(&plan.to_yaml()).unwrap();
        assert_eq!(back.waypoints[0].joints(), Some(joints));
    }

    #[test]
    fn malformed_plans_get_clear_errors() {
        let cases = [
            ("waypoints: []", "no waypoints"),
            ("waypoints:\n- {joints_deg: []}", "plan.yaml: waypoints[0]: joints_deg: expected one angle in degrees per joint of the arm"),
            ("waypoints:\n- {look_at: {distance: 0.5, azimuth_deg: 0, elevation_deg: 0}}", "waypoints[0]: look_at: elevation_deg must be in (0, 90]"),
            ("waypoints:\n- {look_at: {distance: -1, azimuth_deg: 0, elevation_deg: 80}}", "distance must be a positive"),
            ("waypoints:\n- {joints_deg: [0,0,0,0,0,0], look_at: {distance: 0.5, azimuth_deg: 0, elevation_deg: 80}}", "exactly one of"),
            ("waypoints:\n- {}\n", "found 0"),
            ("waypoints:\n- {joints_deg: [0, -90, 90, -90, 7200, 0]}", "plan.yaml: waypoints[0]: joints_deg[4]: expected a value in [-360, 360] °, found 7200"),
            ("waypoints:\n- {T_base_flange: {translation: [0, 0], rotation_vector: [0, 0, 0]}}", "waypoints[0].T_base_flange.translation: expected 3 numbers"),
            ("waypoints:\n- {look_at: {distance: 0.5, azimuth: 0, elevation_deg: 80}}", "waypoints[0].look_at"),
            ("waypoint: []", "unknown field `waypoint`"),
        ];
        for (text, expected) in cases {
            let message = match parse(text) {
                Ok(_) => panic!("{text:?} was accepted"),
                Err(e) => e.to_string(),
            };
            assert!(message.contains(expected), "{text:?} gave {message:?}");
        }
    }

    #[test]
    fn plans_larger_than_the_limit_are_refused() {
        let waypoints = |n: usize| {
            let mut text = String::from("waypoints:\n");
            for _ in 0..n {
                text.push_str("- {joints_deg: [0, -90, 90, -90, -90, 0]}\n");
            }
            text
        };
        assert_eq!(
            parse(&waypoints(MAX_PLAN_POSES)).unwrap().waypoints.len(),
            MAX_PLAN_POSES
        );
        let message = parse(&waypoints(MAX_PLAN_POSES + 1))
            .unwrap_err()
            .to_string();
        assert_eq!(
            message,
            "plan.yaml: waypoints: expected at most 1000 waypoints, found 1001"
        );
    }

    #[test]
    fn views_become_flange_poses_that_show_the_same_view_in_both_setups() {
        let centre = Point3::new(0.14, 0.14, 0.0);
        let view = LookAt {
            distance: 0.55,
            azimuth_deg: 40.0,
            elevation_deg: 65.0,
            roll_deg: 15.0,
            board_in_image_deg: [0.0, 0.0],
        };
        let target_from_camera = view.target_from_camera(&centre);
        for setup in [Setup::EyeInHand, Setup::EyeToHand] {
            let cell = CellTransforms {
                setup,
                camera_mount: Pose::from_parts(
                    Translation3::new(0.03, -0.05, 0.08),
                    UnitQuaternion::from_euler_angles(0.1, -0.2, 1.5),
                ),
                target_mount: Pose::from_parts(
                    Translation3::new(0.5, 0.1, 0.02),
                    UnitQuaternion::from_euler_angles(0.0, 0.05, 0.3),
                ),
            };
            let base_from_flange = cell.base_from_flange_for_view(&target_from_camera);
            let seen = cell.camera_from_target(&base_from_flange);
            let expected = target_from_camera.inverse();
            assert!(seen.rotation.angle_to(&expected.rotation) < 1e-12);
            assert!((seen.translation.vector - expected.translation.vector).norm() < 1e-12);
        }
    }
}
