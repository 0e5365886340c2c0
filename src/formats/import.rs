//! Importers: other tools' hand-eye data turned into our pose pairs (`T_base_flange`,
//! `T_camera_target`) and, for ViSP, into a camera_info file and a recorded-poses file.
//!
//! What each source holds (direction matters; `T_a_b` maps points in `b` into `a`):
//!
//! * **ViSP** (`apps/calibration/hand-eye` data): `<prefix>_pose_rPe_<N>.yaml` is a 6x1 matrix
//!   `[tx, ty, tz, θux, θuy, θuz]` = `T_base_flange` (ViSP's `rMe`: end-effector in robot
//!   reference frame; metres and an axis-angle vector in radians, UR's form). The images
//!   `<prefix>_image-<N>.png` are detected with our detector to get `T_camera_target`; the
//!   intrinsics come from the `vpXmlParserCamera` XML (`px, py, u0, v0` = `fx, fy, cx, cy`;
//!   `perspectiveProjWithDistortion`'s `kud` is the radial `k1` of the undistorted→distorted
//!   map, the same model as OpenCV's `k1`). ViSP's pixel centres are at integers, like ours.
//! * **MoveIt Calibration** pose-sample JSON: a list of samples, each `[T_base_flange,
//!   T_camera_target]` as 4x4 row-major homogeneous matrices in metres (`effector_wrt_world`,
//!   `object_wrt_sensor`).
//! * **CSV** (ours, defined here): one pose is `tx,ty,tz,qx,qy,qz,qw` (quaternion, scalar last)
//!   or UR's `x,y,z,rx,ry,rz` (rotation vector, rad); translations in metres (or mm when asked).
//!   Either one file with two poses per row, `T_base_flange` then `T_camera_target` (14 or 12
//!   columns), or two files of one pose per row paired by row order (robot file: `T_base_flange`,
//!   camera file: `T_camera_target`). Blank lines and lines starting with `#` are skipped; a first
//!   row with no numeric field is a header. Any other row must have exactly the expected number
//!   of finite numbers, or the import fails naming the file and line.
//!
//! Every translation read is checked by `geometry::check_translation` (finite, within
//! `MAX_TRANSLATION_M` of the origin), the same rule the YAML pose form applies. The ViSP XML is
//! parsed as XML (comments are not values); the MoveIt JSON must be one array and nothing more.
//!
//! Depends on `geometry`, `solve`, `camera_model`, `target` (ViSP detection) and
//! `robot::recorded` (the recorded-poses form); writes no files itself except through the
//! callers' save functions.

use std::path::{Path, PathBuf};

use nalgebra::{Matrix3, Quaternion, Translation3, UnitQuaternion, Vector3};

use crate::camera_model::{CameraModel, Distortion};
use crate::dataset::Dataset;
use crate::geometry::{
    check_translation, pose_from_rotvec, rotation_from_matrix, Pose, TranslationProblem,
};
use crate::setup::{PosePair, Setup};
use crate::vision::{estimate_board_pose, Board, DetectorOptions, TagDetector, TargetError};

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

fn read_text(path: &Path) -> Result<String, ImportError> {
    std::fs::read_to_string(path).map_err(|source| ImportError::Read {
        path: path.to_path_buf(),
        source,
    })
}

// ---------------------------------------------------------------------------------------------
// ViSP

#[derive(serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct VispMatrix {
    rows: usize,
    cols: usize,
    data: Vec<Vec<f64>>,
}

/// Reads a ViSP pose vector file (`*_pose_rPe_*.yaml`): `T_base_flange` from
/// `[tx, ty, tz, θux, θuy, θuz]` (m, rad).
pub fn read_visp_pose(path: &Path) -> Result<Pose, ImportError> {
    let text = read_text(path)?;
    let format = |problem: String| ImportError::Format {
        path: path.to_path_buf(),
        expected:
            "ViSP pose vector (rows: 6, cols: 1, data: [[tx], [ty], [tz], [θux], [θuy], [θuz]])",
        problem,
    };
    let m: VispMatrix = serde_yaml_ng::from_str(&text).map_err(|e| format(e.to_string()))?;
    let values: Vec<f64> = m.data.iter().flatten().copied().collect();
    if m.rows != 6 || m.cols != 1 || values.len() != 6 {
        return Err(format(format!(
            "rows {}, cols {}, {} values",
            m.rows,
            m.cols,
            values.len()
        )));
    }
    if let Some(i) = values.iter().position(|v| !v.is_finite()) {
        return Err(ImportError::Value {
            path: path.to_path_buf(),
            location: format!("data[{i}]"),
            problem: format!("{} is not a finite number", values[i]),
        });
    }
    let translation = checked_translation(
        Vector3::new(values[0], values[1], values[2]),
        path,
        "data[0..3] (T_base_flange)",
    )?;
    Ok(pose_from_rotvec(
        translation,
        Vector3::new(values[3], values[4], values[5]),
    ))
}

/// The first child element of `node` named `tag`.
fn xml_child<'a, 'input>(
    node: roxmltree::Node<'a, 'input>,
    tag: &str,
) -> Option<roxmltree::Node<'a, 'input>> {
    node.children()
        .find(|n| n.is_element() && n.tag_name().name() == tag)
}

/// The trimmed text of `node`'s child element `tag` (comments and CDATA handled by the XML
/// parser: a commented-out value is not a value).
fn xml_text(node: roxmltree::Node<'_, '_>, tag: &str) -> Option<String> {
    let child = xml_child(node, tag)?;
    let text: String = child
        .children()
        .filter(|n| n.is_text())
        .filter_map(|n| n.text())
        .collect();
    Some(text.trim().to_string())
}

/// Reads ViSP `vpXmlParserCamera` intrinsics. With several `<model>` entries the one with
/// distortion (`perspectiveProjWithDistortion`) is used; its `kud` becomes radial `k1`. The
/// file is parsed as XML (`roxmltree`), so comments, CDATA and entities mean what they mean.
pub fn read_visp_camera_xml(path: &Path) -> Result<CameraModel, ImportError> {
    let text = read_text(path)?;
    let format = |problem: String| ImportError::Format {
        path: path.to_path_buf(),
        expected: "ViSP vpXmlParserCamera XML",
        problem,
    };
    let document = roxmltree::Document::parse(&text).map_err(|e| format(e.to_string()))?;
    let camera = document
        .descendants()
        .find(|n| n.is_element() && n.tag_name().name() == "camera")
        .ok_or_else(|| format("no <camera> element".into()))?;
    let number = |scope: roxmltree::Node<'_, '_>, tag: &str| -> Result<f64, ImportError> {
        let raw = xml_text(scope, tag).ok_or_else(|| ImportError::Value {
            path: path.to_path_buf(),
            location: format!("<{tag}>"),
            problem: "missing".into(),
        })?;
        raw.parse::<f64>()
            .ok()
            .filter(|v| v.is_finite())
            .ok_or_else(|| ImportError::Value {
                path: path.to_path_buf(),
                location: format!("<{tag}>"),
                problem: format!("`{raw}` is not a finite number"),
            })
    };
    let models: Vec<roxmltree::Node<'_, '_>> = camera
        .children()
        .filter(|n| n.is_element() && n.tag_name().name() == "model")
        .collect();
    let with_distortion = |m: &roxmltree::Node<'_, '_>| {
        xml_text(*m, "type").as_deref() == Some("perspectiveProjWithDistortion")
    };
    let chosen = *models
        .iter()
        .find(|m| with_distortion(m))
        .or_else(|| models.first())
        .ok_or_else(|| format("no <model> element inside <camera>".into()))?;
    let distortion = if with_distortion(&chosen) {
        let k1 = number(chosen, "kud")?;
        if k1 == 0.0 {
            Distortion::None
        } else {
            Distortion::RadTan {
                k1,
                k2: 0.0,
                p1: 0.0,
                p2: 0.0,
                k3: 0.0,
            }
        }
    } else {
        Distortion::None
    };
    let size = |tag: &str| -> Result<u32, ImportError> {
        let v = number(camera, tag)?;
        if v >= 1.0 && v.fract() == 0.0 && v <= u32::MAX as f64 {
            Ok(v as u32)
        } else {
            Err(ImportError::Value {
                path: path.to_path_buf(),
                location: format!("<{tag}>"),
                problem: format!("{v} is not a positive whole number of pixels"),
            })
        }
    };
    let model = CameraModel {
        width: size("image_width")?,
        height: size("image_height")?,
        fx: number(chosen, "px")?,
        fy: number(chosen, "py")?,
        cx: number(chosen, "u0")?,
        cy: number(chosen, "v0")?,
        distortion,
    };
    model.validate(path).map_err(|e| ImportError::Value {
        path: path.to_path_buf(),
        location: "<model>".into(),
        problem: e.to_string(),
    })?;
    Ok(model)
}

/// The trailing number of a file stem after `marker` (`franka_pose_rPe_12` → 12 for `_pose_rPe_`).
fn number_after(stem: &str, marker: &str) -> Option<u64> {
    let at = stem.rfind(marker)? + marker.len();
    stem[at..].parse().ok()
}

/// One ViSP sample found in a folder.
#[derive(Debug, Clone, PartialEq)]
pub struct VispSampleFiles {
    /// The `N` of the file names.
    pub number: u64,
    /// The pose vector file.
    pub pose_file: PathBuf,
    /// The image file.
    pub image: PathBuf,
}

/// What a ViSP data folder holds, in sample-number order.
#[derive(Debug, Clone, PartialEq)]
pub struct VispFolder {
    /// The samples (pose file and image), ascending `N`.
    pub samples: Vec<VispSampleFiles>,
    /// The intrinsics XML, when the folder holds exactly one `.xml`.
    pub camera_xml: Option<PathBuf>,
}

/// Finds the ViSP samples of `folder`: every `*_pose_rPe_<N>.yaml` with its `*image-<N>.png`
/// (or `.jpg`). A pose file without an image is an error; images without a pose are ignored.
pub fn scan_visp_folder(folder: &Path) -> Result<VispFolder, ImportError> {
    let entries = std::fs::read_dir(folder).map_err(|source| ImportError::Read {
        path: folder.to_path_buf(),
        source,
    })?;
    let mut poses = Vec::new();
    let mut images = Vec::new();
    let mut xmls = Vec::new();
    for entry in entries.filter_map(Result::ok) {
        let path = entry.path();
        let (Some(stem), Some(ext)) = (
            path.file_stem().and_then(|s| s.to_str()),
            path.extension().and_then(|s| s.to_str()),
        ) else {
            continue;
        };
        match ext.to_ascii_lowercase().as_str() {
            "yaml" | "yml" => {
                if let Some(n) = number_after(stem, "_pose_rPe_") {
                    poses.push((n, path.clone()));
                }
            }
            "png" | "jpg" | "jpeg" => {
                if let Some(n) =
                    number_after(stem, "image-").or_else(|| number_after(stem, "image_"))
                {
                    images.push((n, path.clone()));
                }
            }
            "xml" => xmls.push(path.clone()),
            _ => {}
        }
    }
    if poses.is_empty() {
        return Err(ImportError::Folder {
            folder: folder.to_path_buf(),
            problem: "no ViSP pose files (`*_pose_rPe_<N>.yaml`)".into(),
        });
    }
    poses.sort();
    let mut samples = Vec::new();
    for (number, pose_file) in poses {
        let matching: Vec<&PathBuf> = images
            .iter()
            .filter(|(n, _)| *n == number)
            .map(|(_, p)| p)
            .collect();
        let image = match matching.as_slice() {
            [one] => (*one).clone(),
            [] => {
                return Err(ImportError::Folder {
                    folder: folder.to_path_buf(),
                    problem: format!(
                        "pose file {} has no image `*image-{number}.png`",
                        pose_file.display()
                    ),
                })
            }
            _ => {
                return Err(ImportError::Folder {
                    folder: folder.to_path_buf(),
                    problem: format!("several images are numbered {number}: {matching:?}"),
                })
            }
        };
        samples.push(VispSampleFiles {
            number,
            pose_file,
            image,
        });
    }
    xmls.sort();
    Ok(VispFolder {
        samples,
        camera_xml: (xmls.len() == 1).then(|| xmls.remove(0)),
    })
}

/// How to import a ViSP folder.
#[derive(Debug, Clone)]
pub struct VispOptions {
    /// Eye-in-hand or eye-to-hand (ViSP's files do not say).
    pub setup: Setup,
    /// The board the images show.
    pub board: Board,
    /// Intrinsics to use instead of the folder's XML.
    pub camera: Option<CameraModel>,
    /// Detector settings.
    pub detector: DetectorOptions,
    /// Skip an image with no board instead of failing.
    pub skip_unfound: bool,
}

/// One imported ViSP sample with its detection quality.
#[derive(Debug, Clone, PartialEq)]
pub struct VispFrame {
    /// The files it came from.
    pub files: VispSampleFiles,
    /// `T_base_flange` from the pose file.
    pub base_from_flange: Pose,
    /// `T_camera_target` from detection, when found.
    pub camera_from_target: Option<Pose>,
    /// Board reprojection RMS, px.
    pub rms_px: Option<f64>,
    /// Lone-tag ambiguity ratio (see `vision::pnp`).
    pub ambiguity: Option<f64>,
    /// Why the board was not found, when skipped.
    pub skipped: Option<String>,
}

/// A ViSP folder imported.
#[derive(Debug, Clone)]
pub struct VispImport {
    /// The solver's dataset (ids `visp-<N>`), only samples whose board was found.
    pub dataset: Dataset,
    /// The intrinsics used.
    pub camera: CameraModel,
    /// Every sample, in order, including skipped ones.
    pub frames: Vec<VispFrame>,
}

/// Imports a ViSP hand-eye folder: pose vectors, intrinsics, and board poses detected in the
/// images with our detector.
pub fn import_visp(folder: &Path, options: &VispOptions) -> Result<VispImport, ImportError> {
    let found = scan_visp_folder(folder)?;
    let camera = match (&options.camera, &found.camera_xml) {
        (Some(camera), _) => *camera,
        (None, Some(xml)) => read_visp_camera_xml(xml)?,
        (None, None) => {
            return Err(ImportError::Folder {
                folder: folder.to_path_buf(),
                problem: "no single intrinsics XML (vpXmlParserCamera) in the folder; give the intrinsics explicitly".into(),
            })
        }
    };
    let detector = TagDetector::spawn(&options.board, options.detector.clone())
        .map_err(|e| ImportError::Target(Box::new(e)))?;
    let mut frames = Vec::new();
    let mut pairs = Vec::new();
    for files in found.samples {
        let base_from_flange = read_visp_pose(&files.pose_file)?;
        let image = crate::vision::detect::load_gray_image(&files.image)
            .map_err(|e| ImportError::Target(Box::new(e)))?;
        if (image.width(), image.height()) != (camera.width, camera.height) {
            return Err(ImportError::Value {
                path: files.image.clone(),
                location: "image size".into(),
                problem: format!(
                    "{}x{} px, but the intrinsics are for {}x{} px",
                    image.width(),
                    image.height(),
                    camera.width,
                    camera.height
                ),
            });
        }
        let pose = detector
            .detect(&image)
            .and_then(|d| estimate_board_pose(&options.board, &camera, &d));
        let frame = match pose {
            Ok(p) => {
                let mut pair = PosePair::new(base_from_flange, p.camera_from_target);
                pair.id = Some(format!("visp-{}", files.number));
                pairs.push(pair);
                VispFrame {
                    files,
                    base_from_flange,
                    camera_from_target: Some(p.camera_from_target),
                    rms_px: Some(p.rms_px),
                    ambiguity: p.ambiguity,
                    skipped: None,
                }
            }
            Err(e) if options.skip_unfound => VispFrame {
                files,
                base_from_flange,
                camera_from_target: None,
                rms_px: None,
                ambiguity: None,
                skipped: Some(e.to_string()),
            },
            Err(e) => {
                return Err(ImportError::NoBoard {
                    image: files.image,
                    pose_file: files.pose_file,
                    reason: e.to_string(),
                })
            }
        };
        frames.push(frame);
    }
    Ok(VispImport {
        dataset: Dataset {
            setup: options.setup,
            pairs,
        },
        camera,
        frames,
    })
}

// ---------------------------------------------------------------------------------------------
// MoveIt Calibration

/// A 4x4 homogeneous matrix (row-major) as a pose; `location` names it in errors.
pub fn pose_from_matrix4(
    m: &[[f64; 4]; 4],
    path: &Path,
    location: &str,
) -> Result<Pose, ImportError> {
    let bad = |problem: String| ImportError::Value {
        path: path.to_path_buf(),
        location: location.to_string(),
        problem,
    };
    if m.iter().flatten().any(|v| !v.is_finite()) {
        return Err(bad("holds a value that is not a finite number".into()));
    }
    let bottom = m[3];
    if (bottom[0].abs() + bottom[1].abs() + bottom[2].abs() + (bottom[3] - 1.0).abs()) > 1e-9 {
        return Err(bad(format!(
            "last row {bottom:?} is not [0, 0, 0, 1]: not a homogeneous transform"
        )));
    }
    let r = Matrix3::from_fn(|i, j| m[i][j]);
    let rotation = rotation_from_matrix(&r, MATRIX_TOLERANCE).ok_or_else(|| {
        bad(format!(
            "the 3x3 block is not a rotation (orthonormality error {:.2e}, det {:.6})",
            (r.transpose() * r - Matrix3::identity()).norm(),
            r.determinant()
        ))
    })?;
    let translation = checked_translation(Vector3::new(m[0][3], m[1][3], m[2][3]), path, location)?;
    Ok(Pose::from_parts(Translation3::from(translation), rotation))
}

/// Reads MoveIt Calibration's pose-sample JSON: `[[T_base_flange, T_camera_target], ...]`, 4x4
/// row-major matrices in metres. Sample ids are `moveit-<i>` (0-based).
pub fn import_moveit_json(path: &Path) -> Result<Vec<PosePair>, ImportError> {
    let text = read_text(path)?;
    let mut deserializer = serde_json::Deserializer::from_str(&text);
    let samples: Vec<[[[f64; 4]; 4]; 2]> = serde_path_to_error::deserialize(&mut deserializer)
        .map_err(|e| ImportError::Format {
            path: path.to_path_buf(),
            expected: "MoveIt Calibration pose-sample JSON ([[T_base_flange 4x4, T_camera_target 4x4], ...])",
            problem: format!("at {}: {}", e.path(), e.inner()),
        })?;
    // The whole input must be that one array: trailing text means a truncated copy, two files
    // pasted together or a different format, never something to ignore.
    deserializer.end().map_err(|e| ImportError::Format {
        path: path.to_path_buf(),
        expected: "MoveIt Calibration pose-sample JSON (one array and nothing after it)",
        problem: format!("text after the array: {e}"),
    })?;
    if samples.is_empty() {
        return Err(ImportError::Format {
            path: path.to_path_buf(),
            expected: "MoveIt Calibration pose-sample JSON",
            problem: "no samples".into(),
        });
    }
    samples
        .iter()
        .enumerate()
        .map(|(i, [flange, target])| {
            let mut pair = PosePair::new(
                pose_from_matrix4(
                    flange,
                    path,
                    &format!("sample {i} ([{i}][0], T_base_flange)"),
                )?,
                pose_from_matrix4(
                    target,
                    path,
                    &format!("sample {i} ([{i}][1], T_camera_target)"),
                )?,
            );
            pair.id = Some(format!("moveit-{i}"));
            Ok(pair)
        })
        .collect()
}

// ---------------------------------------------------------------------------------------------
// CSV

/// How one pose is written in a CSV row.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CsvPoseForm {
    /// `tx,ty,tz,qx,qy,qz,qw` (quaternion scalar last).
    Quaternion,
    /// UR's `x,y,z,rx,ry,rz` (rotation vector, rad).
    RotationVector,
}

impl CsvPoseForm {
    /// Columns per pose.
    pub fn columns(self) -> usize {
        match self {
            CsvPoseForm::Quaternion => 7,
            CsvPoseForm::RotationVector => 6,
        }
    }

    fn header(self) -> &'static str {
        match self {
            CsvPoseForm::Quaternion => "tx,ty,tz,qx,qy,qz,qw",
            CsvPoseForm::RotationVector => "x,y,z,rx,ry,rz",
        }
    }
}

/// How a CSV file is read.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CsvOptions {
    /// The pose form.
    pub form: CsvPoseForm,
    /// Translations are in millimetres (UR's pendant shows mm) instead of metres.
    pub millimetres: bool,
}

/// The data rows of a CSV file: (1-based line number, numbers), with comments, blank lines and a
/// header skipped; every row checked to hold `columns` finite numbers.
fn csv_rows(
    path: &Path,
    columns: usize,
    expect: &str,
) -> Result<Vec<(usize, Vec<f64>)>, ImportError> {
    let text = read_text(path)?;
    let mut rows = Vec::new();
    let mut first_row = true;
    for (i, raw) in text.lines().enumerate() {
        let line = raw.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let fields: Vec<&str> = line.split(',').map(str::trim).collect();
        let is_first = std::mem::replace(&mut first_row, false);
        if is_first && fields.iter().all(|f| f.parse::<f64>().is_err()) {
            continue;
        }
        let bad = |problem: String| ImportError::Line {
            path: path.to_path_buf(),
            line: i + 1,
            problem,
        };
        if fields.len() != columns {
            return Err(bad(format!(
                "{} fields, expected {columns} ({expect})",
                fields.len()
            )));
        }
        let numbers = fields
            .iter()
            .enumerate()
            .map(|(c, f)| {
                f.parse::<f64>()
                    .ok()
                    .filter(|v| v.is_finite())
                    .ok_or_else(|| {
                        bad(format!(
                            "column {} is `{f}`, not a finite number (expected {expect})",
                            c + 1
                        ))
                    })
            })
            .collect::<Result<Vec<f64>, _>>()?;
        rows.push((i + 1, numbers));
    }
    if rows.is_empty() {
        return Err(ImportError::Format {
            path: path.to_path_buf(),
            expected: "pose CSV",
            problem: format!("no data rows (expected {expect})"),
        });
    }
    Ok(rows)
}

fn csv_pose(
    values: &[f64],
    options: &CsvOptions,
    path: &Path,
    line: usize,
    which: &str,
) -> Result<Pose, ImportError> {
    let scale = if options.millimetres { 1e-3 } else { 1.0 };
    let t = checked_translation(
        Vector3::new(values[0], values[1], values[2]) * scale,
        path,
        &format!("line {line}, {which}"),
    )?;
    match options.form {
        CsvPoseForm::RotationVector => Ok(pose_from_rotvec(
            t,
            Vector3::new(values[3], values[4], values[5]),
        )),
        CsvPoseForm::Quaternion => {
            let q = Quaternion::new(values[6], values[3], values[4], values[5]);
            let norm = q.norm();
            if (norm - 1.0).abs() > QUATERNION_TOLERANCE {
                return Err(ImportError::Line {
                    path: path.to_path_buf(),
                    line,
                    problem: format!(
                        "{which}: quaternion norm {norm:.6} is not 1 (±{QUATERNION_TOLERANCE}); the order is qx,qy,qz,qw"
                    ),
                });
            }
            Ok(Pose::from_parts(
                Translation3::from(t),
                UnitQuaternion::from_quaternion(q),
            ))
        }
    }
}

/// Reads a CSV with both poses per row: `T_base_flange` columns, then `T_camera_target` columns.
/// Sample ids are `line-<n>`.
pub fn import_csv_pairs(path: &Path, options: &CsvOptions) -> Result<Vec<PosePair>, ImportError> {
    let n = options.form.columns();
    let expect = format!(
        "T_base_flange {h}, T_camera_target {h}",
        h = options.form.header()
    );
    csv_rows(path, 2 * n, &expect)?
        .into_iter()
        .map(|(line, v)| {
            let mut pair = PosePair::new(
                csv_pose(&v[..n], options, path, line, "T_base_flange")?,
                csv_pose(&v[n..], options, path, line, "T_camera_target")?,
            );
            pair.id = Some(format!("line-{line}"));
            Ok(pair)
        })
        .collect()
}

/// Reads two CSVs of one pose per row, paired by row order: `robot` holds `T_base_flange`,
/// `camera` holds `T_camera_target`. Both must have the same number of data rows.
pub fn import_csv_two_files(
    robot: &Path,
    camera: &Path,
    options: &CsvOptions,
) -> Result<Vec<PosePair>, ImportError> {
    let n = options.form.columns();
    let header = options.form.header();
    let robot_rows = csv_rows(robot, n, &format!("T_base_flange {header}"))?;
    let camera_rows = csv_rows(camera, n, &format!("T_camera_target {header}"))?;
    if robot_rows.len() != camera_rows.len() {
        return Err(ImportError::Format {
            path: camera.to_path_buf(),
            expected: "camera pose CSV paired with the robot pose CSV",
            problem: format!(
                "{} data rows, but {} has {}",
                camera_rows.len(),
                robot.display(),
                robot_rows.len()
            ),
        });
    }
    robot_rows
        .iter()
        .zip(&camera_rows)
        .enumerate()
        .map(|(i, ((rl, rv), (cl, cv)))| {
            let mut pair = PosePair::new(
                csv_pose(rv, options, robot, *rl, "T_base_flange")?,
                csv_pose(cv, options, camera, *cl, "T_camera_target")?,
            );
            pair.id = Some(format!("row-{}", i + 1));
            Ok(pair)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn visp_xml_with_and_without_distortion() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("cam.xml");
        let model = |ty: &str, extra: &str| {
            format!("<model><type>{ty}</type><px>600</px><py>601</py><u0>320.5</u0><v0>240</v0>{extra}</model>")
        };
        let text = format!(
            "<?xml version=\"1.0\"?><root><camera><name>c</name><image_width>640</image_width><image_height>480</image_height>{}{}</camera></root>",
            model("perspectiveProjWithoutDistortion", ""),
            model("perspectiveProjWithDistortion", "<kud>-0.1</kud><kdu>0.1</kdu>")
        );
        std::fs::write(&path, text).unwrap();
        let m = read_visp_camera_xml(&path).unwrap();
        assert_eq!(
            (m.width, m.height, m.fx, m.fy, m.cx, m.cy),
            (640, 480, 600.0, 601.0, 320.5, 240.0)
        );
        assert!(matches!(m.distortion, Distortion::RadTan { k1, .. } if k1 == -0.1));

        std::fs::write(
            &path,
            "<root><camera><image_width>640</image_width></camera></root>",
        )
        .unwrap();
        let e = read_visp_camera_xml(&path).unwrap_err().to_string();
        assert!(e.contains("cam.xml") && e.contains("<model>"), "{e}");
    }

    #[test]
    fn matrix_that_is_not_a_rotation_is_refused() {
        let m = [
            [1.0, 0.0, 0.0, 0.1],
            [0.0, 2.0, 0.0, 0.0],
            [0.0, 0.0, 1.0, 0.0],
            [0.0, 0.0, 0.0, 1.0],
        ];
        let e = pose_from_matrix4(&m, Path::new("x.json"), "sample 4")
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("x.json: sample 4") && e.contains("not a rotation"),
            "{e}"
        );
    }
}
