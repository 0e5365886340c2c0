//! Whole-or-nothing file writes: content goes to a temporary file in the destination's folder,
//! is flushed to disk, then renamed over the destination, so a crash or an error never leaves a
//! half-written file behind. The file ends with the mode a plain `File::create` gives it: a new
//! file `0o666` less the umask, a replaced file keeps its mode (a temporary file alone would be
//! `0o600`). The temporary files' names start with [`TEMP_PREFIX`], so a folder's owner can find
//! and remove the ones a killed writer left ([`is_temp_name`]). Depends on nothing of ours.

use std::io::Write;
use std::path::Path;

/// How the name of every temporary file [`write_atomic`] writes starts.
pub const TEMP_PREFIX: &str = ".tmp";

/// Whether a file name is one of [`write_atomic`]'s temporary files (left behind only when the
/// writing process was killed between creating and renaming it).
pub fn is_temp_name(name: &str) -> bool {
    name.starts_with(TEMP_PREFIX)
}

/// Writes `contents` to `path` atomically (temp file in the same folder, fsync, rename), with the
/// mode `File::create` would leave (see the module docs).
pub fn write_atomic(path: &Path, contents: &[u8]) -> std::io::Result<()> {
    let folder = match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p,
        _ => Path::new("."),
    };
    let mut builder = tempfile::Builder::new();
    builder.prefix(TEMP_PREFIX);
    // The kernel applies the umask to the mode asked for at creation, as for `File::create`.
    #[cfg(unix)]
    builder.permissions(std::os::unix::fs::PermissionsExt::from_mode(0o666));
    let mut temp = builder.tempfile_in(folder)?;
    if let Ok(existing) = std::fs::metadata(path) {
        if existing.is_file() {
            temp.as_file().set_permissions(existing.permissions())?;
        }
    }
    temp.write_all(contents)?;
    temp.as_file().sync_all()?;
    temp.persist(path).map_err(|e| e.error)?;
    Ok(())
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
        std::fs::File::create(&plain).unwrap();
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
    fn missing_folder_is_an_error_not_a_panic() {
        let dir = tempfile::tempdir().unwrap();
        assert!(write_atomic(&dir.path().join("no/such/dir/x.yaml"), b"x").is_err());
    }
}
