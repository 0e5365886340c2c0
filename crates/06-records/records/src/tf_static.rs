//! `tf_static.yaml`: the static transforms a ROS 2 graph held when a run started (the camera
//! driver's chain from its mounting link to the optical frame of its images, the robot driver's
//! `base_link → base`), as heard on `/tf_static`. Recorded so that what the hardware published is
//! part of the session: `export --camera-link` hangs the camera from the chain the driver
//! published, without the driver running.
//!
//! ```yaml
//! topic: /tf_static
//! transforms:
//!   - {parent: camera_link, child: camera_color_frame, pose: {translation: [..], quaternion: {..}, ..}}
//! ```

use std::path::Path;

use serde::{Deserialize, Serialize};

use handeye_core::geometry::{serde_pose, Pose};
use handeye_core::yaml_file::{read_yaml, write_yaml, FileError};
use handeye_ros2::listen::TfTree;
use handeye_ros2::msg::{Header, TfMessage, Time, Transform, TransformStamped};

/// The file's name in a session folder.
pub const TF_STATIC_FILE: &str = "tf_static.yaml";

/// The static transforms heard.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct StaticTransformsFile {
    /// The topic they were heard on.
    pub topic: String,
    /// Each edge, `T_parent_child`.
    pub transforms: Vec<HeardTransform>,
}

/// One static transform heard.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct HeardTransform {
    /// The parent frame id.
    pub parent: String,
    /// The child frame id.
    pub child: String,
    /// `T_parent_child`.
    #[serde(with = "serde_pose")]
    pub pose: Pose,
}

impl StaticTransformsFile {
    /// The edges of `tree`, heard on `topic`.
    pub fn from_tree(topic: &str, tree: &TfTree) -> StaticTransformsFile {
        StaticTransformsFile {
            topic: topic.to_string(),
            transforms: tree
                .edges()
                .into_iter()
                .map(|(parent, child, pose)| HeardTransform {
                    parent,
                    child,
                    pose,
                })
                .collect(),
        }
    }

    /// The tree the edges make.
    pub fn tree(&self) -> TfTree {
        let mut tree = TfTree::default();
        tree.update(&TfMessage {
            transforms: self
                .transforms
                .iter()
                .map(|t| TransformStamped {
                    header: Header {
                        stamp: Time::default(),
                        frame_id: t.parent.clone(),
                    },
                    child_frame_id: t.child.clone(),
                    transform: Transform::from_pose(&t.pose),
                })
                .collect(),
        });
        tree
    }

    /// Writes the file atomically.
    pub fn save(&self, path: &Path) -> Result<(), FileError> {
        write_yaml(self, path)
    }

    /// Reads a file.
    pub fn load(path: &Path) -> Result<StaticTransformsFile, FileError> {
        read_yaml(path)
    }
}
