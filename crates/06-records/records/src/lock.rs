//! The session folder's lock: one process at a time runs or resumes a session.
//!
//! An advisory exclusive lock (`flock`-style, through `fs4`) on `<session>/.lock`, which holds
//! the owner's PID while it runs. The operating system drops the lock when the owner exits
//! however it ends (even `kill -9`), so a lock that can be taken while the file still names a PID
//! is stale: its owner died without releasing it, and the new process takes it over (and says
//! so). The file is emptied, not removed, on a clean release: removing a lock file lets a
//! second process lock a file a third one no longer sees.
//!
//! Readers (`solve`, `report`, `replay`, `verify`, ...) look whether a run holds the lock
//! ([`live_run`]) before they read: a session being recorded is named as such (the run's PID and
//! its poses so far), never mistaken for one a run left unfinished. The look takes the lock
//! shared for an instant; a run taking the lock in that instant waits for it
//! ([`SessionLock::acquire`] retries briefly), so a reader never refuses a run.
//!
//! Depends on nothing of the session but its error type.

use std::fs::{File, OpenOptions};
use std::io::{Read, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};
use std::time::Duration;

use fs4::{FileExt, TryLockError};

use super::SessionError;

/// The lock file's name inside a session folder.
pub const LOCK_FILE: &str = ".lock";

/// How often, and how far apart, [`SessionLock::acquire`] tries again when the lock is held: a
/// reader's [`live_run`] holds it for microseconds, a run for its whole length.
const ACQUIRE_TRIES: u32 = 20;
const ACQUIRE_PAUSE: Duration = Duration::from_millis(10);

/// A run holding a session folder's lock right now: the session is being recorded.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct LiveRun {
    /// The folder whose lock is held (a several-camera session's planner camera folder).
    pub folder: PathBuf,
    /// The PID the lock file names (the run writes it right after taking the lock).
    pub pid: Option<u32>,
    /// Pose records written so far (`poses/NNN.yaml`).
    pub poses: usize,
    /// Whether the run has written `session.yaml` yet (it does before its first pose).
    pub started: bool,
}

impl std::fmt::Display for LiveRun {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self.pid {
            Some(pid) => write!(f, "a run (pid {pid}) is recording this session")?,
            None => write!(f, "a run is recording this session")?,
        }
        write!(f, ": {} poses so far", self.poses)?;
        if !self.started {
            write!(f, " (it has not written session.yaml yet)")?;
        }
        Ok(())
    }
}

/// The run recording the session folder `root`, if one holds its lock now (a several-camera
/// session: the lock of any camera folder under `cameras/`). A folder without a lock file has no
/// run; a lock file whose owner died is not held.
pub fn live_run(root: &Path) -> Result<Option<LiveRun>, SessionError> {
    if let Some(run) = live_run_in(root)? {
        return Ok(Some(run));
    }
    let cameras = root.join("cameras");
    if !cameras.is_dir() {
        return Ok(None);
    }
    let Ok(entries) = std::fs::read_dir(&cameras) else {
        return Ok(None);
    };
    for entry in entries.filter_map(Result::ok) {
        if let Some(run) = live_run_in(&entry.path())? {
            return Ok(Some(run));
        }
    }
    Ok(None)
}

/// Refuses the session folder `root` while a run records it, for a command that must not read
/// it then (`replay` writes files the run writes too): the error names the run and says `next`.
pub fn refuse_live(root: &Path, next: &str) -> Result<(), SessionError> {
    match live_run(root)? {
        Some(run) => Err(SessionError::Recording {
            run,
            next: next.to_string(),
        }),
        None => Ok(()),
    }
}

fn live_run_in(folder: &Path) -> Result<Option<LiveRun>, SessionError> {
    let path = folder.join(LOCK_FILE);
    let io = |source| SessionError::Io {
        path: path.clone(),
        source,
    };
    // Read-only and never created: a reader leaves no trace in the folder. A lock file that
    // cannot be opened (none, a symlink loop, no permission) holds no run this look can see;
    // the read that follows names what is wrong with the folder.
    let Ok(mut file) = File::open(&path) else {
        return Ok(None);
    };
    match FileExt::try_lock_shared(&file) {
        Ok(()) => {
            // Nobody holds it: let go at once (a run may be about to take it).
            FileExt::unlock(&file).map_err(io)?;
            Ok(None)
        }
        Err(TryLockError::WouldBlock) => Ok(Some(LiveRun {
            folder: folder.to_path_buf(),
            pid: read_pid(&mut file),
            poses: pose_records(folder),
            started: folder.join("session.yaml").is_file(),
        })),
        Err(TryLockError::Error(source)) => Err(io(source)),
    }
}

/// The pose records (`poses/NNN.yaml`) in a session folder; temporary files are not records.
fn pose_records(folder: &Path) -> usize {
    std::fs::read_dir(folder.join("poses")).map_or(0, |entries| {
        entries
            .filter_map(Result::ok)
            .filter(|e| {
                let name = e.file_name();
                let name = name.to_string_lossy();
                name.ends_with(".yaml") && !handeye_core::atomic_file::is_temp_name(&name)
            })
            .count()
    })
}

/// An exclusive lock on a session folder, released (and the file emptied) on drop.
#[derive(Debug)]
pub struct SessionLock {
    file: File,
    path: PathBuf,
    stale_owner: Option<u32>,
}

impl SessionLock {
    /// Takes the lock of the session folder `root` (which must exist) and writes this process's
    /// PID into it. Fails with [`SessionError::Locked`] when another live process holds it.
    pub fn acquire(root: &Path) -> Result<SessionLock, SessionError> {
        let path = root.join(LOCK_FILE);
        let io = |source| SessionError::Io {
            path: path.clone(),
            source,
        };
        let mut file = OpenOptions::new()
            .read(true)
            .write(true)
            .create(true)
            .truncate(false)
            .open(&path)
            .map_err(io)?;
        let mut tries = 0;
        loop {
            match FileExt::try_lock(&file) {
                Ok(()) => break,
                // A reader's look (`live_run`) holds it for an instant: try again shortly.
                Err(TryLockError::WouldBlock) if tries < ACQUIRE_TRIES => {
                    tries += 1;
                    std::thread::sleep(ACQUIRE_PAUSE);
                }
                Err(TryLockError::WouldBlock) => {
                    return Err(SessionError::Locked {
                        run: LiveRun {
                            folder: root.to_path_buf(),
                            pid: read_pid(&mut file),
                            poses: pose_records(root),
                            started: root.join("session.yaml").is_file(),
                        },
                    })
                }
                Err(TryLockError::Error(source)) => return Err(io(source)),
            }
        }
        // Locked: whoever the file still names died without releasing it.
        let stale_owner = read_pid(&mut file).filter(|pid| *pid != std::process::id());
        file.set_len(0).map_err(io)?;
        file.seek(SeekFrom::Start(0)).map_err(io)?;
        writeln!(file, "{}", std::process::id()).map_err(io)?;
        file.sync_all().map_err(io)?;
        Ok(SessionLock {
            file,
            path,
            stale_owner,
        })
    }

    /// The PID a stale lock named when it was taken over (its process had ended without
    /// releasing it), if it was.
    pub fn stale_owner(&self) -> Option<u32> {
        self.stale_owner
    }

    /// The lock file.
    pub fn path(&self) -> &Path {
        &self.path
    }
}

impl Drop for SessionLock {
    fn drop(&mut self) {
        // An empty file marks a clean release; the lock itself goes with the handle.
        let _ = self.file.set_len(0);
        let _ = FileExt::unlock(&self.file);
    }
}

/// The pid a lock file holds (written by its owner), if it holds one.
pub(super) fn read_pid(file: &mut File) -> Option<u32> {
    let mut text = String::new();
    file.seek(SeekFrom::Start(0)).ok()?;
    file.read_to_string(&mut text).ok()?;
    text.trim().parse().ok()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_second_lock_is_refused_with_the_owner_pid_and_taken_after_release() {
        let dir = tempfile::tempdir().unwrap();
        let first = SessionLock::acquire(dir.path()).unwrap();
        assert_eq!(first.stale_owner(), None);
        let error = SessionLock::acquire(dir.path()).unwrap_err();
        match &error {
            SessionError::Locked { run } => assert_eq!(run.pid, Some(std::process::id())),
            other => panic!("{other}"),
        }
        assert!(error.to_string().contains(&std::process::id().to_string()));
        drop(first);
        let again = SessionLock::acquire(dir.path()).unwrap();
        assert_eq!(
            again.stale_owner(),
            None,
            "a clean release leaves no stale owner"
        );
    }

    #[test]
    fn a_held_lock_is_a_live_run_with_its_poses_and_a_released_one_is_not() {
        let dir = tempfile::tempdir().unwrap();
        assert_eq!(live_run(dir.path()).unwrap(), None, "no lock file");
        let lock = SessionLock::acquire(dir.path()).unwrap();
        let run = live_run(dir.path()).unwrap().expect("held");
        assert_eq!(run.pid, Some(std::process::id()));
        assert_eq!((run.poses, run.started), (0, false));
        assert!(run.to_string().contains(&format!(
            "a run (pid {}) is recording this session: 0 poses so far",
            std::process::id()
        )));
        std::fs::create_dir(dir.path().join("poses")).unwrap();
        for name in ["000.yaml", "001.yaml", ".001.yaml.tmp-1"] {
            std::fs::write(dir.path().join("poses").join(name), "x").unwrap();
        }
        std::fs::write(dir.path().join("session.yaml"), "x").unwrap();
        let run = live_run(dir.path()).unwrap().expect("held");
        assert_eq!((run.poses, run.started), (2, true));
        // The look left the lock as it was: the run still holds it, nobody else can take it.
        assert!(matches!(
            SessionLock::acquire(dir.path()),
            Err(SessionError::Locked { .. })
        ));
        drop(lock);
        assert_eq!(live_run(dir.path()).unwrap(), None, "released");
        // A lock file naming a process that died is not a live run.
        std::fs::write(dir.path().join(LOCK_FILE), "4194999\n").unwrap();
        assert_eq!(live_run(dir.path()).unwrap(), None);
    }

    #[test]
    fn a_lock_file_naming_a_dead_process_is_taken_over() {
        let dir = tempfile::tempdir().unwrap();
        std::fs::write(dir.path().join(LOCK_FILE), "4194999\n").unwrap();
        let lock = SessionLock::acquire(dir.path()).unwrap();
        assert_eq!(lock.stale_owner(), Some(4194999));
        let text = std::fs::read_to_string(lock.path()).unwrap();
        assert_eq!(text.trim(), std::process::id().to_string());
    }
}
