//! Issue #44: every command on a session folder looks for the run recording it first, and names
//! it ("a run (pid N) is recording this session: K poses so far"): `solve`, `report`, `verify`
//! go on and say their answer is provisional; `replay` and `run --resume` refuse. Before the
//! run's first pose nothing is said to be a run that stopped.
//!
//! The run is this test process: it takes the folder's lock the way a run does
//! (`SessionFolder::create`, `SessionLock::acquire`), so the commands see a live lock with this
//! PID in it.

use std::path::Path;
use std::process::Output;

use handeye_records::{SessionFolder, SessionLock};

use crate::util::{handeye, sim_cell};

fn text(out: &Output) -> String {
    format!(
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    )
}

/// Runs `handeye args... dir`, where `dir` is the session folder.
fn on(args: &[&str], dir: &Path) -> Output {
    handeye().args(args).arg(dir).output().unwrap()
}

/// The five commands on a session folder, each with what it must do while a run records it:
/// go on (`true`) or refuse.
const COMMANDS: [(&[&str], bool); 5] = [
    (&["solve"], true),
    (&["report"], true),
    (&["verify", "--session"], true),
    (&["replay"], false),
    (&["run", "--resume"], false),
];

fn names_the_run(log: &str, poses: usize) -> bool {
    log.contains(&format!(
        "a run (pid {}) is recording this session: {poses} poses so far",
        std::process::id()
    ))
}

/// What none of them may say of a live session: that a run stopped, or to start anew.
fn says_nothing_of_a_stopped_run(log: &str) {
    for wrong in [
        "stopped before it wrote session.yaml",
        "start a new session",
        "start it again",
        "is not a session folder",
    ] {
        assert!(
            !log.contains(wrong),
            "{wrong:?} said of a live session: {log}"
        );
    }
}

#[test]
fn before_the_first_pose_every_command_names_the_live_run() {
    let dir = tempfile::tempdir().unwrap();
    let config = sim_cell(dir.path(), 4);
    let session = dir.path().join("session");
    // The run's first step: the folder created and locked, nothing else written yet.
    let run = SessionFolder::create(&session).unwrap();
    for (args, _) in COMMANDS {
        let out = on(args, &session);
        let log = text(&out);
        println!("{args:?}: {log}");
        assert_eq!(out.status.code(), Some(1), "{args:?}: {log}");
        assert!(names_the_run(&log, 0), "{args:?}: {log}");
        assert!(log.contains("session.yaml"), "{args:?}: {log}");
        says_nothing_of_a_stopped_run(&log);
    }
    // Its next: session.yaml written (the plan), no pose yet.
    handeye()
        .args(["run", "--config"])
        .arg(&config)
        .arg("--output")
        .arg(dir.path().join("finished"))
        .output()
        .unwrap();
    std::fs::copy(
        dir.path().join("finished/session.yaml"),
        session.join("session.yaml"),
    )
    .unwrap();
    for (args, _) in COMMANDS {
        let out = on(args, &session);
        let log = text(&out);
        println!("{args:?} (session.yaml written): {log}");
        assert_eq!(out.status.code(), Some(1), "{args:?}: {log}");
        assert!(names_the_run(&log, 0), "{args:?}: {log}");
        says_nothing_of_a_stopped_run(&log);
    }
    drop(run);
    // Released: the folder is what a run killed before its first pose leaves.
    let log = text(&on(&["replay"], &dir.path().join("nothing-here")));
    assert!(!names_the_run(&log, 0), "{log}");
}

#[test]
fn after_several_poses_solve_report_verify_are_provisional_and_replay_resume_refuse() {
    let dir = tempfile::tempdir().unwrap();
    let config = sim_cell(dir.path(), 6);
    let session = dir.path().join("session");
    let out = crate::util::run_cli(&config, &session);
    assert!(out.status.success(), "{}", text(&out));
    let poses = std::fs::read_dir(session.join("poses")).unwrap().count();
    assert_eq!(poses, 6);
    // A run resumed on it, as `run --resume` takes the lock.
    let run = SessionLock::acquire(&session).unwrap();
    for (args, goes_on) in COMMANDS {
        let out = on(args, &session);
        let log = text(&out);
        println!("{args:?}: {log}");
        assert!(names_the_run(&log, poses), "{args:?}: {log}");
        says_nothing_of_a_stopped_run(&log);
        if goes_on {
            assert!(out.status.success(), "{args:?}: {log}");
            assert!(log.contains("provisional"), "{args:?}: {log}");
        } else {
            assert_eq!(out.status.code(), Some(1), "{args:?}: {log}");
        }
    }
    // What solve and report write says so too.
    let result = std::fs::read_to_string(session.join("result-reprojection.yaml")).unwrap();
    assert!(result.contains("kind: provisional"), "{result}");
    let report = std::fs::read_to_string(session.join("report.html")).unwrap();
    assert!(report.contains("is recording this session"), "report.html");
    // The lock the test holds is left as it was: a second run is still refused.
    assert!(SessionLock::acquire(&session).is_err());
    drop(run);
    // The run ended: the same commands say nothing of it.
    let out = on(&["solve"], &session);
    let log = text(&out);
    assert!(out.status.success(), "{log}");
    assert!(!log.contains("provisional"), "{log}");
}
