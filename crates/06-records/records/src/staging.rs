//! Staging folders: a folder written next to its destination and renamed into place once
//! complete, so a command that fails leaves nothing behind (`import bag` stages its session this
//! way).
//!
//! A staging folder `<parent>/.<name>.<tag>-XXXXXX` is held for its whole life by an exclusive
//! lock (`fs4`, as the session lock) on the file beside it, `<parent>/.<name>.<tag>-XXXXXX.lock`,
//! which names the owner's PID. The operating system drops the lock when the owner ends however
//! it ends (even `kill -9`), so a staging folder whose lock can be taken belongs to a process that
//! was killed: [`remove_abandoned`] removes those (and a folder without a lock file, which only
//! a process killed before this lock existed leaves) and leaves alone the ones a running process
//! still holds. The lock file is made and locked before its folder, checked after locking to be
//! still the file at its path, and removed only after the folder is gone, so a cleanup racing a
//! new or finishing staging folder never removes a live one.
//!
//! Depends on nothing of the session but its error type.

use std::fs::{File, OpenOptions};
use std::io::Write;
use std::path::{Path, PathBuf};

use fs4::{FileExt, TryLockError};

use handeye_core::atomic_file::same_file;

use super::lock::read_pid;
use super::SessionError;

/// A staging folder and the lock that holds it; removed on drop unless committed.
#[derive(Debug)]
pub struct Staging {
    dir: PathBuf,
    lock_path: PathBuf,
    /// Held open (and so locked) until drop.
    lock: File,
    committed: bool,
}

fn io(path: &Path) -> impl FnOnce(std::io::Error) -> SessionError + '_ {
    move |source| SessionError::Io {
        path: path.to_path_buf(),
        source,
    }
}

impl Staging {
    /// Creates and locks a staging folder `.<name>.<tag>-XXXXXX` in `parent` (which must exist).
    pub fn create(parent: &Path, name: &str, tag: &str) -> Result<Staging, SessionError> {
        for _ in 0..16 {
            let (file, lock_path) = tempfile::Builder::new()
                .prefix(&format!(".{name}.{tag}-"))
                .suffix(".lock")
                .tempfile_in(parent)
                .map_err(io(parent))?
                .keep()
                .map_err(|e| SessionError::Io {
                    path: parent.to_path_buf(),
                    source: e.error,
                })?;
            // A cleanup that took this file before us removed it: start again with a new name.
            if FileExt::try_lock(&file).is_err() || !same_file(&file, &lock_path) {
                continue;
            }
            let dir = lock_path.with_extension("");
            match std::fs::create_dir(&dir) {
                Ok(()) => {}
                // A leftover of an older version with the same name: let the cleanup have it.
                Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => {
                    let _ = std::fs::remove_file(&lock_path);
                    continue;
                }
                Err(e) => {
                    let _ = std::fs::remove_file(&lock_path);
                    return Err(io(&dir)(e));
                }
            }
            let staging = Staging {
                dir,
                lock_path,
                lock: file,
                committed: false,
            };
            // The PID, for the message of a cleanup that finds the folder in use.
            writeln!(&staging.lock, "{}", std::process::id()).map_err(io(&staging.lock_path))?;
            return Ok(staging);
        }
        Err(SessionError::Io {
            path: parent.to_path_buf(),
            source: std::io::Error::other("no staging folder could be created and locked"),
        })
    }

    /// The staging folder.
    pub fn path(&self) -> &Path {
        &self.dir
    }

    /// Renames the folder to `destination` (absent, or an empty folder); on failure the staging
    /// folder is removed.
    pub fn commit(mut self, destination: &Path) -> Result<(), SessionError> {
        std::fs::rename(&self.dir, destination).map_err(io(destination))?;
        self.committed = true;
        Ok(())
    }
}

impl Drop for Staging {
    fn drop(&mut self) {
        if !self.committed {
            if let Err(e) = std::fs::remove_dir_all(&self.dir) {
                if e.kind() != std::io::ErrorKind::NotFound {
                    tracing::warn!("{}: could not be removed: {e}", self.dir.display());
                }
            }
        }
        // The folder is gone (renamed or removed): only now may the lock file go.
        let _ = std::fs::remove_file(&self.lock_path);
    }
}

/// What [`remove_abandoned`] found.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Leftover {
    /// Removed: its process had been killed (its lock could be taken, or it had none).
    Removed(PathBuf),
    /// Left alone: a running process holds its lock (with the PID it wrote, if readable).
    InUse(PathBuf, Option<u32>),
}

/// Removes the staging folders (`.<anything>.<tag>-*`) in `parent` whose process was killed and
/// the stray lock files of finished ones; leaves alone those still locked. A missing `parent` has
/// none.
pub fn remove_abandoned(parent: &Path, tag: &str) -> Result<Vec<Leftover>, SessionError> {
    let entries = match std::fs::read_dir(parent) {
        Ok(entries) => entries,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(Vec::new()),
        Err(e) => return Err(io(parent)(e)),
    };
    let marker = format!(".{tag}-");
    let mut found = Vec::new();
    let mut lone_locks = Vec::new();
    for entry in entries.filter_map(Result::ok) {
        let name = entry.file_name().to_string_lossy().into_owned();
        if !(name.starts_with('.') && name.contains(&marker)) {
            continue;
        }
        let path = entry.path();
        if name.ends_with(".lock") {
            lone_locks.push(path);
            continue;
        }
        if !path.is_dir() {
            continue;
        }
        let lock_path = parent.join(format!("{name}.lock"));
        let lock = match OpenOptions::new().read(true).write(true).open(&lock_path) {
            Ok(file) => Some(file),
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => None,
            Err(e) => return Err(io(&lock_path)(e)),
        };
        match lock {
            Some(mut file) => match FileExt::try_lock(&file) {
                Ok(()) if same_file(&file, &lock_path) => {
                    remove_dir(&path)?;
                    let _ = std::fs::remove_file(&lock_path);
                    found.push(Leftover::Removed(path));
                }
                // Removed by a concurrent cleanup since it was opened.
                Ok(()) => {}
                Err(TryLockError::WouldBlock) => {
                    found.push(Leftover::InUse(path, read_pid(&mut file)));
                }
                Err(TryLockError::Error(e)) => return Err(io(&lock_path)(e)),
            },
            None => {
                remove_dir(&path)?;
                found.push(Leftover::Removed(path));
            }
        }
    }
    for lock_path in lone_locks {
        let dir = lock_path.with_extension("");
        if dir.exists() {
            continue;
        }
        let Ok(file) = OpenOptions::new().read(true).write(true).open(&lock_path) else {
            continue;
        };
        // Locked: a staging folder being created (its folder comes next), or a process that has
        // just finished with it. Free and still without its folder: a finished one's leftover.
        if FileExt::try_lock(&file).is_ok() && same_file(&file, &lock_path) && !dir.exists() {
            let _ = std::fs::remove_file(&lock_path);
        }
    }
    found.sort_by(|a, b| format!("{a:?}").cmp(&format!("{b:?}")));
    Ok(found)
}

fn remove_dir(path: &Path) -> Result<(), SessionError> {
    match std::fs::remove_dir_all(path) {
        Err(e) if e.kind() != std::io::ErrorKind::NotFound => Err(io(path)(e)),
        _ => Ok(()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn killed_staging_is_removed_and_a_live_one_kept() {
        let dir = tempfile::tempdir().unwrap();
        let live = Staging::create(dir.path(), "out", "importing").unwrap();
        std::fs::write(live.path().join("a"), "x").unwrap();
        // As a killed run leaves them: a folder with an unlocked lock file, one without any.
        let killed = dir.path().join(".out.importing-abc123");
        std::fs::create_dir(&killed).unwrap();
        std::fs::write(dir.path().join(".out.importing-abc123.lock"), "4194999\n").unwrap();
        let old = dir.path().join(".other.importing-XYZ");
        std::fs::create_dir(&old).unwrap();
        let found = remove_abandoned(dir.path(), "importing").unwrap();
        assert!(
            found.contains(&Leftover::Removed(killed.clone())),
            "{found:?}"
        );
        assert!(found.contains(&Leftover::Removed(old.clone())), "{found:?}");
        assert!(
            found.contains(&Leftover::InUse(
                live.path().to_path_buf(),
                Some(std::process::id())
            )),
            "{found:?}"
        );
        assert!(!killed.exists() && !old.exists() && live.path().join("a").exists());
        assert!(!dir.path().join(".out.importing-abc123.lock").exists());
        let target = dir.path().join("out");
        let staged = live.path().to_path_buf();
        live.commit(&target).unwrap();
        assert!(target.join("a").exists() && !staged.exists());
        let left: Vec<_> = std::fs::read_dir(dir.path()).unwrap().collect();
        assert_eq!(left.len(), 1, "only the committed folder: {left:?}");
        // Dropped without commit: gone, lock file too.
        let failed = Staging::create(dir.path(), "out2", "importing").unwrap();
        drop(failed);
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 1);
    }
}
