//! One DDS participant and one ROS 2 node for everything handeye does on ROS 2 in a process
//! (the robot and camera backends and `handeye publish` share it): ros2-client on RustDDS.
//!
//! Discovery is standard RTPS (SPDP/SEDP, multicast where the network has it, and RustDDS's
//! same-host unicast to the well-known loopback ports), so any ROS 2 node on the same domain id
//! finds it — rmw_cyclonedds, rmw_fastrtps — with no ROS installation here. `interfaces` limits
//! the participant to some local addresses (e.g. `127.0.0.1` for a test on one machine, the
//! robot network's address on a lab PC with several).

use std::net::IpAddr;
use std::sync::{Arc, Mutex};
use std::thread;
use std::time::{Duration, Instant};

use futures::FutureExt;
use ros2_client::{
    Context, MessageTypeName, Name, Node, NodeName, NodeOptions, Publisher, QosProfile,
    Subscription,
};
use serde::de::DeserializeOwned;
use serde::Serialize;

use crate::msg::RosType;
use crate::Ros2Error;

/// Where and as whom to join the ROS 2 graph.
#[derive(Debug, Clone, PartialEq)]
pub struct LinkOptions {
    /// The ROS_DOMAIN_ID (0–232).
    pub domain_id: u16,
    /// Local addresses to use; empty: every interface.
    pub interfaces: Vec<IpAddr>,
    /// The node's name (`handeye`).
    pub node_name: String,
}

impl Default for LinkOptions {
    fn default() -> Self {
        LinkOptions {
            domain_id: 0,
            interfaces: Vec::new(),
            node_name: "handeye".into(),
        }
    }
}

/// A joined ROS 2 graph: cheap to clone, every clone the same node.
#[derive(Clone)]
pub struct Ros2Link {
    node: Arc<Mutex<Node>>,
    /// The node's name, parsed once (a topic's DDS name is made relative to it).
    node_name: NodeName,
    /// The DDS context, for what discovery has heard.
    context: Context,
    options: LinkOptions,
}

impl std::fmt::Debug for Ros2Link {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Ros2Link")
            .field("options", &self.options)
            .finish()
    }
}

fn setup(what: impl Into<String>) -> impl FnOnce(String) -> Ros2Error {
    let what = what.into();
    move |reason| Ros2Error::Setup { what, reason }
}

impl Ros2Link {
    /// Joins domain `options.domain_id` as node `/<node_name>`; its background task (graph
    /// updates) runs on a thread of its own until the last clone is dropped.
    pub fn open(options: LinkOptions) -> Result<Ros2Link, Ros2Error> {
        if options.domain_id > 232 {
            return Err(Ros2Error::Setup {
                what: format!("the DDS participant on domain {}", options.domain_id),
                reason: "a ROS 2 domain id is 0..=232".into(),
            });
        }
        let what = format!("the DDS participant on domain {}", options.domain_id);
        let mut builder =
            ros2_client::dds::rustdds::DomainParticipantBuilder::new(options.domain_id);
        if !options.interfaces.is_empty() {
            builder = builder.with_only_networks(options.interfaces.iter().copied());
        }
        let participant = builder
            .build()
            .map_err(|e| setup(what.clone())(e.to_string()))?;
        let context = Context::from_domain_participant(participant)
            .map_err(|e| setup(what.clone())(e.to_string()))?;
        let node_name = NodeName::new("/", &options.node_name).map_err(|e| Ros2Error::Name {
            kind: "node",
            name: options.node_name.clone(),
            reason: e.to_string(),
        })?;
        let mut node = context
            .new_node(
                node_name.clone(),
                NodeOptions::new()
                    .enable_rosout(false)
                    .start_parameter_services(false),
            )
            .map_err(|e| setup(format!("the node {:?}", options.node_name))(e.to_string()))?;
        let spinner = node
            .spinner()
            .map_err(|e| setup("the node's background task")(e.to_string()))?;
        // The spinner ends when the node is dropped.
        thread::Builder::new()
            .name("ros2-spin".into())
            .spawn(move || smol::block_on(spinner.spin()))
            .map_err(|e| setup("the node's background thread")(e.to_string()))?;
        Ok(Ros2Link {
            node: Arc::new(Mutex::new(node)),
            node_name,
            context,
            options,
        })
    }

    /// The ROS 2 topics other participants on the domain write or read, as discovery has heard
    /// them so far: `(name, type)` in ROS form (`/camera/image_raw`, `sensor_msgs/msg/Image`),
    /// sorted. Our own readers and writers are not counted: what an error about a topic nobody
    /// publishes, or an empty domain, lists.
    pub fn heard_topics(&self) -> Vec<(String, String)> {
        let participant = self.context.domain_participant();
        let writers = participant
            .discovered_writers()
            .into_iter()
            .filter(|w| self.foreign(&w.writer_proxy.remote_writer_guid))
            .map(|w| {
                let t = w.publication_topic_data;
                (t.topic_name, t.type_name)
            });
        let readers = participant
            .discovered_readers()
            .into_iter()
            .filter(|r| self.foreign(&r.reader_proxy.remote_reader_guid))
            .map(|r| {
                let t = r.subscription_topic_data;
                (t.topic_name().clone(), t.type_name().clone())
            });
        let mut topics: Vec<(String, String)> = writers
            .chain(readers)
            .filter_map(|(name, ty)| {
                // ROS 2 topics are `rt/<name>` in DDS, their types `pkg::msg::dds_::Type_`.
                let name = format!("/{}", name.strip_prefix("rt/")?);
                let ty = ty.replace("::dds_::", "::").replace("::", "/");
                Some((name, ty.trim_end_matches('_').to_string()))
            })
            .collect();
        topics.sort();
        topics.dedup();
        topics
    }

    /// The other DDS participants with a reader of the DDS topic `dds_topic` (`rq/…Request` for
    /// a service's or an action's server), as their GUID prefixes in hex, sorted: two servers of
    /// one name both take every request and both answer it.
    pub fn participants_reading(&self, dds_topic: &str) -> Vec<String> {
        let participant = self.context.domain_participant();
        let readers = participant
            .discovered_readers()
            .into_iter()
            .filter(|r| r.subscription_topic_data.topic_name() == dds_topic)
            .map(|r| r.reader_proxy.remote_reader_guid);
        self.others(readers)
    }

    /// Waits up to `timeout` until `matched` holds of the node (`serves` of each client it
    /// needs); whether it came to hold. Asked afresh every 10 ms: ros2-client's
    /// `wait_for_service` future looks at the matches only when a match event arrives, and one
    /// missed on a loaded machine waited out the whole timeout with the server there (CI). A
    /// client's first request waits `settle_after_match` more.
    pub fn wait_until_matched(&self, timeout: Duration, matched: impl Fn(&Node) -> bool) -> bool {
        poll_for(Instant::now() + timeout, || {
            Ok::<_, ()>(self.with_node(|node| matched(node)).then_some(()))
        })
        .is_some()
    }

    /// The participants of `endpoints` other than ours, as GUID prefixes in hex, sorted, each
    /// once.
    fn others(
        &self,
        endpoints: impl Iterator<Item = ros2_client::dds::rustdds::GUID>,
    ) -> Vec<String> {
        let mut others: Vec<String> = endpoints
            .filter(|guid| self.foreign(guid))
            .map(|guid| format!("{:?}", guid.prefix))
            .collect();
        others.sort();
        others.dedup();
        others
    }

    /// Whether an endpoint discovery heard is another participant's (not one of ours).
    fn foreign(&self, endpoint: &ros2_client::dds::rustdds::GUID) -> bool {
        use ros2_client::dds::rustdds::RTPSEntity;
        endpoint.prefix != self.context.domain_participant().guid().prefix
    }

    /// The options it was opened with.
    pub fn options(&self) -> &LinkOptions {
        &self.options
    }

    fn topic<M: RosType>(
        &self,
        node: &Node,
        name: &str,
        qos: &QosProfile,
    ) -> Result<ros2_client::dds::rustdds::Topic, Ros2Error> {
        let parsed = topic_name(name)?;
        node.create_topic(&parsed, MessageTypeName::new(M::PACKAGE, M::NAME), qos)
            .map_err(|e| setup(format!("the topic {name}"))(e.to_string()))
    }

    /// A reader of `name` (an absolute ROS name, `/tf`) with `qos`.
    pub fn subscribe<M: RosType + DeserializeOwned + 'static>(
        &self,
        name: &str,
        qos: QosProfile,
    ) -> Result<Subscription<M>, Ros2Error> {
        let mut node = self.node.lock().unwrap_or_else(|p| p.into_inner());
        let topic = self.topic::<M>(&node, name, &qos)?;
        node.create_subscription(&topic, Some(qos))
            .map_err(|e| setup(format!("a reader of {name}"))(e.to_string()))
    }

    /// A reader of `name` that holds at most the newest message: its topic is made here with a
    /// DDS resource limit of one sample and `qos` keeps the last one. RustDDS keeps up to 64
    /// messages of a topic made without a limit (whatever the reader's history depth), and
    /// keeps a topic's cache for the participant's life: with 100 MB camera frames that was
    /// 1.3 GB (issue #40). For a topic whose messages are only ever wanted newest-first (a
    /// camera's frames); no other reader of `name` may be made in this process, or its limit
    /// would raise the topic's.
    pub fn subscribe_newest<M: RosType + DeserializeOwned + 'static>(
        &self,
        name: &str,
        qos: QosProfile,
    ) -> Result<Subscription<M>, Ros2Error> {
        use ros2_client::dds::rustdds::{policy, QosPolicies, QosPolicyBuilder, TopicKind};
        let qos = qos.history(ros2_client::qos::History::KeepLast { depth: 1 });
        let one = policy::ResourceLimits {
            max_samples: 1,
            max_instances: 1,
            max_samples_per_instance: 1,
        };
        let dds_qos = QosPolicies::from(&qos)
            .modify_by(&QosPolicyBuilder::new().resource_limits(one).build());
        let parsed = topic_name(name)?;
        let mut node = self.node.lock().unwrap_or_else(|p| p.into_inner());
        let topic = self
            .context
            .domain_participant()
            .create_topic(
                parsed.to_dds_name("rt", &self.node_name, ""),
                MessageTypeName::new(M::PACKAGE, M::NAME).dds_msg_type(),
                &dds_qos,
                TopicKind::NoKey,
            )
            .map_err(|e| setup(format!("the topic {name}"))(e.to_string()))?;
        node.create_subscription(&topic, Some(qos))
            .map_err(|e| setup(format!("a reader of {name}"))(e.to_string()))
    }

    /// A writer of `name` with `qos`.
    pub fn publisher<M: RosType + Serialize>(
        &self,
        name: &str,
        qos: QosProfile,
    ) -> Result<Publisher<M>, Ros2Error> {
        let mut node = self.node.lock().unwrap_or_else(|p| p.into_inner());
        let topic = self.topic::<M>(&node, name, &qos)?;
        node.create_publisher(&topic, Some(qos))
            .map_err(|e| setup(format!("a writer of {name}"))(e.to_string()))
    }

    /// Runs `f` with the node (to make action clients and the like).
    pub fn with_node<T>(&self, f: impl FnOnce(&mut Node) -> T) -> T {
        let mut node = self.node.lock().unwrap_or_else(|p| p.into_inner());
        f(&mut node)
    }
}

/// Parses an absolute ROS 2 topic or action name (`/tf`, `/camera/image_raw`).
pub fn topic_name(name: &str) -> Result<Name, Ros2Error> {
    let bad = |reason: String| Ros2Error::Name {
        kind: "topic",
        name: name.to_string(),
        reason,
    };
    let Some(rest) = name.strip_prefix('/') else {
        return Err(bad("it must be absolute (start with /)".into()));
    };
    let (namespace, base) = match rest.rsplit_once('/') {
        Some((ns, base)) => (format!("/{ns}"), base),
        None => ("/".to_string(), rest),
    };
    Name::new(&namespace, base).map_err(|e| bad(e.to_string()))
}

/// QoS of sensor streams (`rclcpp::SensorDataQoS`: best effort, keep last 5), which a reader
/// must match for images from camera drivers; best effort readers also take reliable writers.
pub fn sensor_data_qos() -> QosProfile {
    QosProfile::subscription_default()
        .reliability(ros2_client::qos::Reliability::BestEffort)
        .history(ros2_client::qos::History::KeepLast { depth: 5 })
}

/// QoS of a `/tf` reader: tf2's listener depth (`DynamicListenerQoS`, keep last 100), best
/// effort so that every publisher matches. /tf carries every node's frames at a few hundred
/// messages a second: a shallow queue, read by a thread a loaded machine starves for a moment,
/// keeps only the newest few and loses a slower publisher's edges for that moment (CI saw a
/// driver's base → tool0 drop out for over a second beside a 200 Hz second publisher).
pub fn tf_listener_qos() -> QosProfile {
    QosProfile::subscription_default()
        .reliability(ros2_client::qos::Reliability::BestEffort)
        .history(ros2_client::qos::History::KeepLast { depth: 100 })
}

/// Reliable, volatile, keep last 10: action and service traffic.
pub fn reliable_qos() -> QosProfile {
    QosProfile::publisher_default()
        .reliability(ros2_client::qos::Reliability::Reliable {
            when_full: ros2_client::qos::WhenFull::DEFAULT,
        })
        .history(ros2_client::qos::History::KeepLast { depth: 10 })
}

/// QoS of `/tf_static` (tf2's `StaticBroadcasterQoS`: reliable, transient local, keep last 1):
/// a late joiner still gets the last message.
pub fn static_qos() -> QosProfile {
    QosProfile::publisher_default()
        .reliability(ros2_client::qos::Reliability::Reliable {
            when_full: ros2_client::qos::WhenFull::DEFAULT,
        })
        .durability(ros2_client::qos::Durability::TransientLocal)
        .history(ros2_client::qos::History::KeepLast { depth: 1 })
}

/// A reader of latched transforms: [`static_qos`] keeping 100 messages, as tf2's `/tf_static`
/// listener does (each writer's latched message counts; with one kept, a second node's message
/// arriving in the same instant would hide the first's).
pub fn static_reader_qos() -> QosProfile {
    static_qos().history(ros2_client::qos::History::KeepLast { depth: 100 })
}

/// Whether `client`'s server is on the graph: its request writer matched to a server's reader
/// and its reply reader to a server's writer (looked at now, not awaited).
pub(crate) fn serves<Req, Resp>(client: &ros2_client::Client<Req, Resp>, node: &Node) -> bool
where
    Req: ros2_client::Message + 'static,
    Resp: ros2_client::Message + 'static,
{
    client.wait_for_service(node).now_or_never().is_some()
}

/// How long a new client's first request waits after our side matched its server.
const MATCH_SETTLE: Duration = Duration::from_secs(1);

/// Waits [`MATCH_SETTLE`]: before a new client's first request, once our side has matched its
/// server ([`Ros2Link::wait_until_matched`]), the server must have matched our writer too.
/// Cyclone DDS drops a sample from a writer it has not matched yet, and once matched it takes
/// what the writer's first heartbeat announces as history a volatile reader is not owed: a goal
/// or a controller switch written in between is lost for good (seen in CI, the peer never heard
/// it). Each side learns of the other's endpoints in the same discovery exchange, so the
/// server's match follows ours by the time it takes to process it.
pub(crate) fn settle_after_match() {
    thread::sleep(MATCH_SETTLE);
}

/// How often [`poll_for`] looks.
pub(crate) const POLL: Duration = Duration::from_millis(10);

/// `read`'s first `Some` (or error), looked for every [`POLL`] until `deadline`; `None` after.
/// Replies are polled, not awaited: ros2-client's reply futures wake on DDS notifications, and
/// one missed on a loaded machine left a goal "unanswered" for the whole timeout (seen in CI).
pub(crate) fn poll_for<T, E>(
    deadline: Instant,
    mut read: impl FnMut() -> Result<Option<T>, E>,
) -> Option<Result<T, E>> {
    loop {
        match read() {
            Ok(Some(v)) => return Some(Ok(v)),
            Err(e) => return Some(Err(e)),
            Ok(None) if Instant::now() >= deadline => return None,
            Ok(None) => thread::sleep(POLL),
        }
    }
}

/// The answer `client` has in to one of the requests `sent`, with that request's place in
/// `sent` (answers to other requests, an earlier call's, are read past); `Ok(None)` when none
/// is in yet.
pub(crate) fn answer_to<Req, Resp>(
    client: &ros2_client::Client<Req, Resp>,
    sent: &[ros2_client::RmwRequestId],
) -> Result<Option<(usize, Resp)>, String>
where
    Req: ros2_client::Message + 'static,
    Resp: ros2_client::Message + 'static,
{
    loop {
        match client.receive_response() {
            Ok(Some((answered, response))) => {
                if let Some(k) = sent.iter().position(|id| *id == answered) {
                    return Ok(Some((k, response)));
                }
            }
            Ok(None) => return Ok(None),
            Err(e) => return Err(format!("{e:?}")),
        }
    }
}

/// How long [`call`] waits for an answer before it sends its request again.
pub(crate) const REQUEST_RESEND: Duration = Duration::from_secs(5);

/// A service's answer and whether it answered a repeat of the request (the first sending went
/// unanswered: it may have been lost, or only its answer).
pub(crate) struct Answer<Resp> {
    pub response: Result<Resp, String>,
    pub to_a_repeat: bool,
}

/// `request` to `client`'s server and its answer, polled for up to `timeout` ([`poll_for`]);
/// `None` without an answer. Unanswered for [`REQUEST_RESEND`], the request is sent again (and
/// so on until `timeout`): a request sent before the server's reader has taken in our writer is
/// dropped for good by Cyclone DDS, however long the client waits (seen in CI as a freedrive
/// switch unanswered for 30 s). The first answer to any of the sendings is the answer. Only
/// for requests whose repeat is harmless: a server that did the first may refuse the repeat,
/// which the caller then says.
pub(crate) fn call<Req, Resp>(
    client: &ros2_client::Client<Req, Resp>,
    request: Req,
    timeout: Duration,
) -> Option<Answer<Resp>>
where
    Req: ros2_client::Message + Clone + 'static,
    Resp: ros2_client::Message + 'static,
{
    let deadline = Instant::now() + timeout;
    let mut sent = Vec::new();
    loop {
        match client.send_request(request.clone()) {
            Ok(id) => sent.push(id),
            Err(e) => {
                return Some(Answer {
                    response: Err(format!("{e:?}")),
                    to_a_repeat: !sent.is_empty(),
                })
            }
        }
        let resend_at = (Instant::now() + REQUEST_RESEND).min(deadline);
        let answer = poll_for(resend_at, || answer_to(client, &sent));
        match answer {
            Some(Ok((k, response))) => {
                return Some(Answer {
                    response: Ok(response),
                    to_a_repeat: k > 0,
                })
            }
            Some(Err(e)) => {
                return Some(Answer {
                    response: Err(e),
                    to_a_repeat: sent.len() > 1,
                })
            }
            None if Instant::now() >= deadline => return None,
            None => {}
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn topic_names_are_checked() {
        assert!(topic_name("/tf").is_ok());
        assert!(topic_name("/camera/image_raw").is_ok());
        let e = topic_name("tf").unwrap_err().to_string();
        assert!(e.contains("absolute"), "{e}");
        assert!(topic_name("/9bad").is_err());
    }
}
