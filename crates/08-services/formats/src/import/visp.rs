//! ViSP hand-eye data (`apps/calibration/hand-eye`): `<prefix>_pose_rPe_<N>.yaml` is a 6x1
//! matrix `[tx, ty, tz, θux, θuy, θuz]` = `T_base_flange` (ViSP's `rMe`: end-effector in robot
//! reference frame; metres and an axis-angle vector in radians, UR's form). The images
//! `<prefix>_image-<N>.png` are detected with our detector to get `T_camera_target`; the
//! intrinsics come from the `vpXmlParserCamera` XML (`px, py, u0, v0` = `fx, fy, cx, cy`;
//! `perspectiveProjWithDistortion`'s `kud` is the radial `k1` of the undistorted→distorted map,
//! the same model as OpenCV's `k1`). ViSP's pixel centres are at integers, like ours.
//!
//! The XML is parsed as XML (`roxmltree`: comments are not values). Depends on `geometry`,
//! `setup`, `dataset`, `camera_model`, `vision` (detection and PnP) and the parent's
//! [`ImportError`].

use std::path::{Path, PathBuf};

use nalgebra::Vector3;

use super::{checked_translation, read_text, ImportError};
use handeye_core::camera_model::{CameraModel, Distortion};
use handeye_core::geometry::{pose_from_rotvec, Pose};
use handeye_core::setup::{PosePair, Setup};
use handeye_records::dataset::Dataset;
use handeye_vision::{estimate_board_pose, DetectorOptions, Target, TargetDetector};

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
        source: handeye_core::yaml_file::name_symlink_loop(folder, source),
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
    // `_1` and `_01` are one number: two files for it leave which pose belongs to the image a
    // guess.
    if let Some(pair) = poses.windows(2).find(|w| w[0].0 == w[1].0) {
        let name = |p: &PathBuf| {
            p.file_name()
                .map(|n| n.to_string_lossy().into_owned())
                .unwrap_or_default()
        };
        return Err(ImportError::Folder {
            folder: folder.to_path_buf(),
            problem: format!(
                "two pose files have the number {}: {} and {}; keep one (`_pose_rPe_<N>` numbers \
                 must be unique: `1` and `01` are the same number)",
                pair[0].0,
                name(&pair[0].1),
                name(&pair[1].1)
            ),
        });
    }
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
    pub board: Target,
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
    let detector = TargetDetector::spawn(&options.board, options.detector.clone())
        .map_err(|e| ImportError::Target(Box::new(e)))?;
    let mut frames = Vec::new();
    let mut pairs = Vec::new();
    for files in found.samples {
        let base_from_flange = read_visp_pose(&files.pose_file)?;
        let image = handeye_vision::detect::load_gray_image(&files.image)
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
                pairs.push(PosePair {
                    id: Some(format!("visp-{}", files.number)),
                    view_sigma: p.view_sigma(),
                    ..PosePair::new(base_from_flange, p.camera_from_target)
                });
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
}
