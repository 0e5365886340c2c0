//! Taught joint waypoints on an arm with no model handeye knows (issue #26): `robot.model: none`
//! and the joint names of another make (the peer publishes and takes goals for `fr3_joint1..6`;
//! the kinematics inside it stay the simulated UR10e's, which handeye never learns), with a
//! taught plan — at each view the joints and the flange pose the arm reported there, the file a
//! hand-guided session writes (`taught-plan.yaml`). The run moves by FollowJointTrajectory
//! goals to the taught joints at the configured limits, the plan check uses the taught flange
//! poses, and the solve recovers the simulator's truth. A joint plan without taught flange
//! poses, and a generated plan, are refused before anything opens, naming file and field. The
//! whole way — hand-guided with no plan, then the session's taught plan replayed — runs on a
//! seven-joint arm (the peer's `--model franka`: Franka's published kinematics, `fr3_joint1..7`,
//! mounted where it reaches every view), and a seven-joint taught plan given to a six-joint arm
//! is refused by the plan check before anything moves.

use std::path::{Path, PathBuf};
use std::time::Duration;

use handeye_plan::Plan;
use handeye_robot::Joints;

use super::cell::{assert_truth, captures, cell, poses_kept, run_cell, text, views, Peer};
use super::python;
use crate::util::{ros_domain, within};

pub(super) const NAMES: &str = "fr3_joint1,fr3_joint2,fr3_joint3,fr3_joint4,fr3_joint5,fr3_joint6";

/// The seven joints of the peer's Franka arm (its default names).
const FRANKA_NAMES: &str =
    "fr3_joint1,fr3_joint2,fr3_joint3,fr3_joint4,fr3_joint5,fr3_joint6,fr3_joint7";
/// Franka's datasheet joint ranges, degrees.
const FRANKA_RANGES_DEG: &str =
    "[[-166, 166], [-101, 101], [-166, 166], [-176, -4], [-166, 166], [-1, 215], [-166, 166]]";

/// The ROS 2 cell as an arm of no known model with `plan` under `plan:` (a YAML line).
pub(super) fn no_model_cell(dir: &Path, domain: u16, plan: &str) -> PathBuf {
    // The arm's own joint ranges, as its datasheet gives them (here: every joint ±360°).
    let ranges = "[[-360, 360], [-360, 360], [-360, 360], [-360, 360], [-360, 360], [-360, 360]]";
    arm_cell(dir, domain, plan, "none", NAMES, ranges)
}

/// The ROS 2 cell of `model` (`none` or a UR) with these joint names and ranges and `plan`.
fn arm_cell(
    dir: &Path,
    domain: u16,
    plan: &str,
    model: &str,
    names: &str,
    ranges: &str,
) -> PathBuf {
    let model = format!(
        "model: {model}\n  joint_names: [{}]\n  joint_ranges_deg: {ranges}",
        names.replace(',', ", "),
    );
    cell(
        dir,
        domain,
        &[
            ("model: ur10e", &model),
            (
                "  generate: {count: 12, distance: [0.55, 0.75], max_tilt_deg: 30, max_roll_deg: 20, seed: 1}",
                plan,
            ),
        ],
    )
}

/// The rendered views as a taught plan (the joints each stood at, the flange pose the arm
/// reported there), written to `dir/taught.yaml`.
fn taught_plan(dir: &Path) -> PathBuf {
    let poses: Vec<_> = captures(&views())
        .into_iter()
        .map(|(_, pose, deg)| (pose, Joints::from_fn(deg.len(), |i| deg[i].to_radians())))
        .collect();
    let file = dir.join("taught.yaml");
    Plan::taught(&poses).save(&file).unwrap();
    file
}

#[test]
fn a_taught_plan_runs_on_an_arm_of_no_known_model_and_recovers_the_truth() {
    let Some(python) = python() else { return };
    within(Duration::from_secs(500), move || {
        let dir = tempfile::tempdir().unwrap();
        taught_plan(dir.path());
        let domain = ros_domain();
        let peer = Peer::serving(&python, domain, &views(), &["--joint-names", NAMES]);
        let config = no_model_cell(dir.path(), domain, "  file: taught.yaml");
        let session = dir.path().join("session");
        let out = run_cell(&config, &session);
        let log = text(&out);
        assert!(out.status.success(), "{log}");
        assert!(
            log.contains("robot.model: none"),
            "the plan check says what it could not check:\n{log}"
        );
        // One goal per taught view, each for the configured joints, within 60 °/s.
        for g in peer.assert_served(captures(&views()).len()) {
            assert_eq!(g["accepted"], true, "{g}");
            assert_eq!(
                g["joint_names"],
                serde_json::json!(NAMES.split(',').collect::<Vec<_>>())
            );
        }
        assert_truth(&session);
    });
}

/// The whole way for a seven-joint arm of no known model (a Franka): hand-guided on the console
/// with no plan (`plan: {manual: true}`, no suggestions), its `taught-plan.yaml` — seven joints
/// per view — then replayed by `handeye run` — trajectory goals for the seven joints to the
/// taught ones — to the truth.
#[test]
fn a_seven_joint_arm_is_hand_guided_and_its_taught_plan_replays_to_the_truth() {
    let Some(python) = python() else { return };
    within(Duration::from_secs(700), move || {
        let dir = tempfile::tempdir().unwrap();
        let domain = ros_domain();
        let mut peer = Peer::serving(&python, domain, &views(), &["--model", "franka"]);
        let franka = |plan: &str| {
            arm_cell(
                dir.path(),
                domain,
                plan,
                "none",
                FRANKA_NAMES,
                FRANKA_RANGES_DEG,
            )
        };
        let config = franka("  manual: true");
        let session = super::console::hand_guided_session(dir.path(), &mut peer, &config, false);
        // (hand_guided_session checks each capture's joints against the peer's arm's, and the
        // taught plan against the captures.)
        assert!(captures(&session).iter().all(|(_, _, q)| q.len() == 7));
        let taught = session.join("taught-plan.yaml");
        let config = franka(&format!("  file: {}", taught.display()));
        let replay = dir.path().join("replay");
        let out = run_cell(&config, &replay);
        assert!(out.status.success(), "{}", text(&out));
        // Every taught view visited; the arm stood at the last one captured, which the
        // travel-time order visits first, with no move: one goal fewer than views.
        let views = captures(&views()).len();
        assert_eq!(poses_kept(&replay), views);
        for g in peer.assert_served(views - 1) {
            assert_eq!(g["accepted"], true, "{g}");
            assert_eq!(
                g["joint_names"],
                serde_json::json!(FRANKA_NAMES.split(',').collect::<Vec<_>>())
            );
        }
        assert!(captures(&replay).iter().all(|(_, _, q)| q.len() == 7));
        assert_truth(&replay);
    });
}

/// A plan taught on a seven-joint arm, given to a six-joint UR: the plan check refuses every
/// pose, saying the joint counts, and nothing opens.
#[test]
fn a_seven_joint_plan_is_refused_on_a_six_joint_arm() {
    let dir = tempfile::tempdir().unwrap();
    within(Duration::from_secs(60), move || {
        std::fs::write(
            dir.path().join("seven.yaml"),
            "waypoints:\n- joints_deg: [40, -37, -30, -132, -17, 90, -83]\n  T_base_flange: {translation: [0.75, 0.05, 0.61], rotation_vector: [3.1, 0, 0]}\n",
        )
        .unwrap();
        let ranges =
            "[[-360, 360], [-360, 360], [-180, 180], [-360, 360], [-360, 360], [-360, 360]]";
        let config = arm_cell(
            dir.path(),
            ros_domain(),
            "  file: seven.yaml",
            "ur10e",
            &handeye_config::ros2::UR_DRIVER_JOINT_NAMES.join(","),
            ranges,
        );
        let session = dir.path().join("s");
        let out = run_cell(&config, &session);
        let log = text(&out);
        assert!(!out.status.success(), "{log}");
        assert!(
            log.contains("7 joints named, but the arm has 6"),
            "the count is said:\n{log}"
        );
        assert!(!session.exists(), "the session was created:\n{log}");
    });
}

#[test]
fn without_a_model_untaught_plans_are_refused_naming_file_and_field() {
    let dir = tempfile::tempdir().unwrap();
    within(Duration::from_secs(60), move || {
        // `handeye run` of `config` into `session` fails before anything opens, saying `words`.
        let refused = |config: &Path, session: &str, words: &[&str]| {
            let out = run_cell(config, &dir.path().join(session));
            let log = text(&out);
            assert!(!out.status.success(), "{log}");
            assert!(
                words.iter().all(|w| log.contains(w)),
                "{words:?} in:\n{log}"
            );
            assert!(!dir.path().join(session).exists(), "{session} was created");
        };
        // Joints without the flange pose taught there.
        std::fs::write(
            dir.path().join("joints.yaml"),
            "waypoints:\n- {joints_deg: [0, -90, 90, -90, -90, 0]}\n",
        )
        .unwrap();
        let domain = ros_domain();
        let config = no_model_cell(dir.path(), domain, "  file: joints.yaml");
        refused(
            &config,
            "s",
            &[
                "joints.yaml",
                "waypoints[0].T_base_flange",
                "robot.model is none",
            ],
        );
        // Generated views need kinematics too.
        let config = no_model_cell(
            dir.path(),
            domain,
            "  generate: {count: 12, distance: [0.55, 0.75], max_tilt_deg: 30, max_roll_deg: 20, seed: 1}",
        );
        refused(&config, "s2", &["ros2-cell.yaml", "plan.generate"]);
        // An arm of no known model must name its joint ranges.
        let yaml = std::fs::read_to_string(&config).unwrap();
        let (before, after) = yaml.split_once("  joint_ranges_deg:").unwrap();
        let rest = after.split_once('\n').unwrap().1;
        std::fs::write(&config, format!("{before}{rest}")).unwrap();
        refused(&config, "s3", &["ros2-cell.yaml", "robot.joint_ranges_deg"]);
    });
}
