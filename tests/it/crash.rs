//! Crash consistency of the session folder (issue #13 items 1, 2, 3, 10), with the real binary as
//! a child process: killed at many points (by the `HANDEYE_FAULT` hook, which aborts the process
//! right after a given write, and by a real SIGKILL), stopped by SIGTERM and SIGHUP, raced by a
//! second run of the same folder, resumed after its input files changed. After every resume each
//! visited pose is in the result exactly once, and the pose-space samples and the pixel fit use
//! the same frames.

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Output, Stdio};
use std::time::{Duration, Instant};

use handeye_records::dataset::Dataset;

use crate::util;
use util::handeye;

const POSES: usize = 8;

/// The demo cell with an 8-pose plan, `move_duration_s` per move, and its own copy of the
/// intrinsics (so a test can edit them).
fn cell(dir: &Path, move_duration_s: f64) -> PathBuf {
    let intrinsics = dir.join("camera.yaml");
    std::fs::copy(
        util::repo().join("configs/cameras/sim-1280x720.yaml"),
        &intrinsics,
    )
    .unwrap();
    let configs = util::repo().join("configs");
    let original = format!(
        "intrinsics: {}/cameras/sim-1280x720.yaml",
        configs.display()
    );
    let copy = format!("intrinsics: {}", intrinsics.display());
    let duration = format!("move_duration_s: {move_duration_s}");
    util::config_variant(
        dir,
        "sim-cell.yaml",
        "cell.yaml",
        &[
            ("count: 20", &format!("count: {POSES}")),
            ("move_duration_s: 0.0", &duration),
            (&original, &copy),
            // Every pose of the plan (generated plans are adaptive by default), in the given
            // order: a resumed sim arm starts again at its start joints (a real arm stands
            // where it stopped), from where the end of a travel-ordered tour may lie beyond a
            // straight move inside the box.
            ("plan:\n", "plan:\n  adaptive: false\n  reorder: false\n"),
        ],
    )
}

fn run_new(config: &Path, session: &Path) -> Command {
    let mut command = handeye();
    command
        .args(["run", "--config"])
        .arg(config)
        .arg("--output")
        .arg(session);
    command
}

fn resume(session: &Path) -> Command {
    let mut command = handeye();
    command.args(["run", "--resume"]).arg(session);
    command
}

fn output(command: &mut Command) -> Output {
    command.stdin(Stdio::null()).output().unwrap()
}

fn stderr(out: &Output) -> String {
    String::from_utf8_lossy(&out.stderr).into_owned()
}

fn sample_ids(session: &Path) -> Vec<String> {
    Dataset::load(&session.join("samples.yaml"))
        .unwrap()
        .pairs
        .iter()
        .map(|p| p.id.clone().unwrap())
        .collect()
}

fn all_ids() -> Vec<String> {
    (0..POSES).map(|i| format!("pose-{i:03}")).collect()
}

/// After a finished run: every pose is a sample exactly once, in plan order, and the pixel fit
/// (`reprojection.yaml`) used exactly the same frames.
fn assert_every_pose_once(session: &Path) {
    assert_eq!(sample_ids(session), all_ids(), "samples.yaml");
    let records = std::fs::read_dir(session.join("poses")).unwrap().count();
    assert_eq!(records, POSES, "one record per pose");
    assert!(session.join("result.yaml").is_file());
    let summary: serde_yaml_ng::Value = serde_yaml_ng::from_str(
        &std::fs::read_to_string(session.join("reprojection.yaml")).unwrap(),
    )
    .unwrap();
    let frames: Vec<String> = summary["frames"]
        .as_sequence()
        .unwrap()
        .iter()
        .map(|f| f["id"].as_str().unwrap().to_string())
        .collect();
    assert_eq!(frames, all_ids(), "the pixel fit's frames are the samples");
}

fn wait_for(path: &Path, child: &mut Child) {
    let deadline = Instant::now() + Duration::from_secs(120);
    while !path.exists() {
        assert!(
            Instant::now() < deadline,
            "{} never appeared",
            path.display()
        );
        assert!(
            child.try_wait().unwrap().is_none(),
            "the run ended before {} appeared",
            path.display()
        );
        std::thread::sleep(Duration::from_millis(20));
    }
}

fn signal(child: &Child, name: &str) {
    let status = Command::new("kill")
        .arg(format!("-{name}"))
        .arg(child.id().to_string())
        .status()
        .unwrap();
    assert!(status.success());
}

/// Issue #13 item 1 and the crash points around it: the process dies right after the frame,
/// right after the pose record (before `samples.yaml` — at the last pose, too, so the resume has
/// nothing left to visit), and right after `samples.yaml`. Every resume ends with each pose in
/// the result exactly once.
#[test]
fn killed_at_each_write_of_a_pose_the_resume_has_every_pose_exactly_once() {
    let dir = tempfile::tempdir().unwrap();
    let config = cell(dir.path(), 0.0);
    for (case, fault, index) in [
        (0, "abort-after-frame", 2),
        (1, "abort-after-record", 3),
        (2, "abort-after-samples", 5),
        (3, "abort-after-record", POSES - 1),
    ] {
        let session = dir.path().join(format!("s{case}"));
        let crashed =
            output(run_new(&config, &session).env("HANDEYE_FAULT", format!("{fault}:{index}")));
        assert!(!crashed.status.success(), "{fault}:{index} did not crash");
        // The crash happened where it was asked to.
        let record = session.join(format!("poses/{index:03}.yaml"));
        let frame = session.join(format!("frames/{index:03}.png"));
        let ids = sample_ids(&session);
        let id = format!("pose-{index:03}");
        match fault {
            "abort-after-frame" => assert!(frame.is_file() && !record.exists()),
            "abort-after-record" => assert!(record.is_file() && !ids.contains(&id), "{ids:?}"),
            _ => assert!(ids.contains(&id), "{ids:?}"),
        }

        let resumed = output(&mut resume(&session));
        let message = stderr(&resumed);
        assert!(resumed.status.success(), "{fault}:{index}: {message}");
        assert!(
            message.contains("took over the lock of process"),
            "the dead run's lock is reported: {message}"
        );
        assert_every_pose_once(&session);
    }
}

/// A real `kill -9` mid-run, with a temporary file of the size of a frame left behind as a kill
/// during a write leaves one: the resume removes it, says so, and finishes with every pose once.
#[test]
fn sigkill_mid_run_then_resume_cleans_temp_files_and_has_every_pose_once() {
    let dir = tempfile::tempdir().unwrap();
    let config = cell(dir.path(), 0.2);
    let session = dir.path().join("s");
    let mut child = run_new(&config, &session)
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    wait_for(&session.join("poses/002.yaml"), &mut child);
    child.kill().unwrap();
    child.wait().unwrap();
    let leftover = session.join("frames/.tmpK1LL9d");
    std::fs::write(&leftover, vec![0u8; 470_000]).unwrap();

    let resumed = output(&mut resume(&session));
    let message = stderr(&resumed);
    assert!(resumed.status.success(), "{message}");
    assert!(!leftover.exists(), "the temporary file is removed");
    // The kill itself may have left a temporary file of its own (a frame being written), so the
    // count is 1 or more, and nothing temporary is left anywhere in the folder.
    assert!(
        message.contains("unfinished temporary file(s)") && message.contains("kB)"),
        "{message}"
    );
    for dir in ["", "frames", "previews", "poses"] {
        for entry in std::fs::read_dir(session.join(dir)).unwrap() {
            let name = entry.unwrap().file_name();
            assert!(
                !handeye_core::atomic_file::is_temp_name(&name.to_string_lossy()),
                "{dir}/{name:?} left behind"
            );
        }
    }
    assert_every_pose_once(&session);
}

/// Issue #13 item 10: SIGTERM and SIGHUP stop the run the way Ctrl-C does — the arm stopped,
/// the samples kept, the lock released, a resume hint — instead of killing it at once.
#[test]
fn sigterm_and_sighup_take_the_ctrl_c_path_and_the_run_resumes() {
    let dir = tempfile::tempdir().unwrap();
    let config = cell(dir.path(), 0.3);
    for name in ["TERM", "HUP"] {
        let session = dir.path().join(format!("s-{name}"));
        let mut child = run_new(&config, &session)
            .stdout(Stdio::null())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap();
        wait_for(&session.join("poses/001.yaml"), &mut child);
        signal(&child, name);
        let out = child.wait_with_output().unwrap();
        let message = stderr(&out);
        assert!(!out.status.success(), "SIG{name}: {message}");
        assert!(
            out.status.code().is_some(),
            "SIG{name} must not kill the process outright: {:?}",
            out.status
        );
        assert!(
            message.contains("stopping the arm now")
                && message.contains("interrupted at plan pose"),
            "SIG{name}: {message}"
        );
        assert!(message.contains("--resume"), "SIG{name}: {message}");
        let lock = std::fs::read_to_string(session.join(".lock")).unwrap();
        assert!(
            lock.trim().is_empty(),
            "a clean stop releases the lock: {lock:?}"
        );
        if name == "TERM" {
            let resumed = output(&mut resume(&session));
            assert!(resumed.status.success(), "{}", stderr(&resumed));
            assert!(
                !stderr(&resumed).contains("took over the lock"),
                "{}",
                stderr(&resumed)
            );
            assert_every_pose_once(&session);
        }
    }
}

/// Issue #13 item 2: a second `run --resume DIR` while one runs is refused (naming the running
/// process), and of two `run --output DIR` started together exactly one runs.
#[test]
fn a_second_run_of_the_same_folder_is_refused_while_one_runs() {
    let dir = tempfile::tempdir().unwrap();
    let config = cell(dir.path(), 0.2);
    let session = dir.path().join("s");
    let crashed = output(run_new(&config, &session).env("HANDEYE_FAULT", "abort-after-record:1"));
    assert!(!crashed.status.success());

    let first = resume(&session)
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    // The first resume holds the lock once it has written its PID into it.
    let pid = first.id().to_string();
    let deadline = Instant::now() + Duration::from_secs(60);
    while std::fs::read_to_string(session.join(".lock"))
        .unwrap_or_default()
        .trim()
        != pid
    {
        assert!(
            Instant::now() < deadline,
            "the first resume never took the lock"
        );
        std::thread::sleep(Duration::from_millis(10));
    }
    let second = output(&mut resume(&session));
    let message = stderr(&second);
    assert!(!second.status.success(), "{message}");
    assert!(
        message.contains(&format!("a run (pid {pid}) is recording this session")),
        "{message}"
    );
    let first = first.wait_with_output().unwrap();
    assert!(first.status.success(), "{}", stderr(&first));
    assert_every_pose_once(&session);

    // Two new runs into one folder, started together.
    let race = dir.path().join("race");
    let children: Vec<Child> = (0..2)
        .map(|_| {
            run_new(&config, &race)
                .stdout(Stdio::null())
                .stderr(Stdio::piped())
                .spawn()
                .unwrap()
        })
        .collect();
    let outputs: Vec<Output> = children
        .into_iter()
        .map(|c| c.wait_with_output().unwrap())
        .collect();
    let succeeded = outputs.iter().filter(|o| o.status.success()).count();
    assert_eq!(
        succeeded,
        1,
        "exactly one run owns the folder: {:?}",
        outputs.iter().map(stderr).collect::<Vec<_>>()
    );
    let refused = outputs.iter().find(|o| !o.status.success()).unwrap();
    let message = stderr(refused);
    // The loser may see the lock before the winner has written its PID into it ("a run is
    // recording"), or the folder already made ("already exists").
    assert!(
        message.contains("is recording this session") || message.contains("already exists"),
        "{message}"
    );
    assert_every_pose_once(&race);
}

/// Issue #13 item 3: Ctrl-C (here a crash) after some poses, fx/fy edited 800 → 840 in the
/// camera file, resume: refused, naming the file and both hashes; `--accept-changed` resumes.
#[test]
fn resume_refuses_changed_intrinsics_unless_accepted() {
    let dir = tempfile::tempdir().unwrap();
    let config = cell(dir.path(), 0.0);
    let session = dir.path().join("s");
    let crashed = output(run_new(&config, &session).env("HANDEYE_FAULT", "abort-after-samples:3"));
    assert!(!crashed.status.success());
    let manifest: serde_yaml_ng::Value =
        serde_yaml_ng::from_str(&std::fs::read_to_string(session.join("session.yaml")).unwrap())
            .unwrap();
    let recorded_hash = manifest["inputs"]
        .as_sequence()
        .unwrap()
        .iter()
        .find(|i| i["role"].as_str() == Some("intrinsics"))
        .unwrap()["sha256"]
        .as_str()
        .unwrap()
        .to_string();
    let camera = dir.path().join("camera.yaml");
    let text = std::fs::read_to_string(&camera).unwrap();
    let edited = text.replace(
        "data: [800.0, 0.0, 641.3, 0.0, 800.0,",
        "data: [840.0, 0.0, 641.3, 0.0, 840.0,",
    );
    assert_ne!(text, edited);
    std::fs::write(&camera, &edited).unwrap();
    let new_hash = handeye_records::inputs::sha256_hex(edited.as_bytes());

    let refused = output(&mut resume(&session));
    let message = stderr(&refused);
    assert!(!refused.status.success(), "{message}");
    assert!(
        message.contains("changed since the session was recorded")
            && message.contains("intrinsics")
            && message.contains("camera.yaml")
            && message.contains(&recorded_hash[..16])
            && message.contains(&new_hash[..16])
            && message.contains("--accept-changed"),
        "{message}"
    );
    assert!(
        !message.contains("- config") && !message.contains("- target"),
        "only the edited file is listed: {message}"
    );
    assert_eq!(
        std::fs::read_dir(session.join("poses")).unwrap().count(),
        4,
        "nothing was visited"
    );

    let accepted = output(resume(&session).arg("--accept-changed"));
    let message = stderr(&accepted);
    assert!(accepted.status.success(), "{message}");
    assert!(message.contains("input changed, accepted"), "{message}");
    assert_every_pose_once(&session);
}

/// Issue #13 item 10: a full disk while recording a pose stops the run with the resume hint,
/// and the resume finishes.
#[test]
fn a_full_disk_while_recording_stops_with_the_resume_hint() {
    let dir = tempfile::tempdir().unwrap();
    let config = cell(dir.path(), 0.0);
    let session = dir.path().join("s");
    let failed = output(run_new(&config, &session).env("HANDEYE_FAULT", "full-disk-at-record:4"));
    let message = stderr(&failed);
    assert!(!failed.status.success(), "{message}");
    assert!(
        message.contains("could not record plan pose 4")
            && message.contains(&format!("handeye run --resume {}", session.display()))
            && message.contains("poses/004.yaml")
            && message.contains("no space left on device"),
        "{message}"
    );
    let resumed = output(&mut resume(&session));
    assert!(resumed.status.success(), "{}", stderr(&resumed));
    assert_every_pose_once(&session);
}

/// Issue #13 item 10: a run killed between creating its folder and writing `session.yaml`
/// leaves a folder a new run with `--output` accepts; `--resume` of it says what to do.
#[test]
fn a_folder_left_before_session_yaml_is_reusable_and_resume_says_how() {
    let dir = tempfile::tempdir().unwrap();
    let config = cell(dir.path(), 0.0);
    let session = dir.path().join("s");
    for sub in ["poses", "frames", "previews"] {
        std::fs::create_dir_all(session.join(sub)).unwrap();
    }
    std::fs::write(session.join(".lock"), "4194999\n").unwrap();
    std::fs::write(session.join(".tmpAbC123"), "half a manifest").unwrap();

    let refused = output(&mut resume(&session));
    let message = stderr(&refused);
    assert!(!refused.status.success());
    assert!(
        message.contains("no session.yaml") && message.contains("--output"),
        "{message}"
    );
    let started = output(&mut run_new(&config, &session));
    assert!(started.status.success(), "{}", stderr(&started));
    assert!(!session.join(".tmpAbC123").exists());
    assert_every_pose_once(&session);
}

/// Issue #30: a session that stopped before it recorded any pose (here killed after its first
/// frame, before that pose's record) resumes after its inputs were fixed without
/// `--accept-changed`: there is nothing recorded the change could contradict.
#[test]
fn a_session_that_recorded_nothing_resumes_with_changed_inputs() {
    let dir = tempfile::tempdir().unwrap();
    let config = cell(dir.path(), 0.0);
    let session = dir.path().join("s");
    // The plan is visited in its given order (`reorder: false`): pose 0 first.
    let crashed = output(run_new(&config, &session).env("HANDEYE_FAULT", "abort-after-frame:0"));
    assert!(!crashed.status.success());
    assert!(
        std::fs::read_dir(session.join("poses"))
            .unwrap()
            .next()
            .is_none(),
        "no pose recorded"
    );
    // The person fixes the intrinsics file (same lens, written again with another comment).
    let intrinsics = dir.path().join("camera.yaml");
    let text = std::fs::read_to_string(&intrinsics).unwrap();
    std::fs::write(&intrinsics, format!("# fixed\n{text}")).unwrap();
    let resumed = output(&mut resume(&session));
    let err = stderr(&resumed);
    assert!(resumed.status.success(), "{err}");
    assert!(
        err.contains("input changed, accepted (nothing was recorded yet)"),
        "{err}"
    );
    assert_every_pose_once(&session);

    // With poses recorded, a changed input is still refused without --accept-changed.
    std::fs::write(&intrinsics, format!("# changed again\n{text}")).unwrap();
    let refused = output(&mut resume(&session));
    assert!(!refused.status.success());
    assert!(
        stderr(&refused).contains("--accept-changed"),
        "{}",
        stderr(&refused)
    );
}
