//! The dataset file: the solver's input, and what a calibration session writes.
//!
//! ```yaml
//! setup: eye_in_hand          # or eye_to_hand
//! samples:
//!   - T_base_flange:   {translation: [..], quaternion: {w: .., x: .., y: .., z: ..}}
//!     T_camera_target: {translation: [..], rotation_vector: [..]}
//!     id: pose-03             # optional; text (quote a number: "7"), unique in the file
//!     weight: 1.0             # optional, > 0
//!     view_sigma: {rotation_deg: .., translation_mm: ..}  # optional, written by
//!                             # a session: how precisely the view fixed T_camera_target
//! ```
//!
//! Poses use the YAML pose form of `geometry::yaml` (metres, radians). Unknown keys are refused so
//! typos never pass. Reading is two steps: serde (through `serde_path_to_error`) reads the shape,
//! then every pose is validated; every error names the file, the YAML path
//! (`samples[3].T_camera_target.quaternion`) and the problem. Writing is atomic. Errors are the
//! [`FileError`] every YAML file of the tool shares (`yaml_file`).

use std::path::Path;

use serde::{Deserialize, Serialize};

use handeye_core::geometry::PoseYaml;
use handeye_core::setup::{PosePair, Setup, ViewSigma};

pub use handeye_core::yaml_file::FileError;
use handeye_core::yaml_file::{parse_yaml, read_text, write_yaml, SchemaVersion};

/// One sample as written in the file.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SampleYaml {
    /// Optional name of the sample: text (`pose-03`, or a quoted `"7"`), unique in the file. A
    /// bare number is refused: YAML would read `7`, `07` and `7.0` as one number, so ids written
    /// as numbers silently lose what tells them apart.
    #[serde(
        default,
        skip_serializing_if = "Option::is_none",
        deserialize_with = "sample_id"
    )]
    pub id: Option<String>,
    /// Optional weight (> 0, default 1).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub weight: Option<f64>,
    /// The robot's flange pose in its base.
    #[serde(rename = "T_base_flange")]
    pub base_from_flange: PoseYaml,
    /// The target's pose in the camera.
    #[serde(rename = "T_camera_target")]
    pub camera_from_target: PoseYaml,
    /// How precisely the view fixed `T_camera_target` (the 1-sigma of its board pose), when the
    /// board pose estimate gave it: the solve weights the sample by it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub view_sigma: Option<ViewSigma>,
}

/// Reads a sample id: a string (or null); a number, boolean, list or mapping is refused with a
/// hint to quote it.
fn sample_id<'de, D: serde::Deserializer<'de>>(d: D) -> Result<Option<String>, D::Error> {
    struct Id;
    impl<'de> serde::de::Visitor<'de> for Id {
        type Value = Option<String>;
        fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
            f.write_str(
                "a sample name in text (`id: pose-03`; quote a number to keep it as written: \
                 `id: \"7\"`)",
            )
        }
        fn visit_str<E: serde::de::Error>(self, v: &str) -> Result<Self::Value, E> {
            Ok(Some(v.to_string()))
        }
        fn visit_unit<E: serde::de::Error>(self) -> Result<Self::Value, E> {
            Ok(None)
        }
        fn visit_none<E: serde::de::Error>(self) -> Result<Self::Value, E> {
            Ok(None)
        }
    }
    d.deserialize_any(Id)
}

/// The dataset file as written.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(
    deny_unknown_fields,
    expecting = "a dataset mapping (setup: eye_in_hand or eye_to_hand, samples: [...])"
)]
pub struct DatasetYaml {
    /// The layout version of this file ([`SchemaVersion`]; absent in files written before it).
    #[serde(default = "SchemaVersion::unversioned")]
    pub schema_version: SchemaVersion,
    /// `eye_in_hand` or `eye_to_hand`.
    pub setup: Setup,
    /// The pose pairs.
    pub samples: Vec<SampleYaml>,
}

/// A validated dataset: the setup and its pose pairs.
#[derive(Debug, Clone, PartialEq)]
pub struct Dataset {
    /// The cell layout.
    pub setup: Setup,
    /// The samples, in file order.
    pub pairs: Vec<PosePair>,
}

impl Dataset {
    /// Reads and validates a dataset file.
    pub fn load(path: &Path) -> Result<Dataset, FileError> {
        Dataset::parse(&read_text(path)?, path)
    }

    /// Parses and validates dataset text; `path` is only used in errors. Another of the tool's
    /// files (a result, a cell config) is named as such rather than reported as a shape error.
    pub fn parse(text: &str, path: &Path) -> Result<Dataset, FileError> {
        let raw: DatasetYaml = parse_yaml(text, path).map_err(|e| match e {
            FileError::Shape { .. } => other_kind(text, path).unwrap_or(e),
            e => e,
        })?;
        Dataset::from_yaml(&raw, path)
    }

    /// Validates the raw form.
    pub fn from_yaml(raw: &DatasetYaml, path: &Path) -> Result<Dataset, FileError> {
        let pose_error = |problem| FileError::Pose {
            path: path.to_path_buf(),
            problem,
        };
        let mut seen: std::collections::HashMap<&str, usize> = std::collections::HashMap::new();
        for (i, s) in raw.samples.iter().enumerate() {
            let Some(id) = s.id.as_deref() else { continue };
            if let Some(first) = seen.insert(id, i) {
                return Err(FileError::Value {
                    path: path.to_path_buf(),
                    yaml_path: format!("samples[{i}].id"),
                    problem: format!(
                        "id `{id}` is already the id of samples[{first}]: every sample's id must \
                         be unique (the report and the residuals name samples by it)"
                    ),
                });
            }
        }
        let pairs = raw
            .samples
            .iter()
            .enumerate()
            .map(|(i, s)| {
                let weight = s.weight.unwrap_or(1.0);
                if !(weight.is_finite() && weight > 0.0) {
                    return Err(FileError::Value {
                        path: path.to_path_buf(),
                        yaml_path: format!("samples[{i}].weight"),
                        problem: format!("weight {weight} must be a positive finite number"),
                    });
                }
                Ok(PosePair {
                    base_from_flange: s
                        .base_from_flange
                        .to_pose(&format!("samples[{i}].T_base_flange"))
                        .map_err(pose_error)?,
                    camera_from_target: s
                        .camera_from_target
                        .to_pose(&format!("samples[{i}].T_camera_target"))
                        .map_err(pose_error)?,
                    weight,
                    id: s.id.clone(),
                    view_sigma: s.view_sigma,
                })
            })
            .collect::<Result<Vec<_>, _>>()?;
        Ok(Dataset {
            setup: raw.setup,
            pairs,
        })
    }

    /// The compact file form (translation + quaternion per pose; weight only when not 1).
    pub fn to_yaml(&self) -> DatasetYaml {
        DatasetYaml {
            schema_version: SchemaVersion::CURRENT,
            setup: self.setup,
            samples: self
                .pairs
                .iter()
                .map(|p| SampleYaml {
                    id: p.id.clone(),
                    weight: (p.weight != 1.0).then_some(p.weight),
                    base_from_flange: PoseYaml::from_pose(&p.base_from_flange),
                    camera_from_target: PoseYaml::from_pose(&p.camera_from_target),
                    view_sigma: p.view_sigma,
                })
                .collect(),
        }
    }

    /// Writes the dataset atomically in the compact form, which [`Dataset::load`] reads back.
    pub fn save(&self, path: &Path) -> Result<(), FileError> {
        write_yaml(&self.to_yaml(), path)
    }
}

/// The `samples.yaml` of a session being recorded, sample by sample (keyed by plan index, written
/// in plan order): each sample's YAML is made once, when it is added, and the file is written
/// whole and atomically from those texts, so adding the n-th sample costs one sample's
/// serialisation rather than n (a 200-sample bag import spent 4 % of its CPU serialising the
/// file again after every sample, a cost growing with the square of the samples). The text is
/// the one [`Dataset::save`] writes (tested), so every reader reads it as before.
#[derive(Debug, Clone)]
pub struct SamplesLog {
    setup: Setup,
    samples: std::collections::BTreeMap<usize, (PosePair, String)>,
}

impl SamplesLog {
    /// An empty log of `setup`.
    pub fn new(setup: Setup) -> SamplesLog {
        SamplesLog {
            setup,
            samples: std::collections::BTreeMap::new(),
        }
    }

    /// Adds (or replaces) the sample of plan pose `key`; `path` names the file in an error.
    pub fn insert(&mut self, key: usize, pair: PosePair, path: &Path) -> Result<(), FileError> {
        let one = Dataset {
            setup: self.setup,
            pairs: vec![pair.clone()],
        };
        let text = serde_yaml_ng::to_string(&one.to_yaml().samples).map_err(|source| {
            FileError::Serialise {
                path: path.to_path_buf(),
                source,
            }
        })?;
        self.samples.insert(key, (pair, text));
        Ok(())
    }

    /// Whether it holds no sample.
    pub fn is_empty(&self) -> bool {
        self.samples.is_empty()
    }

    /// The samples in plan order.
    pub fn pairs(&self) -> impl Iterator<Item = &PosePair> {
        self.samples.values().map(|(pair, _)| pair)
    }

    /// Writes the file atomically (what [`Dataset::save`] of the same samples writes).
    pub fn save(&self, path: &Path) -> Result<(), FileError> {
        let header =
            serde_yaml_ng::to_string(&self.header()).map_err(|source| FileError::Serialise {
                path: path.to_path_buf(),
                source,
            })?;
        // The header's keys as serde writes them, the empty list's `[]` replaced by the block
        // list of every sample's text (with no sample, or were serde to write the empty list
        // otherwise, the whole file is serialised as `Dataset::save` does).
        let Some(head) = header
            .strip_suffix(" []\n")
            .filter(|_| !self.samples.is_empty())
        else {
            let pairs = self.pairs().cloned().collect();
            return Dataset {
                setup: self.setup,
                pairs,
            }
            .save(path);
        };
        let mut text = String::with_capacity(
            head.len() + 1 + self.samples.values().map(|(_, t)| t.len()).sum::<usize>(),
        );
        text.push_str(head);
        text.push('\n');
        for (_, sample) in self.samples.values() {
            text.push_str(sample);
        }
        handeye_core::atomic_file::write_atomic(path, text.as_bytes()).map_err(|source| {
            FileError::Write {
                path: path.to_path_buf(),
                source,
            }
        })
    }

    /// The file's keys before its samples, with no sample.
    fn header(&self) -> DatasetYaml {
        DatasetYaml {
            schema_version: SchemaVersion::CURRENT,
            setup: self.setup,
            samples: Vec::new(),
        }
    }
}

/// The kind of tool file `text` is when it is not a dataset but has the top-level keys of a result
/// file or a cell config; `None` otherwise (the shape error stands).
fn other_kind(text: &str, path: &Path) -> Option<FileError> {
    let value: serde_yaml_ng::Value = serde_yaml_ng::from_str(text).ok()?;
    let map = value.as_mapping()?;
    let has = |key: &str| map.contains_key(key);
    if has("samples") {
        return None;
    }
    let (found, hint) = if ["T_flange_camera", "T_base_camera"].iter().any(|k| has(k))
        && (has("residuals") || has("solver"))
    {
        ("result file", "give the session folder or its samples.yaml")
    } else if has("robot") && has("camera") && has("target") {
        (
            "cell config",
            "give the session folder or its samples.yaml (record one with `handeye run --config`)",
        )
    } else {
        return None;
    };
    Some(FileError::WrongKind {
        path: path.to_path_buf(),
        found,
        expected: "dataset",
        hint,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use handeye_core::geometry::Pose;
    use nalgebra::{Translation3, UnitQuaternion};

    #[test]
    fn a_samples_log_writes_what_save_writes_and_reads_back() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand::rngs::StdRng::seed_from_u64(43);
        let dir = tempfile::tempdir().unwrap();
        let (log_path, save_path) = (dir.path().join("log.yaml"), dir.path().join("save.yaml"));
        for setup in [Setup::EyeInHand, Setup::EyeToHand] {
            let mut log = SamplesLog::new(setup);
            log.save(&log_path).unwrap();
            let empty = Dataset {
                setup,
                pairs: Vec::new(),
            };
            empty.save(&save_path).unwrap();
            assert_eq!(
                std::fs::read(&log_path).unwrap(),
                std::fs::read(&save_path).unwrap()
            );
            let mut by_key = std::collections::BTreeMap::new();
            // Added out of plan order, one replaced, ids absent or present, weights 1 or not.
            for _ in 0..12 {
                let key = rng.random_range(0..9);
                let pose = |rng: &mut rand::rngs::StdRng| {
                    Pose::from_parts(
                        Translation3::new(rng.random(), rng.random(), rng.random()),
                        UnitQuaternion::from_euler_angles(rng.random(), rng.random(), rng.random()),
                    )
                };
                let pair = PosePair {
                    base_from_flange: pose(&mut rng),
                    camera_from_target: pose(&mut rng),
                    weight: if rng.random_bool(0.3) { 2.5 } else { 1.0 },
                    id: rng.random_bool(0.7).then(|| format!("pose-{key:03}")),
                    view_sigma: rng.random_bool(0.5).then(|| ViewSigma {
                        rotation_deg: rng.random_range(0.001..0.1),
                        translation_mm: rng.random_range(0.01..1.0),
                    }),
                };
                log.insert(key, pair.clone(), &log_path).unwrap();
                by_key.insert(key, pair);
                log.save(&log_path).unwrap();
                let dataset = Dataset {
                    setup,
                    pairs: by_key.values().cloned().collect(),
                };
                dataset.save(&save_path).unwrap();
                assert_eq!(
                    std::fs::read_to_string(&log_path).unwrap(),
                    std::fs::read_to_string(&save_path).unwrap()
                );
                assert_eq!(log.pairs().cloned().collect::<Vec<_>>(), dataset.pairs);
                assert_eq!(
                    Dataset::load(&log_path).unwrap(),
                    Dataset::load(&save_path).unwrap()
                );
            }
        }
    }

    #[test]
    fn save_and_load_round_trip() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("samples.yaml");
        let pose = |k: f64| {
            Pose::from_parts(
                Translation3::new(0.1 * k, -0.2, 0.3),
                UnitQuaternion::from_euler_angles(0.1 * k, -0.4, 2.0),
            )
        };
        let dataset = Dataset {
            setup: Setup::EyeToHand,
            pairs: (0..3)
                .map(|k| PosePair {
                    base_from_flange: pose(k as f64),
                    camera_from_target: pose(-(k as f64)),
                    weight: if k == 1 { 2.5 } else { 1.0 },
                    id: (k == 2).then(|| "last".to_string()),
                    view_sigma: (k == 0).then_some(ViewSigma {
                        rotation_deg: 0.0125,
                        translation_mm: 0.375,
                    }),
                })
                .collect(),
        };
        dataset.save(&path).unwrap();
        let back = Dataset::load(&path).unwrap();
        assert_eq!(back.setup, Setup::EyeToHand);
        assert_eq!(back.pairs.len(), 3);
        for (a, b) in back.pairs.iter().zip(&dataset.pairs) {
            assert!(
                a.base_from_flange
                    .rotation
                    .angle_to(&b.base_from_flange.rotation)
                    < 1e-15
            );
            assert!(
                (a.camera_from_target.translation.vector - b.camera_from_target.translation.vector)
                    .norm()
                    < 1e-15
            );
            assert_eq!(a.weight, b.weight);
            assert_eq!(a.id, b.id);
            assert_eq!(a.view_sigma, b.view_sigma);
        }
    }
}
