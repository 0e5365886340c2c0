//! The session folder's lock: one process at a time runs or resumes a session.
//!
//! An advisory exclusive lock (`flock`-style, through `fs4`) on `<session>/.lock`, which holds
//! the owner's PID while it runs. The operating system drops the lock when the owner exits
//! however it ends (even `kill -9`), so a lock that can be taken while the file still names a PID
//! is stale: its owner died without releasing it, and the new process takes it over (and says
//! so). The file is emptied, not removed, on a clean release: removing a lock file lets a
//! second process lock a file a third one no longer sees.
//!
//! Depends on nothing of the session but its error type.

use std::fs::{File, OpenOptions};
use std::io::{Read, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};

use fs4::{FileExt, TryLockError};

use super::SessionError;

/// The lock file's name inside a session folder.
pub const LOCK_FILE: &str = ".lock";

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
        match FileExt::try_lock(&file) {
            Ok(()) => {}
            Err(TryLockError::WouldBlock) => {
                return Err(SessionError::Locked {
                    folder: root.to_path_buf(),
                    owner: read_pid(&mut file),
                })
            }
            Err(TryLockError::Error(source)) => return Err(io(source)),
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
            SessionError::Locked { owner, .. } => assert_eq!(*owner, Some(std::process::id())),
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
    fn a_lock_file_naming_a_dead_process_is_taken_over() {
        let dir = tempfile::tempdir().unwrap();
        std::fs::write(dir.path().join(LOCK_FILE), "4194999\n").unwrap();
        let lock = SessionLock::acquire(dir.path()).unwrap();
        assert_eq!(lock.stale_owner(), Some(4194999));
        let text = std::fs::read_to_string(lock.path()).unwrap();
        assert_eq!(text.trim(), std::process::id().to_string());
    }
}
