//! Static transforms on `/tf_static`, as tf2's `static_transform_publisher` sends them: one
//! `tf2_msgs/TFMessage` holding every transform, on a reliable, transient-local writer of depth
//! 1, so a node that starts later still receives it while the writer lives.

use std::time::{Duration, Instant};

use handeye_core::geometry::Pose;
use ros2_client::Publisher;

use crate::link::{static_qos, static_reader_qos, Ros2Link};
use crate::listen::TfTree;
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

/// The static transforms other nodes keep latched on `topic` (normally `/tf_static`), as a late
/// joiner hears them within `window` (transient local: each publisher's message arrives once
/// discovery has matched it, a second or so on one machine): the tree they make, each edge with
/// its publisher (two publishers of one edge that disagree make a lookup through it fail, naming
/// both).
pub fn hear_static(link: &Ros2Link, topic: &str, window: Duration) -> Result<TfTree, Ros2Error> {
    let reader = link.subscribe::<TfMessage>(topic, static_reader_qos())?;
    let mut tree = TfTree::default();
    let end = Instant::now() + window;
    while Instant::now() < end {
        match reader.take() {
            Ok(Some((message, info))) => {
                tree.update_from(&message, crate::arm::publisher_id(&info), Instant::now());
            }
            // Nothing new (or an undecodable sample, which a tf2 listener skips too).
            Ok(None) | Err(_) => std::thread::sleep(Duration::from_millis(20)),
        }
    }
    Ok(tree)
}
