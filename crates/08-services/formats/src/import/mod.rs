//! Importers: other tools' hand-eye data turned into our pose pairs (`T_base_flange`,
//! `T_camera_target`) and, for ViSP, into a camera model and the detected board poses.
//! Direction matters everywhere: `T_a_b` maps points in `b` into `a`.
//!
//! One submodule per source, each stating in its docs what its files hold:
//! * `visp`: ViSP's `apps/calibration/hand-eye` folders (pose vectors, images, intrinsics XML);
//! * `moveit`: MoveIt Calibration's pose-sample JSON;
//! * `csv`: our CSV forms (one file with both poses per row, or a robot and a camera file).
//!
//! This file owns what they share: [`ImportError`] (every message names the file and, where
//! there is one, the line, row or path inside it), the tolerances, and the one translation check
//! every importer applies (`geometry::check_translation`: finite, within `MAX_TRANSLATION_M` of
//! the origin, the same rule the YAML pose form applies). Every public item of the submodules is
//! re-exported here, so callers name `formats::import::…` only.
//!
//! Depends on `geometry`, `setup`, `dataset`, `camera_model` and `vision` (ViSP detection);
//! writes no files itself except through the callers' save functions.

mod csv;
mod moveit;
mod visp;

pub use csv::{import_csv_pairs, import_csv_two_files, CsvOptions, CsvPoseForm};
pub use moveit::{import_moveit_json, pose_from_matrix4};
pub use visp::{
    import_visp, read_visp_camera_xml, read_visp_pose, scan_visp_folder, VispFolder, VispFrame,
    VispImport, VispOptions, VispSampleFiles,
};

use std::path::{Path, PathBuf};

use nalgebra::Vector3;

use handeye_core::geometry::{check_translation, TranslationProblem};
use handeye_vision::TargetError;

/// Tolerance on the orthonormality of an imported rotation matrix (Frobenius norm).
pub const MATRIX_TOLERANCE: f64 = 1e-6;
/// Tolerance on an imported quaternion's norm; within it the quaternion is normalised (text
/// files often print 6 digits).
pub const QUATERNION_TOLERANCE: f64 = 1e-3;

/// Why an import failed. Every message names the file and, where there is one, the line, row or
/// path inside it.
#[derive(Debug, thiserror::Error)]
pub enum ImportError {
    /// A file could not be read.
    #[error("{}: cannot read", path.display())]
    Read {
        /// The file.
        path: PathBuf,
        /// The I/O error.
        #[source]
        source: std::io::Error,
    },
    /// The file is not of the expected kind at all.
    #[error("{}: not a {expected} file: {problem}", path.display())]
    Format {
        /// The file.
        path: PathBuf,
        /// What kind of file was expected.
        expected: &'static str,
        /// What was found.
        problem: String,
    },
    /// A bad line (CSV row).
    #[error("{}: line {line}: {problem}", path.display())]
    Line {
        /// The file.
        path: PathBuf,
        /// 1-based line number.
        line: usize,
        /// What is wrong.
        problem: String,
    },
    /// A bad value at a named place (JSON path, sample index, XML tag).
    #[error("{}: {location}: {problem}", path.display())]
    Value {
        /// The file.
        path: PathBuf,
        /// Where in the file.
        location: String,
        /// What is wrong.
        problem: String,
    },
    /// A translation no robot cell has (`geometry::check_translation`, shared by every loader).
    #[error("{}: {location}: translation {problem}", path.display())]
    Translation {
        /// The file.
        path: PathBuf,
        /// Which sample and pose (`sample 3 (T_base_flange)`, `line 7, T_camera_target`).
        location: String,
        /// What is wrong (in the message, so not a `#[source]`).
        problem: TranslationProblem,
    },
    /// A folder lacks what the import needs.
    #[error("{}: {problem}", folder.display())]
    Folder {
        /// The folder.
        folder: PathBuf,
        /// What is missing or inconsistent.
        problem: String,
    },
    /// The board was not found (or its pose not estimated) in an image.
    #[error("{}: board not found: {reason} (pose file {})", image.display(), pose_file.display())]
    NoBoard {
        /// The image.
        image: PathBuf,
        /// The pose file paired with it.
        pose_file: PathBuf,
        /// What the detector said.
        reason: String,
    },
    /// An image could not be read, or the detector failed to start.
    #[error("detection")]
    Target(#[source] Box<TargetError>),
}

/// A loaded translation (m), checked by the one rule every loader shares.
fn checked_translation(
    t: Vector3<f64>,
    path: &Path,
    location: &str,
) -> Result<Vector3<f64>, ImportError> {
    check_translation(&t).map_err(|problem| ImportError::Translation {
        path: path.to_path_buf(),
        location: location.to_string(),
        problem,
    })?;
    Ok(t)
}

/// A whole text file, its path named in the error.
fn read_text(path: &Path) -> Result<String, ImportError> {
    std::fs::read_to_string(path).map_err(|source| ImportError::Read {
        path: path.to_path_buf(),
        source: handeye_core::yaml_file::name_symlink_loop(path, source),
    })
}
