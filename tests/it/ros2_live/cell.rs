//! `handeye run` of `configs/ros2-sim-cell.yaml` against the independent peer serving the
//! simulated cell (`scripts/ros2-peer.py sim-cell`): the run recovers the simulator's truth; STOP
//! (Ctrl-C) cancels the goal the peer runs; an aborted goal, a dead peer and a frame missing
//! from the TF tree are clear errors that keep the samples, and `--resume` completes.

use std::io::{BufRead, BufReader, Write};
use std::path::{Path, PathBuf};
use std::process::{Child, ChildStdin, Command, Output, Stdio};
use std::sync::{Arc, Mutex, OnceLock};
use std::time::{Duration, Instant};

use nalgebra::Vector3;

use handeye_core::geometry::pose_from_rotvec;
use handeye_records::result::ResultFile;

use super::{peer, python};
use crate::util::{config_variant, handeye, pose_error_mm_deg, repo, ros_domain, within};

/// The views the peer serves: a sim run of `config` into `CARGO_TARGET_TMPDIR/name`, made once.
fn render(name: &str, config: &Path) -> PathBuf {
    let dir = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join(name);
    if !dir.join("result.yaml").exists() {
        let _ = std::fs::remove_dir_all(&dir);
        let out = handeye()
            .args(["run", "--config"])
            .arg(config)
            .arg("-o")
            .arg(&dir)
            .output()
            .unwrap();
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
    }
    dir
}

/// The eye-in-hand views (configs/ros2-sim-cell-views.yaml).
pub(super) fn views() -> PathBuf {
    static VIEWS: OnceLock<PathBuf> = OnceLock::new();
    VIEWS
        .get_or_init(|| {
            render(
                "ros2-views",
                &repo().join("configs/ros2-sim-cell-views.yaml"),
            )
        })
        .clone()
}

/// The accepted records of `session`: plan index, `T_base_flange` and the manifest plan's joints
/// (degrees), in plan order.
pub(super) fn captures(session: &Path) -> Vec<(usize, handeye_core::geometry::Pose, Vec<f64>)> {
    let folder = handeye_records::SessionFolder::open(session).unwrap();
    let plan = folder.read_manifest().unwrap().plan;
    let mut visits = folder.read_visits().unwrap();
    visits.retain(|v| v.rejected.is_none() && v.camera_from_target.is_some());
    visits.sort_by_key(|v| v.plan_index);
    visits
        .iter()
        .map(|v| {
            (
                v.plan_index,
                v.base_from_flange,
                plan[v.plan_index].joints_deg.clone(),
            )
        })
        .collect()
}

/// The peer process, its stdout events collected; killed when dropped.
pub(super) struct Peer {
    child: Child,
    /// Its commands (`guide K`: hand-guide the arm to plan pose K).
    stdin: ChildStdin,
    events: Arc<Mutex<Vec<serde_json::Value>>>,
}

impl Peer {
    pub(super) fn start(python: &PathBuf, domain: u16, faults: &[&str]) -> Peer {
        Self::serving(python, domain, &views(), faults)
    }

    pub(super) fn serving(python: &PathBuf, domain: u16, views: &Path, faults: &[&str]) -> Peer {
        let mut command = peer(python, domain);
        command
            .arg("sim-cell")
            .arg(views)
            .arg("--camera-info")
            .arg(repo().join("configs/cameras/sim-1280x720.yaml"))
            .args(faults);
        Self::spawn(command)
    }

    /// Starts a peer's `sim-cell` command (this one's or the Fast DDS peer's: the same JSON
    /// events) and waits for its `ready`.
    pub(super) fn spawn(mut command: Command) -> Peer {
        let mut child = command
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .stderr(Stdio::inherit())
            .spawn()
            .expect("the peer's sim-cell");
        let events = Arc::new(Mutex::new(Vec::new()));
        let sink = events.clone();
        let stdout = child.stdout.take().unwrap();
        std::thread::spawn(move || {
            for line in BufReader::new(stdout).lines().map_while(Result::ok) {
                match serde_json::from_str(&line) {
                    Ok(v) => sink.lock().unwrap().push(v),
                    // Said, so that a line the harness could not read is not a silent peer.
                    Err(e) => eprintln!(
                        "the peer printed a line that is not one JSON event ({e}): {line}"
                    ),
                }
            }
        });
        let stdin = child.stdin.take().unwrap();
        let peer = Peer {
            child,
            stdin,
            events,
        };
        peer.wait_for("ready", Duration::from_secs(60));
        peer
    }

    /// Hand-guides the arm to plan pose `k` (no trajectory goal), as a person would.
    pub(super) fn guide(&mut self, k: usize) {
        writeln!(self.stdin, "guide {k}").expect("the peer reads its commands");
        self.stdin.flush().unwrap();
    }

    /// `goals` goals, each within the configured 60 °/s, every pose served with its rendered
    /// view; the goals.
    pub(super) fn assert_served(&self, goals: usize) -> Vec<serde_json::Value> {
        let all = self.events("goal");
        assert_eq!(all.len(), goals, "{all:?}");
        for g in &all {
            let speed = g["max_joint_speed_rad_s"].as_f64().unwrap();
            assert!(speed <= 60f64.to_radians() + 1e-9, "{g}");
        }
        let no_view = self.events("no_view");
        assert!(no_view.is_empty(), "{no_view:?}");
        all
    }

    pub(super) fn events(&self, kind: &str) -> Vec<serde_json::Value> {
        self.events
            .lock()
            .unwrap()
            .iter()
            .filter(|e| e["event"] == kind)
            .cloned()
            .collect()
    }

    pub(super) fn wait_for(&self, kind: &str, limit: Duration) -> serde_json::Value {
        self.wait_for_one(kind, limit, |_| true)
    }

    /// The newest event of `kind` that `which` picks, waiting up to `limit`.
    pub(super) fn wait_for_one(
        &self,
        kind: &str,
        limit: Duration,
        which: impl Fn(&serde_json::Value) -> bool,
    ) -> serde_json::Value {
        let end = Instant::now() + limit;
        loop {
            if let Some(e) = self.events(kind).into_iter().rfind(|e| which(e)) {
                return e;
            }
            if Instant::now() >= end {
                let all = self.events.lock().unwrap();
                let last: Vec<_> = all.iter().rev().take(8).collect();
                panic!("the peer said no {kind:?} within {limit:?}; its last events: {last:?}");
            }
            std::thread::sleep(Duration::from_millis(20));
        }
    }
}

impl Drop for Peer {
    fn drop(&mut self) {
        // A failing test names what the peer last said, so a flake shows which side went quiet.
        if std::thread::panicking() {
            let all = self.events.lock().map(|e| e.clone()).unwrap_or_default();
            let last: Vec<String> = all
                .iter()
                .rev()
                .take(12)
                .rev()
                .map(|e| e.to_string())
                .collect();
            eprintln!(
                "the peer's last events ({} in all):\n  {}",
                all.len(),
                last.join("\n  ")
            );
        }
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// configs/ros2-sim-cell.yaml on `domain`, written into `dir`.
pub(super) fn cell(dir: &Path, domain: u16, edits: &[(&str, &str)]) -> PathBuf {
    let mut all = vec![("domain_id: 42", format!("domain_id: {domain}"))];
    all.extend(edits.iter().map(|(a, b)| (*a, b.to_string())));
    // 30 s for the peer to answer unless a test sets its own: two Python peers rendering frames
    // beside two handeye runs on a 2-core machine were seen to answer a goal's result after the
    // shipped 10 s (a move "not finished" although the peer had arrived), which is not what the
    // tests assert. The shipped 10 s stays the default of the config.
    if !edits
        .iter()
        .any(|(from, _)| from.contains("connect_timeout_s"))
    {
        all.push((
            "connect_timeout_s: 10}",
            "connect_timeout_s: 30}".to_string(),
        ));
    }
    let edits: Vec<(&str, &str)> = all.iter().map(|(a, b)| (*a, b.as_str())).collect();
    config_variant(dir, "ros2-sim-cell.yaml", "ros2-cell.yaml", &edits)
}

pub(super) fn run(args: &[&str]) -> Output {
    handeye()
        .args(args)
        .env("HANDEYE_LOG", "warn,rustdds=off,handeye_ros2::latency=info")
        .output()
        .unwrap()
}

/// `handeye run --yes --config CONFIG -o OUT` (as [`run`]).
pub(super) fn run_cell(config: &Path, out: &Path) -> Output {
    run(&[
        "run",
        "--yes",
        "--config",
        config.to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
    ])
}

pub(super) fn text(out: &Output) -> String {
    format!(
        "{}\n{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    )
}

/// The result in `session` against configs/ros2-sim-cell.yaml's `simulation:` truth, within
/// 0.5 mm and 0.05°.
pub(super) fn assert_truth(session: &Path) {
    assert_truth_of(&session.join("result.yaml"));
}

/// [`assert_truth`] of a result file.
pub(super) fn assert_truth_of(result: &Path) {
    let mounts = ResultFile::load_mounts(result).unwrap();
    let camera = pose_from_rotvec(
        Vector3::new(0.0312, -0.0694, 0.0447),
        Vector3::new(0.021, -0.016, 1.561),
    );
    let target = pose_from_rotvec(
        Vector3::new(0.5034, -0.1467, 0.0021),
        Vector3::new(0.012, -0.018, 0.297),
    );
    for (name, got, want) in [
        ("T_flange_camera", mounts.camera_mount, camera),
        ("T_base_target", mounts.target_mount, target),
    ] {
        let (mm, deg) = pose_error_mm_deg(&got, &want);
        eprintln!("{name}: {mm:.3} mm, {deg:.4}° from the truth");
        assert!(mm < 0.5 && deg < 0.05, "{name}: {mm} mm, {deg}°");
    }
}

/// handeye run against a peer started with `peer_args`, on a domain of its own, the shipped
/// ROS 2 cell config edited by `edits` ([`cell`]), into `session/` of a fresh folder: what the
/// tests then assert on.
pub(super) struct PeerRun {
    /// The folder of the config and the session: removed when the run is dropped.
    _dir: tempfile::TempDir,
    /// The domain id.
    pub domain: u16,
    /// The peer, still running.
    pub peer: Peer,
    /// The session folder.
    pub out_dir: PathBuf,
    /// handeye's exit.
    pub out: Output,
    /// handeye's output, both streams.
    pub log: String,
}

impl PeerRun {
    pub(super) fn start(python: &PathBuf, peer_args: &[&str], edits: &[(&str, &str)]) -> PeerRun {
        let dir = tempfile::tempdir().unwrap();
        let domain = ros_domain();
        let peer = Peer::start(python, domain, peer_args);
        let config = cell(dir.path(), domain, edits);
        let out_dir = dir.path().join("session");
        let out = run_cell(&config, &out_dir);
        let log = text(&out);
        PeerRun {
            _dir: dir,
            domain,
            peer,
            out_dir,
            out,
            log,
        }
    }
}

pub(super) fn poses_kept(session: &Path) -> usize {
    std::fs::read_dir(session.join("poses")).map_or(0, |d| d.count())
}

#[test]
fn eye_in_hand_over_ros2_recovers_the_simulated_truth() {
    let Some(python) = python() else { return };
    within(Duration::from_secs(400), move || {
        let run = PeerRun::start(&python, &[], &[]);
        let (peer, out_dir, out, log) = (&run.peer, &run.out_dir, &run.out, &run.log);
        assert!(out.status.success(), "{log}");
        assert_truth(out_dir);
        // A ROS 2 cell is told how the answer reaches its graph.
        let next = String::from_utf8_lossy(&out.stdout);
        let next = next.lines().last().unwrap_or_default();
        assert!(
            next.starts_with("next: handeye publish ") && next.contains("--format ros2-launch"),
            "{log}"
        );
        peer.assert_served(12);
        // The file is the driver's calibration: nothing to say about it.
        let result = std::fs::read_to_string(out_dir.join("result.yaml")).unwrap();
        assert!(!result.contains("camera driver publishes"), "{result}");
        // What the graph held as static is part of the session: the driver's base_link → base
        // turn, as the peer publishes it.
        let recorded =
            handeye_records::tf_static::StaticTransformsFile::load(&out_dir.join("tf_static.yaml"))
                .unwrap();
        let turn = recorded
            .transforms
            .iter()
            .find(|t| (t.parent.as_str(), t.child.as_str()) == ("base_link", "base"))
            .unwrap_or_else(|| panic!("{recorded:?}"));
        assert!((turn.pose.rotation.angle() - std::f64::consts::PI).abs() < 1e-9);
        // The measured time from the arm's rest to the captured frame's stamp.
        let after: Vec<f64> = log
            .lines()
            .filter_map(|l| l.split("frame stamped ").nth(1))
            .filter_map(|l| l.split(" ms").next()?.parse().ok())
            .collect();
        assert_eq!(after.len(), 12, "{log}");
        eprintln!(
            "frame stamp after the arm settled: median {:.1} ms, max {:.1} ms",
            crate::util::median(after.clone()),
            after.iter().cloned().fold(0.0, f64::max)
        );
    });
}

#[test]
fn intrinsics_from_the_camera_info_topic_alone_recover_the_truth() {
    let Some(python) = python() else { return };
    within(Duration::from_secs(400), move || {
        let dir = tempfile::tempdir().unwrap();
        let domain = ros_domain();
        let peer = Peer::start(&python, domain, &[]);
        // No `intrinsics:` file: the camera driver's camera_info is the calibration.
        let file_line = format!(
            "intrinsics: {}/cameras/sim-1280x720.yaml\n",
            repo().join("configs").display()
        );
        let config = cell(dir.path(), domain, &[(file_line.as_str(), "")]);
        let out_dir = dir.path().join("session");
        let out = run_cell(&config, &out_dir);
        let log = text(&out);
        assert!(out.status.success(), "{log}");
        assert!(
            log.contains("the camera driver's calibration on /camera_info kept in"),
            "{log}"
        );
        assert_truth(&out_dir);
        let kept = handeye_core::camera_model::CameraModel::load(
            &out_dir.join(handeye_session::cell::INTRINSICS_FROM_TOPIC_FILE),
        )
        .unwrap();
        let truth = super::sim_camera_model();
        assert!((kept.fx - truth.fx).abs() < 1e-9 && (kept.cy - truth.cy).abs() < 1e-9);
        // The session replays with the driver gone: the intrinsics it read are the session's.
        drop(peer);
        let replay = run(&["replay", out_dir.to_str().unwrap()]);
        assert!(replay.status.success(), "{}", text(&replay));
        assert_truth_of(&out_dir.join("replay-result.yaml"));
    });
}

#[test]
fn an_intrinsics_file_that_differs_from_the_drivers_calibration_is_named() {
    let Some(python) = python() else { return };
    within(Duration::from_secs(400), move || {
        let dir = tempfile::tempdir().unwrap();
        let domain = ros_domain();
        let peer = Peer::start(&python, domain, &[]);
        // A file 4 % off in fx and fy while the driver publishes the camera's true calibration.
        let lens = dir.path().join("stale.yaml");
        let stale_lens = std::fs::read_to_string(repo().join("configs/cameras/sim-1280x720.yaml"))
            .unwrap()
            .replace(
                "data: [800.0, 0.0, 641.3, 0.0, 800.0,",
                "data: [832.0, 0.0, 641.3, 0.0, 832.0,",
            );
        std::fs::write(&lens, stale_lens).unwrap();
        let file_line = format!(
            "intrinsics: {}/cameras/sim-1280x720.yaml",
            repo().join("configs").display()
        );
        let stale = format!("intrinsics: {}", lens.display());
        let config = cell(dir.path(), domain, &[(file_line.as_str(), stale.as_str())]);
        let out_dir = dir.path().join("session");
        let out = run_cell(&config, &out_dir);
        let log = text(&out);
        drop(peer);
        let result = std::fs::read_to_string(out_dir.join("result.yaml"))
            .unwrap_or_else(|e| panic!("{e}: {log}"));
        assert!(
            result.contains("differ from the calibration the camera driver publishes")
                && result.contains("fx in the file 832.0 px, from the driver 800.0 px")
                && result.contains("corners fit the driver"),
            "{result}"
        );
    });
}

/// Runs the cell into `out` with the peer's `faults`, expecting failure with `expected` in the
/// message after some samples; then resumes against a healthy peer and checks the truth.
pub(super) fn fails_then_resumes(domain: u16, faults: &[&str], expected: &str) {
    fails_then_resumes_with(domain, faults, &[], &[expected])
}

/// [`fails_then_resumes`] with the cell's config edited (`edits`, as [`cell`] takes them),
/// expecting one of `expected` in the message.
pub(super) fn fails_then_resumes_with(
    domain: u16,
    faults: &[&str],
    edits: &[(&str, &str)],
    expected: &[&str],
) {
    let Some(python) = python() else { return };
    let dir = tempfile::tempdir().unwrap();
    // The shipped 10 s to answer, not less: on a loaded 2-core CI machine a 3 s budget let a
    // slow-to-answer goal read as the fault under test (seen once in CI).
    let config = cell(dir.path(), domain, edits);
    let out_dir = dir.path().join("session");
    {
        let _peer = Peer::start(&python, domain, faults);
        let out = run_cell(&config, &out_dir);
        let log = text(&out);
        assert!(!out.status.success(), "{log}");
        assert!(
            expected.iter().any(|e| log.contains(e)),
            "expected one of {expected:?} in:\n{log}"
        );
        let kept = poses_kept(&out_dir);
        assert!(kept >= 2, "{kept} samples kept:\n{log}");
    }
    let _peer = Peer::start(&python, domain, &[]);
    let out = run(&["run", "--yes", "--resume", out_dir.to_str().unwrap()]);
    assert!(out.status.success(), "{}", text(&out));
    assert_truth(&out_dir);
}

#[test]
fn an_aborted_goal_is_named_and_resume_completes() {
    within(Duration::from_secs(400), || {
        fails_then_resumes(
            ros_domain(),
            &["--abort-goal", "4"],
            "PATH_TOLERANCE_VIOLATED",
        )
    });
}

/// #38: a flange pose on /tf that jumps while /joint_states stand (every other message 5 mm
/// off, from the end of goal 4 on) is named as a pose stream that contradicts its joints — not
/// as a board scale or a lens — the poses before it are kept, and a resume against a healthy
/// driver completes to the truth.
#[test]
fn a_flange_pose_that_jumps_while_the_joints_stand_is_named_and_resume_completes() {
    within(Duration::from_secs(400), || {
        fails_then_resumes(
            ros_domain(),
            &["--jumping-flange", "4"],
            "contradicts the joints",
        )
    });
}

/// #40: a controller that answers a goal SUCCEEDED without moving the arm is named as such
/// (the arm never reached the goal's end point), not "no tag of the board found" at every pose.
#[test]
fn a_goal_that_succeeds_without_moving_is_named_and_resume_completes() {
    within(Duration::from_secs(400), || {
        fails_then_resumes(
            ros_domain(),
            &["--succeed-without-moving", "4"],
            "answered SUCCEEDED but /joint_states did not reach the goal's end point",
        )
    });
}

/// #40: a flange pose on /tf that stands with the joints but is 40 mm from the forward
/// kinematics of the arm's model at them (`robot.model: ur10e`; from the end of goal 4 on) is
/// named with both sources, nothing is recorded under it, the poses before are kept, and a
/// resume against a healthy driver completes to the truth.
#[test]
fn a_flange_pose_off_the_models_kinematics_is_named_and_resume_completes() {
    within(Duration::from_secs(400), || {
        fails_then_resumes(
            ros_domain(),
            &["--flange-off-model", "4"],
            "from the forward kinematics of the ur10e model at the joints on /joint_states",
        )
    });
}

/// A trajectory goal lost in transit (the first of a run: Cyclone DDS drops for good a request
/// written before the server's reader took in our writer, and a CI run waited 30 s for it) is
/// sent again after 5 s as a new goal of the same trajectory, and so is one whose answer alone
/// is lost (the server runs it, and the new goal replaces it as a trajectory controller's
/// preemption does): the run completes to the truth either way, and says it sent the goal again.
#[test]
fn a_lost_trajectory_goal_is_sent_again_and_the_run_completes() {
    let Some(python) = python() else { return };
    within(Duration::from_secs(500), move || {
        for lost in ["request", "reply"] {
            let run = PeerRun::start(&python, &["--lose-first-goal", lost], &[]);
            let (peer, out_dir, out, log) = (&run.peer, &run.out_dir, &run.out, &run.log);
            assert!(out.status.success(), "{lost}: {log}");
            assert_truth(out_dir);
            assert_eq!(peer.events("goal_lost").len(), 1, "{lost}: {log}");
            assert!(
                log.contains("no answer to the trajectory goal within 5 s: sending it again"),
                "{lost}: {log}"
            );
        }
    });
}

/// The same contradiction from the start: named when the arm is opened, before anything moves.
#[test]
fn a_flange_pose_off_the_models_kinematics_is_named_before_anything_moves() {
    let Some(python) = python() else { return };
    within(Duration::from_secs(120), move || {
        let run = PeerRun::start(&python, &["--flange-off-model", "0"], &[]);
        let (peer, out, log) = (&run.peer, &run.out, &run.log);
        assert!(!out.status.success(), "{log}");
        assert!(
            log.contains("the flange pose base → tool0 on /tf (at [")
                && log
                    .contains("is 40.0 mm / 0.00° from the forward kinematics of the ur10e model")
                && log.contains("the flange pose contradicts the joints' kinematics"),
            "{log}"
        );
        assert!(peer.events("goal").is_empty(), "a goal was sent:\n{log}");
    });
}

/// `robot.flange_pose: joints` for an arm whose TF is not to be trusted: the same flange pose
/// 40 mm off the model on /tf from the start, and the run reads the flange from the joints
/// through the model instead: it completes to the truth and says where its poses came from.
#[test]
fn with_the_flange_pose_from_the_joints_a_wrong_tf_chain_is_not_read() {
    let Some(python) = python() else { return };
    within(Duration::from_secs(300), move || {
        let run = PeerRun::start(
            &python,
            &["--flange-off-model", "0"],
            &[(
                "  flange_frame: tool0",
                "  flange_frame: tool0\n  flange_pose: joints",
            )],
        );
        let (out, out_dir, log) = (&run.out, &run.out_dir, &run.log);
        assert!(out.status.success(), "{log}");
        assert!(
            log.contains("the flange poses are the ur10e model's forward kinematics at the joints on /joint_states"),
            "{log}"
        );
        assert_truth(out_dir);
    });
}

#[test]
fn a_peer_dying_mid_move_is_named_and_resume_completes() {
    within(Duration::from_secs(400), || {
        fails_then_resumes(ros_domain(), &["--die-in-goal", "4"], "/joint_states")
    });
}

/// Waits until the arm is 200 ms into the first goal after the second that takes at least a
/// second; its number.
pub(super) fn mid_long_goal(peer: &Peer) -> u64 {
    let long = peer.wait_for_one("goal", Duration::from_secs(120), |g| {
        g["n"].as_u64().unwrap() >= 2 && g["duration_s"].as_f64().unwrap() >= 1.0
    });
    std::thread::sleep(Duration::from_millis(200));
    long["n"].as_u64().unwrap()
}

#[test]
fn ctrl_c_cancels_the_goal_and_keeps_the_samples() {
    let Some(python) = python() else { return };
    within(Duration::from_secs(300), move || {
        let dir = tempfile::tempdir().unwrap();
        let domain = ros_domain();
        let peer = Peer::start(&python, domain, &[]);
        let config = cell(dir.path(), domain, &[]);
        ctrl_c_mid_goal(&peer, &config, &dir.path().join("session"));
    });
}

/// `handeye run` of `config` into `out_dir`, Ctrl-C (SIGINT to its own pid) in the middle of a
/// long move: the peer sees that goal cancelled and handeye hears it confirmed, the run fails,
/// the samples of the moves before are kept and the cancelled move never arrived.
pub(super) fn ctrl_c_mid_goal(peer: &Peer, config: &Path, out_dir: &Path) {
    let mut child = handeye()
        .args(["run", "--yes", "--config"])
        .arg(config)
        .arg("-o")
        .arg(out_dir)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    // A run that ends before its long move (or never sends it) is shown, not left running.
    let waited = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| mid_long_goal(peer)));
    let n = match waited {
        Ok(n) => n,
        Err(panic) => {
            let _ = child.kill();
            let out = child.wait_with_output().unwrap();
            eprintln!("handeye's output:\n{}", text(&out));
            std::panic::resume_unwind(panic)
        }
    };
    let status = Command::new("kill")
        .args(["-INT", &child.id().to_string()])
        .status()
        .unwrap();
    assert!(status.success());
    let cancel = peer.wait_for("cancel", Duration::from_secs(10));
    assert_eq!(cancel["n"], n, "{cancel}");
    let out = child.wait_with_output().unwrap();
    let log = text(&out);
    assert!(!out.status.success(), "{log}");
    // Unconfirmed, handeye would ask to stop the arm on the pendant.
    assert!(!log.contains("did not confirm the cancel"), "{log}");
    assert_eq!(poses_kept(out_dir) as u64, n - 1, "{log}");
    assert_eq!(peer.events("arrived").len() as u64, n - 1);
}

#[test]
fn a_flange_frame_missing_from_tf_is_named_before_anything_moves() {
    let Some(python) = python() else { return };
    within(Duration::from_secs(120), move || {
        let run = PeerRun::start(
            &python,
            &["--no-tool0"],
            &[("connect_timeout_s: 10", "connect_timeout_s: 3")],
        );
        let (peer, out, log) = (&run.peer, &run.out, &run.log);
        assert!(!out.status.success(), "{log}");
        assert!(log.contains("\"tool0\" is not in the TF tree"), "{log}");
        assert!(
            peer.events("goal").is_empty(),
            "something moved: {:?}",
            peer.events("goal")
        );
    });
}

/// #39: an image topic nobody publishes is named when the camera opens, before the arm moves
/// (it was found at the first pose, after a move).
#[test]
fn an_image_topic_nobody_publishes_is_named_before_anything_moves() {
    let Some(python) = python() else { return };
    within(Duration::from_secs(120), move || {
        let run = PeerRun::start(
            &python,
            &[],
            &[
                ("image_topic: /image_raw", "image_topic: /no_such_image"),
                ("frame_timeout_s: 5", "frame_timeout_s: 2"),
            ],
        );
        let (peer, out, log) = (&run.peer, &run.out, &run.log);
        assert!(!out.status.success(), "{log}");
        assert!(
            log.contains("no image on /no_such_image") && log.contains("nothing has moved"),
            "{log}"
        );
        // The topic the peer does publish is listed, with its type.
        assert!(
            log.contains("image topics heard on this domain: /image_raw (sensor_msgs/msg/Image)"),
            "{log}"
        );
        assert!(peer.events("goal").is_empty(), "a goal was sent:\n{log}");
    });
}

#[test]
fn without_a_driver_the_action_server_is_named() {
    let dir = tempfile::tempdir().unwrap();
    within(Duration::from_secs(60), move || {
        let domain = ros_domain();
        let config = cell(
            dir.path(),
            domain,
            &[("connect_timeout_s: 10", "connect_timeout_s: 2")],
        );
        let out = run_cell(&config, &dir.path().join("s"));
        let log = text(&out);
        assert!(!out.status.success(), "{log}");
        assert!(
            log.contains("/scaled_joint_trajectory_controller/follow_joint_trajectory"),
            "{log}"
        );
        // #39: an empty domain is said as such, not as a controller that is not running.
        assert!(
            log.contains(&format!("nothing at all is heard on domain {domain}")),
            "{log}"
        );
    });
}

/// #39: the config says `rmw: fastrtps` while the driver runs Cyclone DDS: the action server's
/// topics are heard but it does not take the goal; the message names robot.graph.rmw and the
/// other middleware (it was "is the controller running?"), and nothing has moved.
#[test]
fn a_middleware_mismatch_names_robot_graph_rmw() {
    let Some(python) = python() else { return };
    within(Duration::from_secs(120), move || {
        let run = PeerRun::start(
            &python,
            &[],
            &[
                ("rmw: cyclonedds", "rmw: fastrtps"),
                ("connect_timeout_s: 10", "connect_timeout_s: 3"),
            ],
        );
        let (peer, out, log) = (&run.peer, &run.out, &run.log);
        assert!(!out.status.success(), "{log}");
        assert!(
            log.contains("robot.graph.rmw is `fastrtps`") && log.contains("set `rmw: cyclonedds`"),
            "{log}"
        );
        assert!(
            peer.events("goal").is_empty(),
            "the peer took a goal: {:?}",
            peer.events("goal")
        );
    });
}

/// The eye-to-hand cell of configs/sim-cell-eye-to-hand.yaml over ROS 2: the camera on a post,
/// the board on the flange.
#[test]
fn eye_to_hand_over_ros2_recovers_the_simulated_truth() {
    let Some(python) = python() else { return };
    within(Duration::from_secs(400), move || {
        let dir = tempfile::tempdir().unwrap();
        let fixed = [(
            "  generate: {count: 20",
            "  adaptive: false\n  generate: {count: 12",
        )];
        let sim = config_variant(
            dir.path(),
            "sim-cell-eye-to-hand.yaml",
            "views.yaml",
            &fixed,
        );
        let views = render("ros2-views-eye-to-hand", &sim);
        let domain = ros_domain();
        let peer = Peer::serving(&python, domain, &views, &[]);
        let robot = format!("robot:\n  backend: ros2\n  model: ur10e\n  graph: {{domain_id: {domain}, interfaces: [127.0.0.1], rmw: cyclonedds}}\n  repeatability_mm: 0.02\n  repeatability_deg: 0.002\n\ncamera:\n  backend: ros2\n  camera_info_topic: /camera_info\n");
        let config = config_variant(
            dir.path(),
            "sim-cell-eye-to-hand.yaml",
            "ros2-cell.yaml",
            &[
                fixed[0],
                ("robot:\n  backend: sim\n  model: ur10e\n  start_joints_deg: [0, -90, 90, -90, -90, 0]\n  move_duration_s: 0.0\n  repeatability_mm: 0.02\n  repeatability_deg: 0.002\n  seed: 5\n\ncamera:\n  backend: sim\n  noise_sigma: 2.0\n  blur_sigma_px: 0.5\n  seed: 13\n", robot.as_str()),
                ("session: {settle_s: 0.0,", "session: {settle_s: 0.0, settle_window_s: 0.05,"),
            ],
        );
        let out_dir = dir.path().join("session");
        let out = run_cell(&config, &out_dir);
        assert!(out.status.success(), "{}", text(&out));
        assert!(
            peer.events("no_view").is_empty(),
            "{:?}",
            peer.events("no_view")
        );
        let mounts = ResultFile::load_mounts(&out_dir.join("result.yaml")).unwrap();
        let camera = handeye_core::geometry::Pose::from_parts(
            nalgebra::Translation3::new(1.1537, 0.0042, 0.7468),
            nalgebra::UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(
                0.4247281012,
                -0.5658387224,
                -0.5656999087,
                0.4235754875,
            )),
        );
        let target = pose_from_rotvec(
            Vector3::new(-0.1432, -0.1461, 0.0113),
            Vector3::new(0.011, 0.006, 0.021),
        );
        for (name, got, want) in [
            ("T_base_camera", mounts.camera_mount, camera),
            ("T_flange_target", mounts.target_mount, target),
        ] {
            let (mm, deg) = pose_error_mm_deg(&got, &want);
            eprintln!("{name}: {mm:.3} mm, {deg:.4}° from the truth");
            assert!(mm < 0.5 && deg < 0.05, "{name}: {mm} mm, {deg}°");
        }
    });
}

/// #38: a second publisher of base_link → tool0 on the domain (another node's writer on /tf,
/// 10 cm and 180° from the driver's flange, at 200 Hz while the arm stands) made a run "measure
/// the board at 0.119×" and answer 805 mm off. The run names the contradiction — the edge, two
/// publishers, how far apart they are — records no pose from it, and writes no answer: no board
/// scale or lens file is blamed, no GOOD or CHECK verdict is given. `from_goal`: the peer's
/// second publisher starts once that goal has ended (0: from the start); `kept`: the poses
/// recorded before it.
fn a_second_flange_publisher(from_goal: usize, kept: usize) {
    let Some(python) = python() else { return };
    let from = from_goal.to_string();
    // The peer floods /tf at 200 Hz: on a loaded 2-core machine its action server can take
    // longer than the shipped 10 s to answer (a CI run saw it), which is not what this tests.
    let run = PeerRun::start(
        &python,
        &["--second-flange-publisher", &from],
        &[("connect_timeout_s: 10}", "connect_timeout_s: 40}")],
    );
    let (peer, out_dir, out, log) = (&run.peer, &run.out_dir, &run.out, &run.log);
    eprintln!("{log}");
    assert!(
        !peer.events("second_flange_publisher").is_empty(),
        "the peer's second publisher never wrote"
    );
    assert!(!out.status.success(), "{log}");
    // The edge, the count of its publishers and how far apart they are, and what to do. Named
    // where the second publisher started, both speak of the arm at rest there: the peer's
    // offset, 100 mm and 180°. Named one pose later (DDS discovery slower than the check at
    // opening, under load), the second one's newest word may still be from the pose before
    // (it speaks only while the arm stands), so the distance is that offset and the move's.
    let named = "base_link → tool0 has 2 publishers that disagree by ";
    let said = log
        .split(named)
        .nth(1)
        .unwrap_or_else(|| panic!("the edge and its 2 publishers not named:\n{log}"));
    let goals = peer.events("goal").len();
    if goals == from_goal {
        assert!(said.starts_with("100.0 mm and 180.0°"), "{log}");
    }
    assert!(log.contains("stop all but the driver's"), "{log}");
    for blame in [
        "board measures",
        "printed at",
        "tagSize",
        "intrinsics in",
        "camera_info.yaml",
    ] {
        assert!(!log.contains(blame), "blamed a file ({blame:?}):\n{log}");
    }
    // No answer from contradictory poses: no result, no verdict, no pose recorded while the
    // second publisher spoke.
    assert!(!out_dir.join("result.yaml").exists(), "{log}");
    for level in ["GOOD", "CHECK", "REDO"] {
        assert!(!log.contains(level), "a {level} verdict:\n{log}");
    }
    assert_eq!(poses_kept(out_dir), kept, "poses recorded:\n{log}");
    // Named when the arm is opened, or — when DDS discovery matches the second writer only
    // after that check — at the first pose, before its capture is recorded.
    assert!(
        goals == from_goal || (from_goal == 0 && goals == 1),
        "{goals} goals:\n{log}"
    );
}

/// Named before anything moves (or at the first pose, when discovery is late), nothing recorded.
#[test]
fn a_second_publisher_of_the_flange_is_named_before_a_pose_is_recorded() {
    within(Duration::from_secs(200), || a_second_flange_publisher(0, 0));
}

/// The same publisher appearing mid-run: the poses before it are kept, the one after is not
/// recorded, and the run stops naming it.
#[test]
fn a_second_publisher_of_the_flange_mid_run_stops_the_run_naming_it() {
    within(Duration::from_secs(300), || a_second_flange_publisher(4, 3));
}

/// #40: a second action server of the driver's name (a simulated controller left running, on a
/// DDS participant of its own) that answers every goal SUCCEEDED at once, from the start: named
/// with both participants before a goal is sent, nothing recorded.
#[test]
fn a_duplicate_action_server_is_named_before_anything_moves() {
    let Some(python) = python() else { return };
    within(Duration::from_secs(200), move || {
        let run = PeerRun::start(&python, &["--duplicate-action-server"], &[]);
        let (domain, peer, out_dir, out, log) =
            (&run.domain, &run.peer, &run.out_dir, &run.out, &run.log);
        assert!(!out.status.success(), "{log}");
        assert!(
            log.contains(&format!(
                "2 action servers take the goals of /scaled_joint_trajectory_controller/follow_joint_trajectory on domain {domain}"
            )),
            "{log}"
        );
        assert!(log.contains("nothing was sent"), "{log}");
        assert!(peer.events("goal").is_empty(), "a goal was sent:\n{log}");
        assert!(
            peer.events("liar_goal").is_empty(),
            "a goal was sent:\n{log}"
        );
        assert_eq!(poses_kept(out_dir), 0, "{log}");
    });
}

/// The same server joining when goal 4 is accepted: named at the next goal (or, when discovery
/// is slower than the move, by the arm not reaching the goal it "succeeded"), the poses before
/// it kept, and resume completes to the truth once it is gone.
#[test]
fn a_duplicate_action_server_mid_run_is_named_and_resume_completes() {
    within(Duration::from_secs(400), || {
        fails_then_resumes_with(
            ros_domain(),
            &["--duplicate-action-server", "4"],
            &[],
            &[
                "2 action servers take the goals of",
                "answered SUCCEEDED but /joint_states did not reach the goal's end point",
            ],
        )
    });
}

/// #40: a /tf flood of 5000 frame names nobody asked for, heard before the driver's
/// base_link → tool0 (over the TF tree's 4096-frame cap), does not crowd out the arm's frames:
/// the run completes to the truth.
#[test]
fn a_tf_flood_before_the_arms_frames_does_not_crowd_them_out() {
    let Some(python) = python() else { return };
    within(Duration::from_secs(400), move || {
        let run = PeerRun::start(&python, &["--tf-flood", "5000"], &[]);
        let (peer, out_dir, out, log) = (&run.peer, &run.out_dir, &run.out, &run.log);
        assert!(!peer.events("tf_flood").is_empty(), "no flood was sent");
        assert!(out.status.success(), "{log}");
        assert_truth(out_dir);
    });
}
