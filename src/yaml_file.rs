//! Reading and writing the tool's YAML files: one reader (serde through `serde_path_to_error`, so
//! every shape error names the YAML path), one atomic writer, and the one error type they share
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
    #[error("{}: {}", path.display(), shape_message(.yaml_path, .problem))]
    Shape {
        /// The file.
        path: PathBuf,
        /// YAML path of the problem (`.` for the document root).
        yaml_path: String,
        /// What serde found.
        problem: serde_yaml_ng::Error,
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

/// `<yaml path>: <problem>`, the path once: serde_yaml_ng already starts some messages with it.
fn shape_message(yaml_path: &str, problem: &serde_yaml_ng::Error) -> String {
    let problem = plain_parser_message(problem);
    if problem.starts_with(&format!("{yaml_path}: ")) {
        problem
    } else {
        format!("{yaml_path}: {problem}")
    }
}

/// The parser's message with the Rust type names serde puts in it (`expected struct PoseYaml`)
/// replaced by what the YAML should hold (`expected a pose mapping (...)`).
pub(crate) fn plain_parser_message(problem: &serde_yaml_ng::Error) -> String {
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
    text
}

/// What a type of ours looks like in YAML, for error messages.
fn yaml_words(type_name: &str, is_enum: bool) -> &'static str {
    match type_name {
        "PoseYaml" | "PoseRecord" => {
            "a pose mapping (translation: [x, y, z] m and quaternion: {w, x, y, z} or rotation_vector: [rx, ry, rz] rad)"
        }
        "QuaternionYaml" => "a quaternion mapping {w, x, y, z}",
        "DatasetYaml" => "a dataset mapping (setup: eye_in_hand or eye_to_hand, samples: [...])",
        "ResultFile" => "a result mapping (setup, the two transforms, residuals, solver, ...)",
        "BoardFile" => {
            "a board mapping (Kalibr aprilgrid keys: target_type, tagCols, tagRows, tagSize, tagSpacing)"
        }
        _ if is_enum => "one of the listed names",
        _ => "a mapping of keys",
    }
}

/// Reads a YAML file into `T`, naming the YAML path of any shape error.
pub(crate) fn read_yaml<T: serde::de::DeserializeOwned>(path: &Path) -> Result<T, FileError> {
    parse_yaml(&read_text(path)?, path)
}

/// Reads a text file, naming it in the error.
pub(crate) fn read_text(path: &Path) -> Result<String, FileError> {
    std::fs::read_to_string(path).map_err(|source| FileError::Read {
        path: path.to_path_buf(),
        source,
    })
}

/// Parses YAML text into `T`; `path` is only used in errors.
pub(crate) fn parse_yaml<T: serde::de::DeserializeOwned>(
    text: &str,
    path: &Path,
) -> Result<T, FileError> {
    let deserializer = serde_yaml_ng::Deserializer::from_str(text);
    serde_path_to_error::deserialize(deserializer).map_err(|e| {
        let yaml_path = e.path().to_string();
        FileError::Shape {
            path: path.to_path_buf(),
            yaml_path,
            problem: e.into_inner(),
        }
    })
}

/// Serialises `value` and writes it atomically.
pub(crate) fn write_yaml<T: Serialize>(value: &T, path: &Path) -> Result<(), FileError> {
    let text = serde_yaml_ng::to_string(value).map_err(|source| FileError::Serialise {
        path: path.to_path_buf(),
        source,
    })?;
    write_atomic(path, text.as_bytes()).map_err(|source| FileError::Write {
        path: path.to_path_buf(),
        source,
    })
}
