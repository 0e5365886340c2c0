//! Static transforms on `/tf_static`, as tf2's `static_transform_publisher` sends them: one
//! `tf2_msgs/TFMessage` holding every transform, on a reliable, transient-local writer of depth
//! 1, so a node that starts later still receives it while the writer lives.

use handeye_core::geometry::Pose;
use ros2_client::Publisher;

use crate::link::{static_qos, Ros2Link};
use crate::msg::{Header, TfMessage, Time, Transform, TransformStamped};
use crate::Ros2Error;

/// One transform to publish: `T_parent_child`.
#[derive(Debug, Clone, PartialEq)]
pub struct StaticTransform {
    /// Parent frame id (no leading `/`).
    pub parent: String,
    /// Child frame id.
    pub child: String,
    /// `T_parent_child`.
    pub parent_from_child: Pose,
}

/// The message of `transforms`, stamped `stamp`.
pub fn tf_message(transforms: &[StaticTransform], stamp: Time) -> TfMessage {
    TfMessage {
        transforms: transforms
            .iter()
            .map(|t| TransformStamped {
                header: Header {
                    stamp,
                    frame_id: t.parent.clone(),
                },
                child_frame_id: t.child.clone(),
                transform: Transform::from_pose(&t.parent_from_child),
            })
            .collect(),
    }
}

/// A latched `/tf_static` writer holding its message: the transforms stay available to late
/// joiners until it is dropped.
pub struct StaticPublisher {
    _writer: Publisher<TfMessage>,
}

impl StaticPublisher {
    /// Publishes `transforms` once on `topic` (normally `/tf_static`), stamped now.
    pub fn publish(
        link: &Ros2Link,
        topic: &str,
        transforms: &[StaticTransform],
    ) -> Result<StaticPublisher, Ros2Error> {
        let writer = link.publisher::<TfMessage>(topic, static_qos())?;
        writer
            .publish(tf_message(transforms, Time::now()))
            .map_err(|e| Ros2Error::Publish {
                topic: topic.to_string(),
                reason: format!("{e:?}"),
            })?;
        Ok(StaticPublisher { _writer: writer })
    }
}
