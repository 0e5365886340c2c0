//! Reading and writing the tool's YAML files: one reader (serde through `serde_path_to_error`, so
//! every shape error names the YAML path, located at the key's own line by `key_line` where
//! the parser's location is missing or wrong), one atomic writer, and the one error type they share
//! ([`FileError`]: the message names the file, the YAML path and the problem). Used by datasets,
//! results, cell configs, plans, session records and recorded robot poses. Depends on
//! `atomic_file` and `geometry` only.

use std::path::{Path, PathBuf};

use serde::Serialize;

use crate::atomic_file::write_atomic;
use crate::geometry::PoseError;

/// What went wrong reading or writing one of the tool's YAML files (dataset, result, cell
/// config, plan, session records): the message names the file and the YAML path.
#[derive(Debug, thiserror::Error)]
pub enum FileError {
    /// The file could not be read.
    #[error("{}: cannot read", path.display())]
    Read {
        /// The file.
        path: PathBuf,
        /// The I/O error.
        #[source]
        source: std::io::Error,
    },
    /// The file is larger than any file of its kind could be (a device, a wrong path, a file
    /// grown without end): refused before it is read into memory.
    #[error("{}: cannot read: larger than {} MiB, far beyond any config, plan, record or result file (is it the right file?)", path.display(), MAX_TEXT_BYTES >> 20)]
    TooLarge {
        /// The file.
        path: PathBuf,
    },
    /// The file's path does not resolve: a symbolic link in it leads back to itself.
    #[error("{}: cannot read: symlink loop at {}", path.display(), at.display())]
    SymlinkLoop {
        /// The file.
        path: PathBuf,
        /// The link (the file itself or a folder above it) where resolving goes round in circles.
        at: PathBuf,
    },
    /// The file could not be written.
    #[error("{}: cannot write", path.display())]
    Write {
        /// The file.
        path: PathBuf,
        /// The I/O error.
        #[source]
        source: std::io::Error,
    },
    /// The YAML does not have the expected shape (unknown key, wrong type, missing key...).
    // The serde error is part of the message (it is the problem itself, with no further cause),
    // so it is not also a `#[source]`: `{:#}` chains would print it twice.
    #[error("{}: {}", path.display(), shape_message(.yaml_path, .problem, *.line))]
    Shape {
        /// The file.
        path: PathBuf,
        /// YAML path of the problem (`.` for the document root).
        yaml_path: String,
        /// What serde found.
        problem: serde_yaml_ng::Error,
        /// The 1-based line of the key `yaml_path` names, when the parser's own location is
        /// missing or points elsewhere (an enclosing section read as a whole); `None`: the
        /// parser's location stands.
        line: Option<usize>,
    },
    /// A pose with a bad value.
    #[error("{}: {problem}", path.display())]
    Pose {
        /// The file.
        path: PathBuf,
        /// The pose problem, with its YAML path (in the message, so not a `#[source]`).
        problem: PoseError,
    },
    /// Any other bad value.
    #[error("{}: {yaml_path}: {problem}", path.display())]
    Value {
        /// The file.
        path: PathBuf,
        /// YAML path of the value.
        yaml_path: String,
        /// What is wrong.
        problem: String,
    },
    /// The file is another of the tool's files than the one expected (a result given where a
    /// dataset belongs, say).
    #[error("this is a {found} ({}), not a {expected}: {hint}", path.display())]
    WrongKind {
        /// The file.
        path: PathBuf,
        /// What the file is (`result file`).
        found: &'static str,
        /// What was expected (`dataset`).
        expected: &'static str,
        /// What to give instead.
        hint: &'static str,
    },
    /// Serialising failed (should not happen for valid data).
    #[error("{}: cannot serialise", path.display())]
    Serialise {
        /// The file.
        path: PathBuf,
        /// The serde error.
        #[source]
        source: serde_yaml_ng::Error,
    },
}

/// `<yaml path>: <problem>[ at line N]`, the path once: serde_yaml_ng starts some messages with
/// the path (or the enclosing section's path), which is dropped. With `line`, the parser's own
/// location (`at line L column C`) is replaced by the key's line.
fn shape_message(yaml_path: &str, problem: &serde_yaml_ng::Error, line: Option<usize>) -> String {
    let mut problem = plain_parser_message(problem);
    if let Some((prefix, rest)) = problem.split_once(": ") {
        let is_path_prefix = yaml_path == prefix
            || yaml_path.starts_with(&format!("{prefix}."))
            || yaml_path.starts_with(&format!("{prefix}["));
        if is_path_prefix {
            problem = rest.to_string();
        }
    }
    if let Some(line) = line {
        if let Some(at) = problem.rfind(" at line ") {
            problem.truncate(at);
        }
        problem = format!("{problem} at line {line}");
    }
    format!("{yaml_path}: {problem}")
}

/// The shape error of `text` (the file at `path`) at `yaml_path`: with the key's own line when
/// the parser's location is missing or before the key (a section read as a whole).
pub fn shape_error(
    text: &str,
    path: &Path,
    yaml_path: String,
    problem: serde_yaml_ng::Error,
) -> FileError {
    let key = key_line(text, &yaml_path);
    let line = match (problem.location(), key) {
        (Some(location), Some(key)) if location.line() >= key => None,
        (_, key) => key,
    };
    FileError::Shape {
        path: path.to_path_buf(),
        yaml_path,
        problem,
        line,
    }
}

/// The 1-based line of the key a YAML path (`camera.noise_sigma`, `samples[3].T_base_flange`)
/// names in `text`, found by indentation (block style) or on the line (flow style); `None`
/// when a key is not found (an index past the end of a list gives the list's line). A reading
/// aid for messages, not a parser: comments are skipped, quoted keys are not looked for.
pub fn key_line(text: &str, yaml_path: &str) -> Option<usize> {
    let lines: Vec<&str> = text.lines().collect();
    let indent = |line: &str| line.len() - line.trim_start().len();
    let is_content = |line: &str| {
        let t = line.trim_start();
        !t.is_empty() && !t.starts_with('#')
    };
    // The lines after `at` that belong to a node starting in column `column` of line `at`.
    let block_end = |at: usize, column: usize| {
        (at + 1..lines.len())
            .find(|&i| is_content(lines[i]) && indent(lines[i]) <= column)
            .unwrap_or(lines.len())
    };
    // The column of `key` as a mapping key in `line`.
    let key_column = |line: &str, key: &str| -> Option<usize> {
        if !is_content(line) {
            return None;
        }
        let body = line.trim_start();
        let body = body.strip_prefix("- ").map(str::trim_start).unwrap_or(body);
        let start = line.len() - body.len();
        if body.starts_with(&format!("{key}:")) {
            return Some(start);
        }
        ["{", ", ", ",", "{ "].iter().find_map(|before| {
            line.find(&format!("{before}{key}:"))
                .map(|at| at + before.len())
        })
    };
    let (mut start, mut end) = (0, lines.len());
    let mut found = None;
    for part in yaml_path.split('.') {
        let (key, indices) = part.split_at(part.find('[').unwrap_or(part.len()));
        if !key.is_empty() {
            let (at, column) =
                (start..end).find_map(|i| key_column(lines[i], key).map(|c| (i, c)))?;
            found = Some(at);
            (start, end) = (at, block_end(at, column));
        }
        for index in indices
            .split(['[', ']'])
            .filter_map(|i| i.parse::<usize>().ok())
        {
            let items: Vec<usize> = (start + 1..end)
                .filter(|&i| lines[i].trim_start().starts_with('-'))
                .collect();
            let Some(item_indent) = items.iter().map(|&i| indent(lines[i])).min() else {
                return found.map(|at| at + 1);
            };
            let Some(&item) = items
                .iter()
                .filter(|&&i| indent(lines[i]) == item_indent)
                .nth(index)
            else {
                return found.map(|at| at + 1);
            };
            found = Some(item);
            (start, end) = (item, block_end(item, item_indent));
        }
    }
    found.map(|at| at + 1)
}

/// The parser's message with the Rust type names serde puts in it (`expected struct PoseYaml`)
/// replaced by what the YAML should hold (`expected a pose mapping (...)`).
pub fn plain_parser_message(problem: &serde_yaml_ng::Error) -> String {
    let mut text = problem.to_string();
    for kind in [
        "expected tuple struct ",
        "expected struct ",
        "expected enum ",
    ] {
        while let Some(at) = text.find(kind) {
            let name_start = at + kind.len();
            let name_len = text[name_start..]
                .find(|c: char| !(c.is_ascii_alphanumeric() || c == '_'))
                .unwrap_or(text.len() - name_start);
            let name = &text[name_start..name_start + name_len];
            let words = yaml_words(name, kind == "expected enum ");
            text.replace_range(at..name_start + name_len, &format!("expected {words}"));
        }
    }
    // Rust's number types, as the YAML should hold them.
    for (rust, yaml) in [
        ("usize", "a whole number ≥ 0"),
        ("u64", "a whole number ≥ 0"),
        ("u32", "a whole number ≥ 0"),
        ("u16", "a whole number ≥ 0"),
        ("u8", "a whole number ≥ 0"),
        ("i64", "a whole number"),
        ("i32", "a whole number"),
        ("f64", "a number"),
        ("f32", "a number"),
    ] {
        text = text.replace(&format!("expected {rust}"), &format!("expected {yaml}"));
    }
    text
}

/// What a type looks like in YAML, for serde's messages that name a Rust type (`expected struct
/// X`). The file shapes say it themselves (`#[serde(expecting = "...")]` on each), so only
/// the generic words are left here: this floor names no type of the layers above it.
fn yaml_words(_type_name: &str, is_enum: bool) -> &'static str {
    if is_enum {
        "one of the listed names"
    } else {
        "a mapping of keys"
    }
}

/// Reads a YAML file into `T`, naming the YAML path of any shape error.
pub fn read_yaml<T: serde::de::DeserializeOwned>(path: &Path) -> Result<T, FileError> {
    parse_yaml(&read_text(path)?, path)
}

/// The largest text file read whole (configs, plans, boards, intrinsics, a session's records,
/// datasets, results): far above any real one (a 1000-pose session's `samples.yaml` is about
/// 1 MB) and far below what would exhaust memory.
pub const MAX_TEXT_BYTES: u64 = 64 << 20;

/// Reads a text file, naming it in the error (and the link that loops, when one does). A file
/// over [`MAX_TEXT_BYTES`] is refused (also one that never ends, such as `/dev/zero`), never
/// read until memory runs out.
pub fn read_text(path: &Path) -> Result<String, FileError> {
    use std::io::Read;
    let failed = |source: std::io::Error| match symlink_loop(path) {
        Some(at) => FileError::SymlinkLoop {
            path: path.to_path_buf(),
            at,
        },
        None => FileError::Read {
            path: path.to_path_buf(),
            source,
        },
    };
    let file = std::fs::File::open(path).map_err(failed)?;
    let mut text = String::new();
    file.take(MAX_TEXT_BYTES + 1)
        .read_to_string(&mut text)
        .map_err(failed)?;
    if text.len() as u64 > MAX_TEXT_BYTES {
        return Err(FileError::TooLarge {
            path: path.to_path_buf(),
        });
    }
    Ok(text)
}

/// `source` (an error of opening `path`), or, when `path` runs into a symbolic link loop, an
/// error saying `symlink loop at <link>`: for errors that carry an `io::Error` as their cause.
pub fn name_symlink_loop(path: &Path, source: std::io::Error) -> std::io::Error {
    match symlink_loop(path) {
        Some(at) => std::io::Error::other(format!("symlink loop at {}", at.display())),
        None => source,
    }
}

/// Where `path` runs into a symbolic link loop: the shortest leading part of it (a folder above
/// it or the path itself) whose resolution the system gives up on (`ELOOP`); `None` when the
/// path has no loop. For messages that would otherwise say "not found" or "not a file" of a
/// path that is a link going round in circles.
pub fn symlink_loop(path: &Path) -> Option<PathBuf> {
    #[cfg(unix)]
    {
        let loops = |p: &Path| matches!(std::fs::metadata(p), Err(e) if e.raw_os_error() == Some(libc::ELOOP));
        if !loops(path) {
            return None;
        }
        let mut prefix = PathBuf::new();
        for part in path.components() {
            prefix.push(part);
            if loops(&prefix) {
                return Some(prefix);
            }
        }
        Some(path.to_path_buf())
    }
    #[cfg(not(unix))]
    {
        let _ = path;
        None
    }
}

/// Parses YAML text into `T`; `path` is only used in errors.
pub fn parse_yaml<T: serde::de::DeserializeOwned>(text: &str, path: &Path) -> Result<T, FileError> {
    let deserializer = serde_yaml_ng::Deserializer::from_str(text);
    serde_path_to_error::deserialize(deserializer).map_err(|e| {
        let yaml_path = e.path().to_string();
        shape_error(text, path, yaml_path, e.into_inner())
    })
}

/// Serialises `value` and writes it atomically.
pub fn write_yaml<T: Serialize>(value: &T, path: &Path) -> Result<(), FileError> {
    let text = serde_yaml_ng::to_string(value).map_err(|source| FileError::Serialise {
        path: path.to_path_buf(),
        source,
    })?;
    write_atomic(path, text.as_bytes()).map_err(|source| FileError::Write {
        path: path.to_path_buf(),
        source,
    })
}

#[cfg(test)]
mod tests {
    use super::key_line;

    const TEXT: &str = "\
# a comment naming seed: 1
setup: eye_in_hand
robot:
  backend: sim
  seed: 7
camera:
  backend: sim

  # noise_sigma: commented out
  noise_sigma: 2.0
  seed: 11
plan:
  generate: {count: 20, seed: 1}
samples:
  - a: 1
    b: 2
  - a: 3
    b:
      c: 4
";

    #[test]
    fn key_line_follows_the_path_through_blocks_flow_mappings_and_lists() {
        for (path, line) in [
            ("setup", Some(2)),
            ("robot.seed", Some(5)),
            ("camera.seed", Some(11)),
            ("camera.noise_sigma", Some(10)),
            ("plan.generate.seed", Some(13)),
            ("samples[0].b", Some(16)),
            ("samples[1].a", Some(17)),
            ("samples[1].b.c", Some(19)),
            // Not there: the deepest key found, or nothing.
            ("camera.missing", None),
            ("nowhere", None),
            ("samples[7].a", Some(14)),
        ] {
            assert_eq!(key_line(TEXT, path), line, "{path}");
        }
    }
}

/// The version of the layout of a file handeye writes and reads back (a session's
/// `session.yaml` and `poses/NNN.yaml`, `samples.yaml` and datasets, `result.yaml`): its
/// `schema_version:` key. A file without the key was written before versions were kept and has
/// the layout of version 1; a file of a version newer than this build reads is refused with a
/// message that says so (rather than misread).
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Serialize)]
#[serde(transparent)]
pub struct SchemaVersion(u32);

impl SchemaVersion {
    /// What this build writes, and the newest it reads.
    pub const CURRENT: SchemaVersion = SchemaVersion(1);

    /// The version of a file without the key (serde `default` of the field).
    pub fn unversioned() -> SchemaVersion {
        SchemaVersion(1)
    }

    /// The number.
    pub fn get(self) -> u32 {
        self.0
    }
}

impl Default for SchemaVersion {
    /// What a new file is written with: [`SchemaVersion::CURRENT`].
    fn default() -> Self {
        SchemaVersion::CURRENT
    }
}

impl<'de> serde::Deserialize<'de> for SchemaVersion {
    fn deserialize<D: serde::Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        let version = u32::deserialize(deserializer)?;
        if version == 0 {
            return Err(serde::de::Error::custom(
                "schema_version 0: versions start at 1 (leave the key out for a file of version 1)",
            ));
        }
        if version > SchemaVersion::CURRENT.0 {
            return Err(serde::de::Error::custom(format!(
                "schema_version {version}: this file was written by a newer handeye (this build reads schema_version 1 to {}); read it with that version",
                SchemaVersion::CURRENT.0
            )));
        }
        Ok(SchemaVersion(version))
    }
}

#[cfg(test)]
mod read_tests {
    use super::*;

    #[test]
    fn a_file_that_never_ends_is_refused_not_read_until_memory_runs_out() {
        // /dev/zero: endless NUL bytes (valid UTF-8), as a wrong path to a device would give.
        let error = read_text(Path::new("/dev/zero")).unwrap_err();
        assert!(matches!(error, FileError::TooLarge { .. }), "{error}");
        assert!(error.to_string().contains("/dev/zero"), "{error}");
    }

    #[test]
    fn a_missing_file_is_named() {
        let error = read_text(Path::new("/nonexistent/cell.yaml")).unwrap_err();
        assert!(matches!(error, FileError::Read { .. }));
        assert!(error.to_string().contains("/nonexistent/cell.yaml"));
    }
}

#[cfg(test)]
mod schema_version_tests {
    use super::SchemaVersion;

    #[derive(Debug, serde::Deserialize)]
    #[allow(dead_code)]
    struct File {
        #[serde(default = "SchemaVersion::unversioned")]
        schema_version: SchemaVersion,
    }

    #[test]
    fn absent_is_version_one_and_newer_or_zero_is_refused() {
        let read = |text: &str| serde_yaml_ng::from_str::<File>(text);
        assert_eq!(read("{}").unwrap().schema_version.get(), 1);
        assert_eq!(
            read("schema_version: 1").unwrap().schema_version,
            SchemaVersion::CURRENT
        );
        for text in ["schema_version: 2", "schema_version: 0"] {
            let e = read(text).unwrap_err().to_string();
            assert!(
                e.contains("newer handeye") || e.contains("schema_version 0"),
                "{e}"
            );
        }
        assert!(read("schema_version: one").is_err());
    }
}
