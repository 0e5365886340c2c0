//! The intrinsics file forms of a [`CameraModel`]: reading ROS/OpenCV `camera_info` YAML and
//! Kalibr camchain YAML (its `cam0`), detected by their keys; writing `camera_info` YAML
//! (atomically); checking a model's numbers; and [`CameraModelError`], which names the file, the
//! YAML key, the value found and what was expected. The one reading of a ROS distortion model
//! name ([`Distortion::from_model_name`]) and camera matrix ([`CameraModel::from_camera_matrix`])
//! is here, for these files and for `sensor_msgs/CameraInfo` messages (`handeye-ros2`) alike.
//!
//! Both forms use OpenCV's pixel convention (centres at integers), like [`CameraModel`], so
//! nothing is shifted on the way in or out. Depends on `atomic_file` (the write), `yaml_file`
//! (naming a symlink loop) and on the parent module's types.

use std::path::{Path, PathBuf};

use serde_yaml_ng::Value;

use super::{CameraModel, Distortion};
use crate::atomic_file::write_atomic;
use crate::yaml_file::symlink_loop;

/// The smallest focal length [`CameraModel::validate`] accepts, as a fraction of the image's
/// larger side (a pinhole field of view of about 178°).
pub const MIN_FOCAL_PER_SIZE: f64 = 0.01;
/// The largest focal length [`CameraModel::validate`] accepts, in multiples of the image's larger
/// side (a field of view of about 0.06°): past it a value is a typo, not a lens.
pub const MAX_FOCAL_PER_SIZE: f64 = 1000.0;

/// Why an intrinsics file could not be used.
#[derive(Debug, thiserror::Error)]
pub enum CameraModelError {
    /// The file could not be read or written.
    #[error("intrinsics file {path}: cannot read or write")]
    Io {
        /// The file.
        path: PathBuf,
        /// The I/O failure.
        #[source]
        source: std::io::Error,
    },
    /// The file's path does not resolve: a symbolic link in it leads back to itself.
    #[error("intrinsics file {path}: cannot read: symlink loop at {at}")]
    SymlinkLoop {
        /// The file.
        path: PathBuf,
        /// The link where resolving goes round in circles.
        at: PathBuf,
    },
    /// The file is not YAML text at all (binary bytes, several documents, broken syntax).
    // The parser's error is the problem itself (no further cause): in the message, not also a
    // `#[source]`, so `{:#}` chains print it once.
    #[error("intrinsics file {path}: not a ROS camera_info or Kalibr camchain YAML: {problem}")]
    NotYaml {
        /// The file.
        path: PathBuf,
        /// What the file is instead, in words.
        problem: String,
    },
    /// The YAML is neither a `camera_info` file nor a Kalibr camchain.
    #[error(
        "intrinsics file {path}: not a ROS camera_info YAML (needs `camera_matrix`), a \
         sensor_msgs/CameraInfo message as `ros2 topic echo --once <topic>` prints it (needs \
         `k`, `width`, `height`) nor a Kalibr camchain (needs `cam0`); found {found}"
    )]
    UnknownFormat {
        /// The file.
        path: PathBuf,
        /// What the document holds (its top-level keys, or its kind).
        found: String,
    },
    /// The file has the keys of both forms, so which numbers are meant is a guess.
    #[error(
        "intrinsics file {path}: both a ROS camera_info YAML (keys {camera_info}) and a Kalibr \
         camchain (keys {kalibr}); keep one form in the file"
    )]
    Ambiguous {
        /// The file.
        path: PathBuf,
        /// The `camera_info` keys found.
        camera_info: String,
        /// The Kalibr keys found.
        kalibr: String,
    },
    /// A required key is absent.
    #[error("intrinsics file {path}: missing key `{key}`")]
    MissingKey {
        /// The file.
        path: PathBuf,
        /// The YAML path of the key.
        key: String,
    },
    /// A key holds a value of the wrong form or out of range.
    #[error("intrinsics file {path}: `{key}` must be {expected}, found {found}")]
    BadValue {
        /// The file.
        path: PathBuf,
        /// The YAML path of the key.
        key: String,
        /// What was expected.
        expected: String,
        /// What was found.
        found: String,
    },
}

impl CameraModel {
    /// Checks the model's numbers, the one check every intrinsics source passes through (ROS
    /// `camera_info` and Kalibr YAML, ViSP XML, a bag's `camera_info` messages): a positive image
    /// size; focal lengths between [`MIN_FOCAL_PER_SIZE`] and [`MAX_FOCAL_PER_SIZE`] times the
    /// image's larger side; a principal point inside the image or at most one image size outside
    /// it; finite distortion coefficients that make a lens over this image (see
    /// [`Distortion::check_over_image`]). The error names the key, the value and the bound.
    pub fn validate(&self, path: &Path) -> Result<(), CameraModelError> {
        let bad = |key: &str, expected: &str, found: String| CameraModelError::BadValue {
            path: path.to_path_buf(),
            key: key.to_string(),
            expected: expected.to_string(),
            found,
        };
        if self.width == 0 || self.height == 0 {
            return Err(bad(
                "image size",
                "positive width and height (px)",
                format!("{}x{}", self.width, self.height),
            ));
        }
        let (width, height) = (f64::from(self.width), f64::from(self.height));
        let side = width.max(height);
        let (low, high) = (MIN_FOCAL_PER_SIZE * side, MAX_FOCAL_PER_SIZE * side);
        for (key, value) in [("fx", self.fx), ("fy", self.fy)] {
            if !(value.is_finite() && value >= low && value <= high) {
                return Err(bad(
                    key,
                    &format!(
                        "a positive focal length within {MIN_FOCAL_PER_SIZE} to \
                         {MAX_FOCAL_PER_SIZE} times the image's larger side ({low} to {high} px \
                         for {}x{} px: a field of view between about 178° and 0.06°)",
                        self.width, self.height
                    ),
                    format!("{value:?}"),
                ));
            }
        }
        for (key, value, size) in [("cx", self.cx, width), ("cy", self.cy, height)] {
            if !(value.is_finite() && value >= -size && value <= 2.0 * size) {
                return Err(bad(
                    key,
                    &format!(
                        "a principal point inside the image or at most one image size outside \
                         it ({} to {} px for {}x{} px)",
                        -size,
                        2.0 * size,
                        self.width,
                        self.height
                    ),
                    format!("{value:?}"),
                ));
            }
        }
        let coefficients = self.distortion_coefficients();
        if !coefficients.iter().all(|v| v.is_finite()) {
            return Err(bad(
                "distortion coefficients",
                "finite numbers",
                format!("{coefficients:?}"),
            ));
        }
        // The farthest image corner (pixel edges, OpenCV convention) in distorted normalised
        // coordinates: the radius the distortion must stay a lens out to.
        let corner_radius = [(-0.5, -0.5), (width - 0.5, -0.5), (-0.5, height - 0.5)]
            .into_iter()
            .chain([(width - 0.5, height - 0.5)])
            .map(|(u, v)| ((u - self.cx) / self.fx).hypot((v - self.cy) / self.fy))
            .fold(0.0, f64::max);
        self.distortion
            .check_over_image(corner_radius, self.fx.min(self.fy))
            .map_err(|p| {
                bad(
                    &format!("distortion {}", p.coefficient),
                    &p.expected,
                    format!(
                        "{:?} ({}; coefficients {coefficients:?})",
                        p.value, p.problem
                    ),
                )
            })
    }

    /// The distortion coefficients in file order (`plumb_bob`: k1 k2 p1 p2 k3; `equidistant`: k1..k4).
    pub fn distortion_coefficients(&self) -> Vec<f64> {
        match self.distortion {
            Distortion::None => vec![0.0; 5],
            Distortion::RadTan { k1, k2, p1, p2, k3 } => vec![k1, k2, p1, p2, k3],
            Distortion::Equidistant { k1, k2, k3, k4 } => vec![k1, k2, k3, k4],
        }
    }

    /// Loads intrinsics from a ROS/OpenCV `camera_info` YAML or a Kalibr camchain YAML (its
    /// `cam0`), detected by their keys.
    pub fn load(path: &Path) -> Result<Self, CameraModelError> {
        let bytes = std::fs::read(path).map_err(|source| match symlink_loop(path) {
            Some(at) => CameraModelError::SymlinkLoop {
                path: path.to_path_buf(),
                at,
            },
            None => CameraModelError::Io {
                path: path.to_path_buf(),
                source,
            },
        })?;
        let text = String::from_utf8(bytes).map_err(|e| CameraModelError::NotYaml {
            path: path.to_path_buf(),
            problem: format!(
                "not text (byte {} is not UTF-8): a binary file?",
                e.utf8_error().valid_up_to()
            ),
        })?;
        Self::from_yaml_str(&text, path)
    }

    /// Parses intrinsics YAML text; `path` only names the source in errors.
    pub fn from_yaml_str(text: &str, path: &Path) -> Result<Self, CameraModelError> {
        // `ros2 topic echo --once` ends its message with a `---` line: the end of the message,
        // not a second YAML document.
        let text = strip_echo_end(text);
        let value: Value =
            serde_yaml_ng::from_str(text).map_err(|problem| CameraModelError::NotYaml {
                path: path.to_path_buf(),
                problem: yaml_problem(text, &problem),
            })?;
        let reader = Reader { path };
        let keys: Vec<String> = value
            .as_mapping()
            .map(|m| {
                m.keys()
                    .map(|k| match k.as_str() {
                        Some(k) => k.to_string(),
                        None => serde_json::to_string(k).unwrap_or_else(|_| "?".into()),
                    })
                    .collect()
            })
            .unwrap_or_default();
        let camera_info_keys: Vec<&str> = keys
            .iter()
            .map(String::as_str)
            .filter(|k| CAMERA_INFO_KEYS.contains(k))
            .collect();
        let kalibr_keys: Vec<&str> = keys
            .iter()
            .map(String::as_str)
            .filter(|k| is_kalibr_key(k))
            .collect();
        let has_camera_info = value.get("camera_matrix").is_some();
        let has_kalibr = value.get("cam0").is_some();
        if (has_camera_info && !kalibr_keys.is_empty())
            || (has_kalibr && !camera_info_keys.is_empty())
        {
            return Err(CameraModelError::Ambiguous {
                path: path.to_path_buf(),
                camera_info: camera_info_keys.join(", "),
                kalibr: kalibr_keys.join(", "),
            });
        }
        let model = if has_camera_info {
            reader.camera_info(&value)?
        } else if let Some(cam0) = value.get("cam0") {
            reader.kalibr(cam0)?
        } else if value.get("k").is_some() && value.get("width").is_some() {
            reader.camera_info_message(&value)?
        } else {
            let found = match &value {
                Value::Mapping(_) if keys.is_empty() => "an empty mapping".to_string(),
                Value::Mapping(_) => format!("the keys {}", keys.join(", ")),
                Value::Null => "an empty document".to_string(),
                Value::Sequence(_) => "a list".to_string(),
                Value::String(_) => "a line of text".to_string(),
                Value::Number(_) | Value::Bool(_) => "a single value".to_string(),
                Value::Tagged(_) => "a tagged value".to_string(),
            };
            return Err(CameraModelError::UnknownFormat {
                path: path.to_path_buf(),
                found,
            });
        };
        model.validate(path)?;
        Ok(model)
    }

    /// The ROS `camera_info` YAML text of this model (`plumb_bob` or `equidistant`).
    pub fn to_camera_info_yaml(&self, camera_name: &str) -> String {
        let (model_name, coefficients) = match self.distortion {
            Distortion::Equidistant { .. } => ("equidistant", self.distortion_coefficients()),
            _ => ("plumb_bob", self.distortion_coefficients()),
        };
        let list = |values: &[f64]| {
            values
                .iter()
                .map(|v| format!("{v:?}"))
                .collect::<Vec<_>>()
                .join(", ")
        };
        let (fx, fy, cx, cy) = (self.fx, self.fy, self.cx, self.cy);
        format!(
            "# Pixel centres at integer coordinates (OpenCV/ROS convention).\n\
             image_width: {w}\nimage_height: {h}\ncamera_name: {camera_name}\n\
             camera_matrix:\n  rows: 3\n  cols: 3\n  data: [{k}]\n\
             distortion_model: {model_name}\n\
             distortion_coefficients:\n  rows: 1\n  cols: {n}\n  data: [{d}]\n\
             rectification_matrix:\n  rows: 3\n  cols: 3\n  data: [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]\n\
             projection_matrix:\n  rows: 3\n  cols: 4\n  data: [{p}]\n",
            w = self.width,
            h = self.height,
            k = list(&[fx, 0.0, cx, 0.0, fy, cy, 0.0, 0.0, 1.0]),
            n = coefficients.len(),
            d = list(&coefficients),
            p = list(&[fx, 0.0, cx, 0.0, 0.0, fy, cy, 0.0, 0.0, 0.0, 1.0, 0.0]),
        )
    }

    /// Writes this model as a ROS `camera_info` YAML (atomically).
    pub fn save_camera_info(&self, path: &Path) -> Result<(), CameraModelError> {
        let name = path
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_else(|| "camera".to_string());
        write_atomic(path, self.to_camera_info_yaml(&name).as_bytes()).map_err(|source| {
            CameraModelError::Io {
                path: path.to_path_buf(),
                source,
            }
        })
    }
}

/// The top-level keys of a ROS `camera_info` YAML (`camera_calibration_parsers`).
const CAMERA_INFO_KEYS: [&str; 8] = [
    "image_width",
    "image_height",
    "camera_name",
    "camera_matrix",
    "distortion_model",
    "distortion_coefficients",
    "rectification_matrix",
    "projection_matrix",
];

/// `text` without the `---` line `ros2 topic echo` prints after a message (and what follows
/// only blank lines); any other text as it is.
fn strip_echo_end(text: &str) -> &str {
    let trimmed = text.trim_end();
    match trimmed.strip_suffix("---") {
        Some(rest) if rest.is_empty() || rest.ends_with('\n') => rest,
        _ => text,
    }
}

/// Whether `key` is a top-level key of a Kalibr camchain (`cam0`, `cam1`, ...).
fn is_kalibr_key(key: &str) -> bool {
    key.strip_prefix("cam")
        .is_some_and(|n| !n.is_empty() && n.bytes().all(|b| b.is_ascii_digit()))
}

/// The YAML parser's complaint about `text` in words a person reading an intrinsics error
/// follows (what the file is instead).
fn yaml_problem(text: &str, problem: &serde_yaml_ng::Error) -> String {
    let message = problem.to_string();
    if message.contains("more than one document") {
        let markers = text
            .lines()
            .filter(|l| l.starts_with("---") || l.starts_with("..."))
            .count();
        format!(
            "it holds several YAML documents ({markers} `---`/`...` marker line(s)), an \
             intrinsics file is one mapping of keys"
        )
    } else {
        format!("not YAML of that shape ({message})")
    }
}

/// Pulls typed values out of a YAML tree, naming the file and key path in every error.
struct Reader<'a> {
    path: &'a Path,
}

impl Reader<'_> {
    fn missing(&self, key: &str) -> CameraModelError {
        CameraModelError::MissingKey {
            path: self.path.to_path_buf(),
            key: key.to_string(),
        }
    }

    fn bad(&self, key: &str, expected: &str, found: &Value) -> CameraModelError {
        // Flow style (`[800.0]`), never block style: `- 800.0` reads as a negative number.
        // JSON is flow-style YAML; a mapping with non-string keys falls back to YAML.
        let found = serde_json::to_string(found)
            .or_else(|_| serde_yaml_ng::to_string(found).map(|s| s.trim().to_string()))
            .unwrap_or_else(|_| "?".to_string());
        CameraModelError::BadValue {
            path: self.path.to_path_buf(),
            key: key.to_string(),
            expected: expected.to_string(),
            found,
        }
    }

    fn get<'v>(
        &self,
        node: &'v Value,
        key: &str,
        full_key: &str,
    ) -> Result<&'v Value, CameraModelError> {
        node.get(key).ok_or_else(|| self.missing(full_key))
    }

    fn size(&self, value: &Value, key: &str) -> Result<u32, CameraModelError> {
        value
            .as_u64()
            .and_then(|v| u32::try_from(v).ok())
            .filter(|v| *v > 0)
            .ok_or_else(|| self.bad(key, "a positive integer (px)", value))
    }

    fn numbers(
        &self,
        value: &Value,
        key: &str,
        lengths: &[usize],
    ) -> Result<Vec<f64>, CameraModelError> {
        let expected = format!(
            "a list of {} numbers",
            lengths
                .iter()
                .map(|n| n.to_string())
                .collect::<Vec<_>>()
                .join(" or ")
        );
        let list = value
            .as_sequence()
            .ok_or_else(|| self.bad(key, &expected, value))?;
        let numbers: Option<Vec<f64>> = list.iter().map(Value::as_f64).collect();
        match numbers {
            Some(numbers) if lengths.contains(&numbers.len()) => Ok(numbers),
            _ => Err(self.bad(key, &expected, value)),
        }
    }

    /// Checks an OpenCV matrix node's `rows` and `cols` (when given) against its `data`: the
    /// shape `shape` (rows, cols) when there is one, and `rows · cols` numbers of data. A
    /// `distortion_coefficients` node (no fixed shape) is one row.
    fn matrix_shape(
        &self,
        node: &Value,
        key: &str,
        shape: Option<(u64, u64)>,
    ) -> Result<(), CameraModelError> {
        let data_len = node.get("data").and_then(Value::as_sequence).map(Vec::len);
        let mut dims = [None, None];
        for (slot, name) in dims.iter_mut().zip(["rows", "cols"]) {
            let Some(value) = node.get(name) else {
                continue;
            };
            let full = format!("{key}.{name}");
            let n = value
                .as_u64()
                .ok_or_else(|| self.bad(&full, "a whole number", value))?;
            let expected = match (shape, name) {
                (Some((rows, _)), "rows") => Some(rows),
                (Some((_, cols)), _) => Some(cols),
                (None, _) => None,
            };
            if let Some(expected) = expected.filter(|e| *e != n) {
                return Err(self.bad(&full, &expected.to_string(), value));
            }
            *slot = Some(n);
        }
        if let ([Some(rows), Some(cols)], Some(len)) = (dims, data_len) {
            // A coefficient vector is one row (ROS) or one column (OpenCV).
            if shape.is_none() && rows.min(cols) != 1 && len > 0 {
                return Err(self.bad(
                    &format!("{key}.rows"),
                    &format!("1 (one row of {len} coefficients; or cols: 1)"),
                    &node["rows"],
                ));
            }
            if rows * cols != len as u64 {
                return Err(self.bad(
                    &format!("{key}.data"),
                    &format!("{} numbers (rows {rows} x cols {cols})", rows * cols),
                    &node["data"],
                ));
            }
        }
        Ok(())
    }

    fn camera_info(&self, root: &Value) -> Result<CameraModel, CameraModelError> {
        let width = self.size(self.get(root, "image_width", "image_width")?, "image_width")?;
        let height = self.size(
            self.get(root, "image_height", "image_height")?,
            "image_height",
        )?;
        // ROS's message form names the size `width`/`height`; a file with both must agree.
        for (key, size, own) in [
            ("width", width, "image_width"),
            ("height", height, "image_height"),
        ] {
            if let Some(value) = root.get(key) {
                if value.as_u64() != Some(u64::from(size)) {
                    return Err(self.bad(key, &format!("{size}, the file's {own}"), value));
                }
            }
        }
        let matrix = self.get(root, "camera_matrix", "camera_matrix")?;
        let k = self.numbers(
            self.get(matrix, "data", "camera_matrix.data")?,
            "camera_matrix.data",
            &[9],
        )?;
        self.matrix_shape(matrix, "camera_matrix", Some((3, 3)))?;
        for (key, shape) in [
            ("distortion_coefficients", None),
            ("rectification_matrix", Some((3, 3))),
            ("projection_matrix", Some((3, 4))),
        ] {
            if let Some(node) = root.get(key) {
                self.matrix_shape(node, key, shape)?;
            }
        }
        let model_name = match root.get("distortion_model") {
            None => "plumb_bob".to_string(),
            Some(v) => v
                .as_str()
                .ok_or_else(|| self.bad("distortion_model", "a string", v))?
                .to_string(),
        };
        let coefficients = match root.get("distortion_coefficients") {
            None => Vec::new(),
            Some(node) => self.numbers(
                self.get(node, "data", "distortion_coefficients.data")?,
                "distortion_coefficients.data",
                &[0, 4, 5, 8],
            )?,
        };
        let distortion = self.distortion(&model_name, &coefficients, "distortion_model")?;
        self.pinhole(
            (width, height),
            &k,
            distortion,
            "camera_matrix.data",
            &matrix["data"],
        )
    }

    /// The pinhole of the row-major camera matrix `k` (at `key`, the node `found`), which must
    /// be `[fx, 0, cx, 0, fy, cy, 0, 0, 1]`.
    fn pinhole(
        &self,
        size: (u32, u32),
        k: &[f64],
        distortion: Distortion,
        key: &str,
        found: &Value,
    ) -> Result<CameraModel, CameraModelError> {
        CameraModel::from_camera_matrix(size, k, distortion)
            .ok_or_else(|| self.bad(key, "[fx, 0, cx, 0, fy, cy, 0, 0, 1] (no skew)", found))
    }

    /// A `sensor_msgs/CameraInfo` message as `ros2 topic echo` prints it: `width`, `height`,
    /// `k` (row-major 3x3), `d`, `distortion_model` (the topic a RealSense or any ROS camera
    /// driver publishes its factory calibration on).
    fn camera_info_message(&self, root: &Value) -> Result<CameraModel, CameraModelError> {
        let width = self.size(self.get(root, "width", "width")?, "width")?;
        let height = self.size(self.get(root, "height", "height")?, "height")?;
        let k = self.numbers(self.get(root, "k", "k")?, "k", &[9])?;
        let coefficients = match root.get("d") {
            None | Some(Value::Null) => Vec::new(),
            Some(d) => self.numbers(d, "d", &[0, 4, 5, 8])?,
        };
        // A driver without a calibration publishes an empty model name and no coefficients.
        let model_name = match root.get("distortion_model") {
            None => "plumb_bob",
            Some(v) => v
                .as_str()
                .ok_or_else(|| self.bad("distortion_model", "a string", v))?,
        };
        let distortion = self.distortion(model_name, &coefficients, "distortion_model")?;
        self.pinhole((width, height), &k, distortion, "k", &root["k"])
    }

    fn kalibr(&self, cam0: &Value) -> Result<CameraModel, CameraModelError> {
        if let Some(model) = cam0.get("camera_model") {
            if model.as_str() != Some("pinhole") {
                return Err(self.bad("cam0.camera_model", "`pinhole`", model));
            }
        }
        let intrinsics = self.numbers(
            self.get(cam0, "intrinsics", "cam0.intrinsics")?,
            "cam0.intrinsics",
            &[4],
        )?;
        let resolution = self.get(cam0, "resolution", "cam0.resolution")?;
        let size = self.numbers(resolution, "cam0.resolution", &[2])?;
        let to_size = |v: f64| {
            (v.fract() == 0.0 && v > 0.0 && v < u32::MAX as f64)
                .then_some(v as u32)
                .ok_or_else(|| self.bad("cam0.resolution", "[width, height] in px", resolution))
        };
        let model_name = self
            .get(cam0, "distortion_model", "cam0.distortion_model")?
            .as_str()
            .ok_or_else(|| {
                self.bad(
                    "cam0.distortion_model",
                    "a string",
                    &cam0["distortion_model"],
                )
            })?
            .to_string();
        let coefficients = self.numbers(
            self.get(cam0, "distortion_coeffs", "cam0.distortion_coeffs")?,
            "cam0.distortion_coeffs",
            &[0, 4, 5],
        )?;
        let distortion = self.distortion(&model_name, &coefficients, "cam0.distortion_model")?;
        Ok(CameraModel {
            width: to_size(size[0])?,
            height: to_size(size[1])?,
            fx: intrinsics[0],
            fy: intrinsics[1],
            cx: intrinsics[2],
            cy: intrinsics[3],
            distortion,
        })
    }

    fn distortion(&self, name: &str, c: &[f64], key: &str) -> Result<Distortion, CameraModelError> {
        Distortion::from_model_name(name, c).map_err(|e| match e {
            ModelNameError::Count {
                found, expected, ..
            } => CameraModelError::BadValue {
                path: self.path.to_path_buf(),
                key: format!("{key} coefficients"),
                expected: expected.to_string(),
                found: format!("{found} coefficients for `{name}`"),
            },
            ModelNameError::Unknown(_) => CameraModelError::BadValue {
                path: self.path.to_path_buf(),
                key: key.to_string(),
                expected: MODEL_NAMES.to_string(),
                found: name.to_string(),
            },
        })
    }
}

/// The distortion model names [`Distortion::from_model_name`] reads.
const MODEL_NAMES: &str = "plumb_bob, radtan, equidistant, fisheye or none";

/// Why a distortion model name and its coefficients describe no [`Distortion`].
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ModelNameError {
    /// A model handeye knows, with another number of coefficients than it takes.
    #[error("{found} coefficients for `{name}`, expected {expected}")]
    Count {
        /// The model's name.
        name: String,
        /// How many coefficients were given.
        found: usize,
        /// What the model takes.
        expected: &'static str,
    },
    /// A model handeye does not know.
    #[error("distortion model `{0}`, expected {MODEL_NAMES}")]
    Unknown(String),
}

impl Distortion {
    /// The distortion a ROS `distortion_model` (or Kalibr camchain) name and its coefficients
    /// describe: `plumb_bob` / `radtan` (4 or 5: k1 k2 p1 p2 [k3]), `equidistant` / `fisheye`
    /// (4: k1..k4), `none`; no coefficients under `plumb_bob`, `radtan` or an empty name (a
    /// driver without a calibration) is an ideal pinhole. The one reading of a model name, for
    /// `camera_info` files and `sensor_msgs/CameraInfo` messages alike.
    pub fn from_model_name(name: &str, c: &[f64]) -> Result<Distortion, ModelNameError> {
        let count = |expected| ModelNameError::Count {
            name: name.to_string(),
            found: c.len(),
            expected,
        };
        match (name, c.len()) {
            ("plumb_bob" | "radtan" | "", 0) | ("none", _) => Ok(Distortion::None),
            ("plumb_bob" | "radtan", 4 | 5) => Ok(Distortion::RadTan {
                k1: c[0],
                k2: c[1],
                p1: c[2],
                p2: c[3],
                k3: c.get(4).copied().unwrap_or(0.0),
            }),
            ("plumb_bob" | "radtan", _) => Err(count("4 or 5 coefficients (k1 k2 p1 p2 [k3])")),
            ("equidistant" | "fisheye", 4) => Ok(Distortion::Equidistant {
                k1: c[0],
                k2: c[1],
                k3: c[2],
                k4: c[3],
            }),
            ("equidistant" | "fisheye", _) => Err(count("4 coefficients (k1 k2 k3 k4)")),
            _ => Err(ModelNameError::Unknown(name.to_string())),
        }
    }
}

impl CameraModel {
    /// The pinhole of the row-major camera matrix `k` (`[fx, 0, cx, 0, fy, cy, 0, 0, 1]`) with
    /// its image size and `distortion`; `None` for a matrix of another form (skew, a scaled last
    /// row) or not of 9 numbers. The one reading of a camera matrix, for `camera_info` files and
    /// `sensor_msgs/CameraInfo` messages alike.
    pub fn from_camera_matrix(
        (width, height): (u32, u32),
        k: &[f64],
        distortion: Distortion,
    ) -> Option<CameraModel> {
        let plain =
            k.len() == 9 && k[1] == 0.0 && k[3] == 0.0 && k[6] == 0.0 && k[7] == 0.0 && k[8] == 1.0;
        plain.then(|| CameraModel {
            width,
            height,
            fx: k[0],
            fy: k[4],
            cx: k[2],
            cy: k[5],
            distortion,
        })
    }
}

#[cfg(test)]
mod tests {
    use std::path::Path;

    use super::CameraModelError;
    use crate::camera_model::tests::models;
    use crate::camera_model::{CameraModel, Distortion};

    #[test]
    fn camera_info_round_trips_through_save_and_load() {
        let dir = tempfile::tempdir().unwrap();
        for (i, model) in models().into_iter().enumerate() {
            let path = dir.path().join(format!("cam{i}.yaml"));
            model.save_camera_info(&path).unwrap();
            let loaded = CameraModel::load(&path).unwrap();
            assert_eq!(loaded, model);
        }
    }

    /// What `ros2 topic echo --once /camera/color/camera_info` prints for a RealSense D435's
    /// colour stream (its factory calibration), `---` and all: read as the message says.
    #[test]
    fn a_camera_info_message_as_ros2_topic_echo_prints_it_loads() {
        let echo = "header:\n  stamp:\n    sec: 1733300000\n    nanosec: 123456789\n  frame_id: camera_color_optical_frame\nheight: 720\nwidth: 1280\ndistortion_model: plumb_bob\nd:\n- 0.0\n- 0.0\n- 0.0\n- 0.0\n- 0.0\nk:\n- 909.7\n- 0.0\n- 644.2\n- 0.0\n- 908.9\n- 371.5\n- 0.0\n- 0.0\n- 1.0\nr:\n- 1.0\n- 0.0\n- 0.0\n- 0.0\n- 1.0\n- 0.0\n- 0.0\n- 0.0\n- 1.0\np:\n- 909.7\n- 0.0\n- 644.2\n- 0.0\n- 0.0\n- 908.9\n- 371.5\n- 0.0\n- 0.0\n- 0.0\n- 1.0\n- 0.0\nbinning_x: 0\nbinning_y: 0\nroi:\n  x_offset: 0\n  y_offset: 0\n  height: 0\n  width: 0\n  do_rectify: false\n---\n";
        let model = CameraModel::from_yaml_str(echo, Path::new("echo.yaml")).unwrap();
        assert_eq!((model.width, model.height), (1280, 720));
        assert_eq!(
            (model.fx, model.fy, model.cx, model.cy),
            (909.7, 908.9, 644.2, 371.5)
        );
        assert_eq!(
            model.distortion,
            Distortion::RadTan {
                k1: 0.0,
                k2: 0.0,
                p1: 0.0,
                p2: 0.0,
                k3: 0.0
            }
        );
        // A driver with no calibration: an empty model name and no coefficients.
        let bare = echo
            .replace("distortion_model: plumb_bob", "distortion_model: ''")
            .replace("d:\n- 0.0\n- 0.0\n- 0.0\n- 0.0\n- 0.0\n", "d: []\n");
        let model = CameraModel::from_yaml_str(&bare, Path::new("echo.yaml")).unwrap();
        assert_eq!(model.distortion, Distortion::None);
        // A skewed `k` is refused naming the key.
        let skewed = echo.replacen("- 909.7\n- 0.0\n", "- 909.7\n- 2.0\n", 1);
        let message = CameraModel::from_yaml_str(&skewed, Path::new("echo.yaml"))
            .unwrap_err()
            .to_string();
        assert!(
            message.contains("echo.yaml") && message.contains("`k` must be [fx, 0, cx"),
            "{message}"
        );
    }

    #[test]
    fn kalibr_camchain_loads_cam0() {
        let text = "cam0:\n  camera_model: pinhole\n  intrinsics: [461.6, 460.3, 363.0, 248.1]\n  \
                    distortion_model: radtan\n  distortion_coeffs: [-0.2917, 0.08228, 5.333e-05, -0.0001578]\n  \
                    resolution: [752, 480]\n  rostopic: /cam0/image_raw\n";
        let model = CameraModel::from_yaml_str(text, Path::new("camchain.yaml")).unwrap();
        assert_eq!((model.width, model.height), (752, 480));
        assert_eq!(model.fx, 461.6);
        assert_eq!(
            model.distortion,
            Distortion::RadTan {
                k1: -0.2917,
                k2: 0.08228,
                p1: 5.333e-05,
                p2: -0.0001578,
                k3: 0.0
            }
        );
    }

    #[test]
    fn bad_files_name_the_key_and_expectation() {
        let path = Path::new("bad.yaml");
        let error = CameraModel::from_yaml_str("foo: 1\n", path).unwrap_err();
        assert!(
            matches!(error, CameraModelError::UnknownFormat { .. }),
            "{error}"
        );
        let error = CameraModel::from_yaml_str(
            "image_width: 640\nimage_height: 480\ncamera_matrix: {data: [1, 0, 2, 0, 1, 2, 0, 0]}\n",
            path,
        )
        .unwrap_err();
        let message = error.to_string();
        assert!(
            message.contains("camera_matrix.data") && message.contains("9 numbers"),
            "{message}"
        );
        let error = CameraModel::from_yaml_str(
            "image_width: 640\nimage_height: 480\ncamera_matrix: {data: [-5, 0, 2, 0, 1, 2, 0, 0, 1]}\n",
            path,
        )
        .unwrap_err();
        assert!(error.to_string().contains("fx"), "{error}");
        let error = CameraModel::from_yaml_str(
            "image_width: 640\nimage_height: 480\ncamera_matrix: {data: [5, 0, 2, 0, 1, 2, 0, 0, 1]}\n\
             distortion_model: rational_polynomial\ndistortion_coefficients: {data: [0, 0, 0, 0, 0, 0, 0, 0]}\n",
            path,
        )
        .unwrap_err();
        assert!(error.to_string().contains("rational_polynomial"), "{error}");
    }
}
