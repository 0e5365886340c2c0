//! Whole-or-nothing file writes: content goes to a temporary file in the destination's folder,
//! is flushed to disk, then renamed over the destination, so a crash or an error never leaves a
//! half-written file behind. The file ends with the mode a plain `File::create` gives it: a new
//! file `0o666` less the umask, a replaced file keeps its mode (a temporary file alone would be
//! `0o600`). Depends on nothing of ours.
//!
//! A killed writer (`kill -9` between creating and renaming) still leaves its temporary file, so
//! each is recognisable and owned: it is named `.<destination name>.<random><TEMP_SUFFIX>`
//! ([`is_temp_name`]) and its writer holds an advisory exclusive lock on it (`fs4`, `flock`)
//! until the rename. The operating system drops that lock when the writer dies, however it dies,
//! so a temporary file whose lock can be taken is a dead writer's and is removed
//! ([`remove_stale_temp_files`]); one whose lock is held belongs to a running writer and is left
//! alone. Every [`write_atomic`] first removes the stale temporary files of its kind in its
//! folder, whatever their destination, and names each one (a `tracing` warning; [`write_atomic_reporting`] returns them instead).

use std::fs::File;
use std::io::Write;
use std::path::{Path, PathBuf};

use fs4::{FileExt, TryLockError};

/// How the name of every temporary file [`write_atomic`] writes ends.
pub const TEMP_SUFFIX: &str = ".handeye-tmp";

/// How the names of the temporary files of versions before [`TEMP_SUFFIX`] start (`tempfile`'s
/// default, unlocked). Only a sweep of a folder its caller owns removes them (a session folder
/// under its lock, see [`remove_stale_temp_files`]): elsewhere another program's live temporary
/// file may have that name.
pub const LEGACY_TEMP_PREFIX: &str = ".tmp";

/// The longest part of the destination's name a temporary file's name repeats (file names are
/// at most 255 bytes).
const MAX_NAME_IN_TEMP: usize = 160;

/// How many random characters `tempfile` puts in a temporary file's name.
const RANDOM_LEN: usize = 6;

/// Whether a file name is one of [`write_atomic`]'s temporary files (left behind only when the
/// writing process was killed between creating and renaming it), or a temporary file of an
/// earlier version ([`LEGACY_TEMP_PREFIX`]).
pub fn is_temp_name(name: &str) -> bool {
    is_locked_temp_name(name) || name.starts_with(LEGACY_TEMP_PREFIX)
}

/// Whether `name` has the form `.<name>.<random><TEMP_SUFFIX>` of [`write_atomic`]'s temporary
/// files.
fn is_locked_temp_name(name: &str) -> bool {
    name.starts_with('.')
        && name.ends_with(TEMP_SUFFIX)
        && name.len() > 2 + RANDOM_LEN + TEMP_SUFFIX.len()
}

/// The start of the names of the temporary files of `destination` (`.<name>.`).
fn temp_prefix(destination: &Path) -> String {
    let name = destination
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    let mut end = name.len().min(MAX_NAME_IN_TEMP);
    while !name.is_char_boundary(end) {
        end -= 1;
    }
    format!(".{}.", &name[..end])
}

/// Whether `name` is a temporary file name of the destination whose prefix is `prefix`.
fn is_temp_of(name: &str, prefix: &str) -> bool {
    name.len() == prefix.len() + RANDOM_LEN + TEMP_SUFFIX.len()
        && name.starts_with(prefix)
        && name.ends_with(TEMP_SUFFIX)
}

/// A dead writer's temporary file that was removed.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RemovedTemp {
    /// The file.
    pub path: PathBuf,
    /// Its size, bytes.
    pub bytes: u64,
}

/// Which temporary files [`remove_stale_temp_files`] looks at.
#[derive(Debug, Clone, Copy)]
pub enum TempScope<'a> {
    /// Those of one destination file.
    Destination(&'a Path),
    /// Every temporary file of [`write_atomic`]'s own form (`.<name>.<random>.handeye-tmp`),
    /// whatever its destination: what [`write_atomic`] sweeps before writing (a killed
    /// `export -o a.yaml` leaves one that a later `export -o b.yaml` in the folder removes).
    /// The name is ours alone and its lock tells a live writer, so no other program's file is
    /// touched.
    Ours,
    /// Every temporary file in the folder, earlier versions' unlocked ones included: only for a
    /// folder the caller owns, where no other program writes (a session folder under its lock).
    OwnedFolder,
}

/// Removes the temporary files of killed writers in `folder` (those of `scope`): each whose lock
/// can be taken (its writer has ended) is removed, each whose lock is held (a writer still at
/// work, in this process or another) is left alone. Returns what was removed; a file that cannot
/// be opened or removed is skipped (it is not ours to fix here).
pub fn remove_stale_temp_files(folder: &Path, scope: TempScope<'_>) -> Vec<RemovedTemp> {
    let Ok(entries) = std::fs::read_dir(folder) else {
        return Vec::new();
    };
    let prefix = match scope {
        TempScope::Destination(destination) => Some(temp_prefix(destination)),
        TempScope::Ours | TempScope::OwnedFolder => None,
    };
    let mut removed = Vec::new();
    for entry in entries.flatten() {
        let name = entry.file_name();
        let name = name.to_string_lossy();
        let ours = match (&prefix, scope) {
            (Some(prefix), _) => is_temp_of(&name, prefix),
            (None, TempScope::Ours) => is_locked_temp_name(&name),
            (None, _) => is_temp_name(&name),
        };
        if !ours {
            continue;
        }
        let path = entry.path();
        // Beside live writers, an empty unlocked one may be a writer about to lock it; a folder
        // owned under its lock has no other writer.
        let grace = !matches!(scope, TempScope::OwnedFolder);
        if let Some(bytes) = remove_if_unlocked(&path, grace) {
            removed.push(RemovedTemp { path, bytes });
        }
    }
    removed.sort_by(|a, b| a.path.cmp(&b.path));
    removed
}

/// Removes the regular file `path` when its lock can be taken (with `grace`, not while it is
/// [`just_created`]); its size when removed.
fn remove_if_unlocked(path: &Path, grace: bool) -> Option<u64> {
    let before = std::fs::symlink_metadata(path).ok()?;
    if !before.is_file() || (grace && just_created(&before)) {
        return None;
    }
    let file = File::open(path).ok()?;
    match FileExt::try_lock(&file) {
        Ok(()) => {}
        Err(TryLockError::WouldBlock) | Err(TryLockError::Error(_)) => return None,
    }
    // Still the file that was locked (not renamed away and replaced meanwhile).
    if !same_file(&file, path) {
        return None;
    }
    std::fs::remove_file(path).ok()?;
    Some(before.len())
}

/// How long an empty, unlocked temporary file is taken for a writer still between creating and
/// locking it (an instant; under load, a little more): a killed writer's is removed by a sweep
/// after this, and a live one is neither removed (it would retry under another name) nor
/// reported as a killed write.
const JUST_CREATED: std::time::Duration = std::time::Duration::from_secs(10);

/// Whether a temporary file is empty and younger than [`JUST_CREATED`] (a modification time in
/// the future counts as young).
fn just_created(metadata: &std::fs::Metadata) -> bool {
    metadata.len() == 0
        && metadata.modified().is_ok_and(|modified| {
            std::time::SystemTime::now()
                .duration_since(modified)
                .map_or(true, |age| age < JUST_CREATED)
        })
}

/// Whether the open `file` is the file at `path` now (not removed, renamed away or replaced
/// since it was opened): what a lock on an open file proves about a path.
pub fn same_file(file: &File, path: &Path) -> bool {
    let (Ok(open), Ok(named)) = (file.metadata(), std::fs::symlink_metadata(path)) else {
        return false;
    };
    #[cfg(unix)]
    {
        use std::os::unix::fs::MetadataExt;
        open.dev() == named.dev() && open.ino() == named.ino()
    }
    #[cfg(not(unix))]
    {
        open.len() == named.len() && open.modified().ok() == named.modified().ok()
    }
}

/// Writes `contents` to `path` atomically (locked temporary file in the same folder, fsync,
/// rename), with the mode `File::create` would leave (see the module docs). The stale temporary
/// files of `path` that killed writers left are removed first, each named in a warning.
pub fn write_atomic(path: &Path, contents: &[u8]) -> std::io::Result<()> {
    write_atomic_with(path, |out| out.write_all(contents))?
}

/// [`write_atomic`], returning the stale temporary files of `path` it removed instead of
/// warning about them.
pub fn write_atomic_reporting(path: &Path, contents: &[u8]) -> std::io::Result<Vec<RemovedTemp>> {
    let (removed, written) = write_atomic_streamed(path, |out| out.write_all(contents))?;
    written?;
    Ok(removed)
}

/// [`write_atomic`] of what `write` writes to it (buffered), for a file too large to hold in
/// memory whole before it is written (a report of hundreds of frames). The outer error is the
/// file's (creating, syncing, renaming); the inner one `write`'s own, after which `path` is left
/// as it was and the temporary file removed, as after any failed write.
pub fn write_atomic_with<E>(
    path: &Path,
    write: impl FnOnce(&mut dyn Write) -> Result<(), E>,
) -> std::io::Result<Result<(), E>> {
    let (removed, written) = write_atomic_streamed(path, write)?;
    for removed in removed {
        tracing::warn!(
            "removed {} ({} bytes): the unfinished temporary file of a killed write of {}",
            removed.path.display(),
            removed.bytes,
            path.display()
        );
    }
    Ok(written)
}

/// The one atomic write: stale temporary files of `path` removed (returned), a locked temporary
/// file in its folder written by `write` through a buffer, synced and renamed over `path` —
/// unless `write` fails (its error returned inside, the temporary file removed).
fn write_atomic_streamed<E>(
    path: &Path,
    write: impl FnOnce(&mut dyn Write) -> Result<(), E>,
) -> std::io::Result<(Vec<RemovedTemp>, Result<(), E>)> {
    let folder = crate::folder_of(path);
    // Said of the folder, not of the temporary file the write would have made in it (whose
    // random name means nothing to the person who named `path`).
    match std::fs::metadata(folder) {
        Ok(m) if m.is_dir() => {}
        Ok(_) => {
            return Err(std::io::Error::new(
                std::io::ErrorKind::NotADirectory,
                format!("{} is a file, not a folder", folder.display()),
            ))
        }
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
            return Err(std::io::Error::new(
                std::io::ErrorKind::NotFound,
                format!("the folder {} does not exist", folder.display()),
            ))
        }
        Err(e) => return Err(e),
    }
    let removed = remove_stale_temp_files(folder, TempScope::Ours);
    let temp = locked_temp_file(folder, path)?;
    if let Ok(existing) = std::fs::metadata(path) {
        if existing.is_file() {
            temp.as_file().set_permissions(existing.permissions())?;
        }
    }
    let mut buffered = std::io::BufWriter::new(temp);
    if let Err(e) = write(&mut buffered) {
        // Dropping the temporary file removes it.
        return Ok((removed, Err(e)));
    }
    let temp = buffered.into_inner().map_err(|e| e.into_error())?;
    temp.as_file().sync_all()?;
    // The lock goes with the handle `persist` returns, after the rename.
    let _file = temp.persist(path).map_err(|e| e.error)?;
    Ok((removed, Ok(())))
}

/// A new temporary file for `destination` in `folder`, locked. A sweep by another process may
/// open and remove a new file in the instant before it is locked; then (the name no longer leads
/// to the locked file) another is made.
fn locked_temp_file(folder: &Path, destination: &Path) -> std::io::Result<tempfile::NamedTempFile> {
    let prefix = temp_prefix(destination);
    let mut last_error = None;
    for _ in 0..8 {
        let mut builder = tempfile::Builder::new();
        builder
            .prefix(&prefix)
            .suffix(TEMP_SUFFIX)
            .rand_bytes(RANDOM_LEN);
        // The kernel applies the umask to the mode asked for at creation, as for `File::create`.
        #[cfg(unix)]
        builder.permissions(std::os::unix::fs::PermissionsExt::from_mode(0o666));
        let temp = builder.tempfile_in(folder)?;
        match FileExt::try_lock(temp.as_file()) {
            Ok(()) if same_file(temp.as_file(), temp.path()) => return Ok(temp),
            Ok(()) => {
                // Removed by a sweep before the lock: keep the file out of `tempfile`'s drop,
                // which would remove whatever now has that name.
                let _ = temp.into_temp_path().keep();
            }
            Err(TryLockError::WouldBlock) => {
                // A sweep holds it and is about to remove it.
                let _ = temp.into_temp_path().keep();
            }
            Err(TryLockError::Error(e)) => last_error = Some(e),
        }
    }
    Err(last_error.unwrap_or_else(|| {
        std::io::Error::other(format!(
            "{}: could not create and lock a temporary file for {}",
            folder.display(),
            destination.display()
        ))
    }))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn replaces_whole_file_and_leaves_no_temp_behind() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("result.yaml");
        write_atomic(&path, b"first version, longer").unwrap();
        write_atomic(&path, b"second").unwrap();
        assert_eq!(std::fs::read(&path).unwrap(), b"second");
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 1);
    }

    #[cfg(unix)]
    #[test]
    fn new_files_get_the_umask_mode_and_replaced_files_keep_theirs() {
        use std::os::unix::fs::PermissionsExt;
        let dir = tempfile::tempdir().unwrap();
        let mode = |p: &Path| std::fs::metadata(p).unwrap().permissions().mode() & 0o777;
        // What a plain File::create gives here (0o666 less this process's umask).
        let plain = dir.path().join("plain");
        File::create(&plain).unwrap();
        let new = dir.path().join("new.yaml");
        write_atomic(&new, b"x").unwrap();
        assert_eq!(mode(&new), mode(&plain));
        // A file someone made group-writable (or private) keeps that mode when rewritten.
        for kept in [0o664, 0o600, 0o640] {
            std::fs::set_permissions(&new, std::fs::Permissions::from_mode(kept)).unwrap();
            write_atomic(&new, b"y").unwrap();
            assert_eq!(mode(&new), kept);
        }
    }

    #[test]
    fn missing_folder_is_an_error_naming_it_not_a_panic() {
        let dir = tempfile::tempdir().unwrap();
        let missing = dir.path().join("no/such/dir");
        let e = write_atomic(&missing.join("x.yaml"), b"x").unwrap_err();
        assert_eq!(e.kind(), std::io::ErrorKind::NotFound);
        assert_eq!(
            e.to_string(),
            format!("the folder {} does not exist", missing.display())
        );
        assert!(!dir.path().join("no").exists(), "a folder was made");
        // A file where the folder should be.
        let file = dir.path().join("file");
        std::fs::write(&file, b"x").unwrap();
        let e = write_atomic(&file.join("x.yaml"), b"x").unwrap_err();
        assert_eq!(
            e.to_string(),
            format!("{} is a file, not a folder", file.display())
        );
    }

    #[test]
    fn temp_names_are_recognised_per_destination() {
        let prefix = temp_prefix(Path::new("/x/out.yaml"));
        assert_eq!(prefix, ".out.yaml.");
        let name = format!("{prefix}AbC123{TEMP_SUFFIX}");
        assert!(is_temp_of(&name, &prefix) && is_temp_name(&name));
        assert!(!is_temp_of(&name, &temp_prefix(Path::new("other.yaml"))));
        assert!(!is_temp_of(".out.yaml", &prefix));
        // A long destination name keeps its temporary file's name within 255 bytes.
        let long = "é".repeat(120);
        assert!(temp_prefix(Path::new(&long)).len() <= MAX_NAME_IN_TEMP + 2);
    }

    /// A writer between creating its temporary file and locking it leaves it empty and unlocked
    /// for an instant: a sweep then (another thread's write into the folder) leaves it, where it
    /// used to remove it and warn of a killed write; an empty one left by a writer killed there
    /// goes once it is older than a live writer's could be.
    #[test]
    fn an_empty_temp_being_created_is_left_and_an_old_one_removed() {
        let dir = tempfile::tempdir().unwrap();
        let creating = dir.path().join(format!(".003.png.Cr3ate{TEMP_SUFFIX}"));
        File::create(&creating).unwrap();
        let removed = write_atomic_reporting(&dir.path().join("004.png"), b"png").unwrap();
        assert!(removed.is_empty() && creating.exists(), "{removed:?}");
        let old = std::time::SystemTime::now() - JUST_CREATED * 2;
        File::options()
            .write(true)
            .open(&creating)
            .unwrap()
            .set_modified(old)
            .unwrap();
        let removed = write_atomic_reporting(&dir.path().join("005.png"), b"png").unwrap();
        assert_eq!(
            removed,
            vec![RemovedTemp {
                path: creating.clone(),
                bytes: 0
            }]
        );
        assert!(!creating.exists());
        // A folder owned under its lock (a resumed session's) has no writer between creating and
        // locking: its sweep takes a young empty one too.
        File::create(&creating).unwrap();
        let removed = remove_stale_temp_files(dir.path(), TempScope::OwnedFolder);
        assert_eq!(removed.len(), 1);
        assert!(!creating.exists());
    }

    #[test]
    fn stale_temps_of_every_destination_are_removed_and_locked_ones_kept() {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("out.yaml");
        let stale = dir.path().join(format!(".out.yaml.Kil1ed{TEMP_SUFFIX}"));
        let live = dir.path().join(format!(".out.yaml.L1veXX{TEMP_SUFFIX}"));
        let other = dir.path().join(format!(".other.yaml.Kil1ed{TEMP_SUFFIX}"));
        let foreign = dir.path().join(".tmpAbC123");
        for p in [&stale, &live, &other, &foreign] {
            std::fs::write(p, b"half").unwrap();
        }
        // Another writer (here another open file of this process: flock locks are per open
        // file) is still writing `live`.
        let holder = File::open(&live).unwrap();
        FileExt::try_lock(&holder).unwrap();
        // A dead writer's file of another destination goes too (it is ours by its name); an
        // earlier version's unlocked one is not (the name could be another program's).
        let removed = write_atomic_reporting(&out, b"whole").unwrap();
        assert_eq!(
            removed,
            vec![
                RemovedTemp {
                    path: other.clone(),
                    bytes: 4
                },
                RemovedTemp {
                    path: stale.clone(),
                    bytes: 4
                }
            ]
        );
        assert!(!stale.exists() && live.exists() && !other.exists() && foreign.exists());
        assert_eq!(std::fs::read(&out).unwrap(), b"whole");
        // Once its writer is gone, the next write removes it too.
        drop(holder);
        let removed = write_atomic_reporting(&out, b"again").unwrap();
        assert_eq!(removed.len(), 1);
        assert!(!live.exists());
        // An owned folder's sweep takes every temporary file, earlier versions' too.
        let removed = remove_stale_temp_files(dir.path(), TempScope::OwnedFolder);
        assert_eq!(removed.len(), 1);
        assert!(!foreign.exists());
    }
}
