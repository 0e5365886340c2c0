//! The console over ROS 2 (issue #26), driven from its WebSocket as the page drives it (no
//! browser), against the independent peer.
//!
//! Hand-guided capture: `handeye console` of configs/ros2-sim-cell.yaml
//! against the independent peer, driven from the console's WebSocket as the page drives it (no
//! browser). With `robot.freedrive`, the page's freedrive switches the UR driver's controllers
//! (the peer serves them as ur_robot_driver does, and refuses to be guided out of freedrive);
//! without it (an arm of no known model, `taught.rs`), freedrive is answered with how to
//! hand-guide the arm instead, and the session goes on. The peer's arm is then "hand-guided" to
//! each view (its `guide K` command: a joint path with no trajectory goal, as a person would);
//! without freedrive switching every other capture is asked for while the arm still moves. Each
//! capture must be taken where the arm came to rest (joints from /joint_states, `T_base_flange`
//! from TF, a frame stamped after it stood still), the session's taught plan holds them, and the
//! solve recovers the simulator's truth.
//!
//! STOP: pressing it during a planned ROS 2 run cancels the running trajectory goal (the peer
//! sees the cancel), the samples so far are kept, and `--resume` completes the run.

use std::path::{Path, PathBuf};
use std::time::Duration;

use handeye_plan::{Plan, Waypoint};

use super::cell::{
    assert_truth, captures, cell, mid_long_goal, poses_kept, run, text, views, Peer,
};
use super::python;
use crate::util::live::{runtime, Live, Page};
use crate::util::{handeye, ros_domain, within};

/// `handeye ARGS CONFIG OUT_FLAG SESSION` in `dir`, serving the console (DDS logs quiet).
fn serving_console(
    dir: &Path,
    args: &[&str],
    config: &Path,
    out_flag: &[&str],
    session: &Path,
) -> Live {
    Live::spawn(
        handeye()
            .args(args)
            .arg(config)
            .args(out_flag)
            .arg(session)
            .env("HANDEYE_LOG", "warn,rustdds=off")
            .current_dir(dir),
    )
}

/// A UR arm under the UR driver, freedrive switched from the page: every switch strict and
/// answered, the arm under the motion controller again when the session ends.
#[test]
fn a_hand_guided_console_session_with_freedrive_over_ros2_recovers_the_truth() {
    let Some(python) = python() else { return };
    within(Duration::from_secs(600), move || {
        let dir = tempfile::tempdir().unwrap();
        let domain = ros_domain();
        let mut peer = Peer::start(&python, domain, &["--freedrive", "jazzy"]);
        let config = cell(
            dir.path(),
            domain,
            &[(
                "  flange_frame: tool0",
                "  flange_frame: tool0\n  freedrive: {distro: jazzy}",
            )],
        );
        hand_guided_session(dir.path(), &mut peer, &config, true);
        let switches = peer.events("switch");
        assert!(switches.len() >= 2, "{switches:?}");
        for s in &switches {
            assert_eq!(
                (&s["ok"], &s["strictness"]),
                (&true.into(), &2.into()),
                "{s}"
            );
        }
        let motion = "scaled_joint_trajectory_controller";
        assert_eq!(switches[0]["activate"][0], "freedrive_mode_controller");
        assert_eq!(switches[0]["deactivate"][0], motion);
        let last = switches.last().unwrap();
        assert_eq!(last["active"], serde_json::json!([motion]), "{switches:?}");
        assert!(peer.events("bad_command").is_empty());
        assert!(peer
            .events("freedrive")
            .iter()
            .all(|e| e["why"] != "keep-alive timeout"));
    });
}

/// A hand-guided session of `config` on the console into `dir/guided`, every rendered view
/// captured by hand (the checks above), solved to the truth; the session folder. `freedrive`:
/// the page switches it on and the arm is let go at each view before the capture (which switches
/// freedrive off while it takes the sample); otherwise the page is told how to hand-guide.
pub(super) fn hand_guided_session(
    dir: &Path,
    peer: &mut Peer,
    config: &Path,
    freedrive: bool,
) -> PathBuf {
    {
        let session = dir.join("guided");
        let mut live = serving_console(
            dir,
            &["console", "--addr", "127.0.0.1:0", "--config"],
            config,
            &["--output"],
            &session,
        );
        let url = live.url();
        let rendered = captures(&views());
        let verdict = runtime().block_on(async {
            let mut page = Page::open(&url).await;
            page.send_json(serde_json::json!({"cmd": "freedrive", "on": true}))
                .await;
            let check = page.next("check").await;
            let message = check["message"].as_str().unwrap_or_default();
            if freedrive {
                assert_eq!(check["ok"], true, "{check}");
                peer.wait_for_one("freedrive", Duration::from_secs(10), |e| e["on"] == true);
            } else {
                // Freedrive is not switched on this arm: the answer says how to hand-guide.
                assert_eq!(check["ok"], false, "{check}");
                assert!(
                    message.contains("teach pendant") && message.contains("capture"),
                    "{message}"
                );
            }
            for (n, &(k, ..)) in rendered.iter().enumerate() {
                if freedrive {
                    // The capture before switched freedrive off for the sample and then on
                    // again: the person guides once the arm is free again.
                    let on = || {
                        peer.events("freedrive")
                            .iter()
                            .filter(|e| e["on"] == true)
                            .count()
                    };
                    let end = std::time::Instant::now() + Duration::from_secs(10);
                    while on() < n + 1 && std::time::Instant::now() < end {
                        tokio::time::sleep(Duration::from_millis(20)).await;
                    }
                    assert_eq!(on(), n + 1, "freedrive is not back on after capture {n}");
                }
                peer.guide(k);
                let limit = Duration::from_secs(30);
                // The last view too: the arm then stands where it was captured, as a replay of
                // the taught plan expects (one goal fewer than views). Captured near the end of
                // a move still slowing, its joints are a hair from where the arm comes to rest.
                if freedrive || n % 2 == 0 || n + 1 == rendered.len() {
                    // Let go at the view: the arm stands still when the capture is asked for.
                    peer.wait_for_one("guided", limit, |e| e["k"] == k);
                } else {
                    // Asked for while the arm still moves (the move takes 1.5 s): the capture
                    // must wait for /joint_states to show it still.
                    peer.wait_for_one("guiding", limit, |e| e["k"] == k);
                    tokio::time::sleep(Duration::from_millis(200)).await;
                    assert!(
                        peer.events("guided").iter().all(|e| e["k"] != k),
                        "the arm arrived before the capture was asked for"
                    );
                }
                page.send("capture").await;
                let check = page.next("check").await;
                assert_eq!(check["ok"], true, "capture at view {k}: {check}");
            }
            page.send("finish").await;
            page.next("finished").await
        });
        let (ok, out) = live.finish();
        assert!(ok, "the hand-guided session did not finish:\n{out}");
        assert!(
            peer.events("goal").is_empty(),
            "a trajectory goal was sent: {:?}",
            peer.events("goal")
        );
        // Each capture is where the arm came to rest at its view: the joints /joint_states gave
        // (the peer's arm's joints at that view: six on a UR, seven on its Franka) and the
        // flange pose TF gave there (the rendered session's record of that view).
        let got = captures(&session);
        assert_eq!(got.len(), rendered.len(), "{out}");
        let arm_joints = peer.wait_for("ready", Duration::from_secs(1))["plan_joints_deg"].clone();
        for ((_, pose, joints), (k, want_pose, _)) in got.iter().zip(&rendered) {
            let (mm, deg) = crate::util::pose_error_mm_deg(pose, want_pose);
            assert!(mm < 1e-6 && deg < 1e-6, "capture {k}: {mm} mm, {deg}°");
            let want_joints: Vec<f64> = serde_json::from_value(arm_joints[k].clone()).unwrap();
            assert_eq!(joints.len(), want_joints.len(), "capture {k}: {joints:?}");
            // "Still" is the settle rule's (every joint below 0.5 °/s for 50 ms): an arm easing
            // into its rest may still creep by thousandths of a degree when it counts as still.
            let worst =
                (0..joints.len()).fold(0.0f64, |m, i| m.max((joints[i] - want_joints[i]).abs()));
            assert!(
                worst < 0.01,
                "capture {k}: joints {joints:?} vs {want_joints:?}"
            );
        }
        // The session's taught plan is its captures: joints and flange poses as recorded.
        let taught = Plan::load(&session.join("taught-plan.yaml")).unwrap();
        assert_eq!(taught.waypoints.len(), got.len());
        for (waypoint, (k, pose, joints)) in taught.waypoints.iter().zip(&got) {
            let Waypoint::Taught {
                joints: taught_joints,
                base_from_flange,
            } = waypoint
            else {
                panic!("waypoint {k} is not taught: {waypoint:?}")
            };
            let (mm, deg) = crate::util::pose_error_mm_deg(base_from_flange, pose);
            assert!(mm < 1e-6 && deg < 1e-6, "taught {k}: {mm} mm, {deg}°");
            assert_eq!(taught_joints.len(), joints.len());
            assert!(
                (0..joints.len()).all(|i| (taught_joints[i].to_degrees() - joints[i]).abs() < 1e-9)
            );
        }
        eprintln!("verdict {}", verdict["verdict"]);
        assert_truth(&session);
        session
    }
}

#[test]
fn stop_on_the_console_cancels_the_goal_and_resume_completes() {
    let Some(python) = python() else { return };
    within(Duration::from_secs(600), move || {
        let dir = tempfile::tempdir().unwrap();
        let domain = ros_domain();
        let peer = Peer::start(&python, domain, &[]);
        let config = cell(dir.path(), domain, &[]);
        let session = dir.path().join("stopped");
        let mut live = serving_console(
            dir.path(),
            &["run", "--yes", "--console", "127.0.0.1:0", "--config"],
            &config,
            &["-o"],
            &session,
        );
        let url = live.url();
        let n = runtime().block_on(async {
            let mut page = Page::open(&url).await;
            let n = mid_long_goal(&peer);
            page.send("stop").await;
            n
        });
        let cancel = peer.wait_for("cancel", Duration::from_secs(10));
        assert_eq!(cancel["n"], n, "{cancel}");
        let (ok, out) = live.finish();
        assert!(!ok, "a stopped run exits with an error:\n{out}");
        assert!(
            out.contains(&format!("handeye run --resume {}", session.display())),
            "the stop says how to resume:\n{out}"
        );
        // The samples of the moves before are kept; the cancelled move never arrived.
        assert_eq!(poses_kept(&session) as u64, n - 1, "{out}");
        assert_eq!(peer.events("arrived").len() as u64, n - 1);
        let resumed = run(&["run", "--yes", "--resume", session.to_str().unwrap()]);
        assert!(resumed.status.success(), "{}", text(&resumed));
        assert_truth(&session);
    });
}
