//! The intrinsics file forms of a [`CameraModel`]: reading ROS/OpenCV `camera_info` YAML and
//! Kalibr camchain YAML (its `cam0`), detected by their keys; writing `camera_info` YAML
//! (atomically); checking a model's numbers; and [`CameraModelError`], which names the file, the
//! YAML key, the value found and what was expected.
//!
//! Both forms use OpenCV's pixel convention (centres at integers), like [`CameraModel`], so
//! nothing is shifted on the way in or out. Depends on `atomic_file` (the write) and on the
//! parent module's types.

use std::path::{Path, PathBuf};

use serde_yaml_ng::Value;

use super::{CameraModel, Distortion};
use crate::atomic_file::write_atomic;

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
    /// The file is not YAML.
    // The parser's error is the problem itself (no further cause): in the message, not also a
    // `#[source]`, so `{:#}` chains print it once.
    #[error("intrinsics file {path}: not valid YAML: {problem}")]
    Yaml {
        /// The file.
        path: PathBuf,
        /// The parser's error.
        problem: serde_yaml_ng::Error,
    },
    /// The YAML is neither a `camera_info` file nor a Kalibr camchain.
    #[error(
        "intrinsics file {path}: neither a camera_info YAML (needs `camera_matrix`) nor a Kalibr \
         camchain (needs `cam0`)"
    )]
    UnknownFormat {
        /// The file.
        path: PathBuf,
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
    /// Checks the model's numbers (positive finite focal lengths and size, finite coefficients).
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
        for (key, value) in [("fx", self.fx), ("fy", self.fy)] {
            if !(value.is_finite() && value > 0.0) {
                return Err(bad(key, "a positive focal length (px)", value.to_string()));
            }
        }
        for (key, value) in [("cx", self.cx), ("cy", self.cy)] {
            if !value.is_finite() {
                return Err(bad(key, "a finite principal point (px)", value.to_string()));
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
        Ok(())
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
        let text = std::fs::read_to_string(path).map_err(|source| CameraModelError::Io {
            path: path.to_path_buf(),
            source,
        })?;
        Self::from_yaml_str(&text, path)
    }

    /// Parses intrinsics YAML text; `path` only names the source in errors.
    pub fn from_yaml_str(text: &str, path: &Path) -> Result<Self, CameraModelError> {
        let value: Value =
            serde_yaml_ng::from_str(text).map_err(|problem| CameraModelError::Yaml {
                path: path.to_path_buf(),
                problem,
            })?;
        let reader = Reader { path };
        let model = if value.get("camera_matrix").is_some() {
            reader.camera_info(&value)?
        } else if let Some(cam0) = value.get("cam0") {
            reader.kalibr(cam0)?
        } else {
            return Err(CameraModelError::UnknownFormat {
                path: path.to_path_buf(),
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

    fn camera_info(&self, root: &Value) -> Result<CameraModel, CameraModelError> {
        let width = self.size(self.get(root, "image_width", "image_width")?, "image_width")?;
        let height = self.size(
            self.get(root, "image_height", "image_height")?,
            "image_height",
        )?;
        let matrix = self.get(root, "camera_matrix", "camera_matrix")?;
        let k = self.numbers(
            self.get(matrix, "data", "camera_matrix.data")?,
            "camera_matrix.data",
            &[9],
        )?;
        if k[1] != 0.0 || k[3] != 0.0 || k[6] != 0.0 || k[7] != 0.0 || k[8] != 1.0 {
            return Err(self.bad(
                "camera_matrix.data",
                "[fx, 0, cx, 0, fy, cy, 0, 0, 1] (no skew)",
                &matrix["data"],
            ));
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
        Ok(CameraModel {
            width,
            height,
            fx: k[0],
            fy: k[4],
            cx: k[2],
            cy: k[5],
            distortion,
        })
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
        let count_error = |expected: &str| CameraModelError::BadValue {
            path: self.path.to_path_buf(),
            key: format!("{key} coefficients"),
            expected: expected.to_string(),
            found: format!("{} coefficients for `{name}`", c.len()),
        };
        match name {
            "plumb_bob" | "radtan" => match c.len() {
                0 => Ok(Distortion::None),
                4 | 5 => Ok(Distortion::RadTan {
                    k1: c[0],
                    k2: c[1],
                    p1: c[2],
                    p2: c[3],
                    k3: c.get(4).copied().unwrap_or(0.0),
                }),
                _ => Err(count_error("4 or 5 coefficients (k1 k2 p1 p2 [k3])")),
            },
            "equidistant" | "fisheye" => match c.len() {
                4 => Ok(Distortion::Equidistant {
                    k1: c[0],
                    k2: c[1],
                    k3: c[2],
                    k4: c[3],
                }),
                _ => Err(count_error("4 coefficients (k1 k2 k3 k4)")),
            },
            "none" => Ok(Distortion::None),
            _ => Err(CameraModelError::BadValue {
                path: self.path.to_path_buf(),
                key: key.to_string(),
                expected: "plumb_bob, radtan, equidistant, fisheye or none".to_string(),
                found: name.to_string(),
            }),
        }
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
