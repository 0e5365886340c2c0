//! A validated [`Pose`] held in memory and read and written in the pose form of every YAML file
//! (`#[serde(with = "serde_pose")]`, or [`option`] for an optional one): the file's shape
//! ([`PoseYaml`]) lives only at the edge, and a pose that fails its checks (a quaternion of norm
//! 0.9, a matrix that is not a rotation) is refused when the file is read, with the field's path.

use serde::{Deserialize, Deserializer, Serialize, Serializer};

use super::{Pose, PoseYaml};

/// Writes `pose` as `translation` and `quaternion`.
pub fn serialize<S: Serializer>(pose: &Pose, serializer: S) -> Result<S::Ok, S::Error> {
    PoseYaml::from_pose(pose).serialize(serializer)
}

/// Reads any pose form and checks it.
pub fn deserialize<'de, D: Deserializer<'de>>(deserializer: D) -> Result<Pose, D::Error> {
    checked(PoseYaml::deserialize(deserializer)?)
}

fn checked<E: serde::de::Error>(raw: PoseYaml) -> Result<Pose, E> {
    // The reader's own path (serde_path_to_error) names the field; the problem names the key
    // inside the pose.
    raw.to_pose("").map_err(|e| match e.path.as_str() {
        "" => E::custom(&e.problem),
        key => E::custom(format_args!("{key}: {}", e.problem)),
    })
}

/// The same for an optional pose (`None` is written as nothing: pair it with
/// `skip_serializing_if = "Option::is_none"` and `default`).
pub mod option {
    use super::*;

    /// Writes the pose when there is one.
    pub fn serialize<S: Serializer>(pose: &Option<Pose>, serializer: S) -> Result<S::Ok, S::Error> {
        pose.as_ref().map(PoseYaml::from_pose).serialize(serializer)
    }

    /// Reads an optional pose and checks it.
    pub fn deserialize<'de, D: Deserializer<'de>>(
        deserializer: D,
    ) -> Result<Option<Pose>, D::Error> {
        Option::<PoseYaml>::deserialize(deserializer)?
            .map(checked)
            .transpose()
    }
}
