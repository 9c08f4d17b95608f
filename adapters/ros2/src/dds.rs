//! A ROS 2 node over RustDDS: participant set-up (domain, interfaces), typed publishers and
//! subscriptions for the message types of [`spomp_ros_msgs`].

use std::net::IpAddr;

use ros2_client::dds::rustdds::DomainParticipantBuilder;
use ros2_client::qos::{Durability, History, QosProfile};
use ros2_client::{Context, MessageTypeName, Name, NodeName, NodeOptions, Publisher, Subscription};
use serde::de::DeserializeOwned;
use spomp_ros_msgs::RosMessage;

/// Why the ROS 2 side could not be set up or used.
#[derive(Debug, thiserror::Error)]
pub enum DdsError {
    /// The DDS participant or an entity could not be created.
    #[error("DDS: {0}")]
    Create(String),
    /// A topic or node name ROS 2 does not accept.
    #[error("`{name}` is not a valid ROS 2 name: {reason}")]
    Name {
        /// The name.
        name: String,
        /// Why.
        reason: String,
    },
}

/// Where DDS may talk.
///
/// `interfaces` restricts what is sent and advertised, not what is received: RustDDS (0.15, under
/// ros2-client 0.12) binds its four receive sockets — discovery and user traffic, unicast and
/// multicast — to `0.0.0.0` with no option to choose an address, and filters only the multicast
/// group joins and the locators it advertises. A peer that is told nothing of this robot cannot
/// find it through another interface, but a datagram sent there to its port still arrives.
/// [`RECEIVE_ON_ALL_INTERFACES`] is the notice `spomp run` and `spomp sim --ros2` print; the
/// remedy (a host firewall rule or a network namespace) is in `docs/robots.md`.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct DdsSettings {
    /// DDS domain id.
    pub domain_id: u16,
    /// Only these local addresses carry multicast discovery and are advertised; empty = all.
    pub interfaces: Vec<IpAddr>,
}

/// What a user restricting DDS to some interfaces must know (see [`DdsSettings`]).
pub const RECEIVE_ON_ALL_INTERFACES: &str = "DDS advertises and sends on the chosen interfaces only, but its receive \
     sockets listen on every interface (RustDDS binds 0.0.0.0); to refuse DDS traffic elsewhere, \
     firewall UDP ports 7400+250·domain … +249 on the other interfaces or run in a network namespace \
     (docs/robots.md, \"DDS interfaces\")";

impl DdsSettings {
    /// The ports of this domain's RTPS traffic (RTPS 2.5 §9.6.2.3: port base 7400, 250 per
    /// domain; discovery and user traffic of up to 120 participants), for a firewall rule.
    pub fn rtps_ports(&self) -> std::ops::RangeInclusive<u32> {
        let base = 7400 + 250 * u32::from(self.domain_id);
        base..=base + 249
    }
}

impl DdsSettings {
    /// A robot's `ros2:` domain and interfaces, then the ROS 2 environment
    /// ([`DdsSettings::with_ros_environment`]).
    pub fn for_robot(spec: &crate::mission_section::Ros2Spec) -> Result<Self, String> {
        let interfaces = spec
            .interfaces
            .iter()
            .map(|a| a.parse::<IpAddr>().map_err(|_| format!("ros2.interfaces: `{a}` is not an IP address")))
            .collect::<Result<Vec<_>, _>>()?;
        DdsSettings { domain_id: spec.domain_id, interfaces }.with_ros_environment()
    }

    /// Applies the ROS 2 environment a launch file or shell sets: `ROS_DOMAIN_ID`, and
    /// `ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST` / `ROS_LOCALHOST_ONLY=1` (loopback only).
    pub fn with_ros_environment(mut self) -> Result<Self, String> {
        if let Ok(v) = std::env::var("ROS_DOMAIN_ID")
            && !v.trim().is_empty()
        {
            self.domain_id = v
                .trim()
                .parse::<u16>()
                .ok()
                .filter(|d| *d <= 232)
                .ok_or_else(|| format!("ROS_DOMAIN_ID={v}: expected a domain id 0..232"))?;
        }
        let localhost = std::env::var("ROS_AUTOMATIC_DISCOVERY_RANGE")
            .is_ok_and(|v| v.eq_ignore_ascii_case("localhost"))
            || std::env::var("ROS_LOCALHOST_ONLY").is_ok_and(|v| v.trim() == "1");
        if localhost {
            self.interfaces = vec![IpAddr::from([127, 0, 0, 1])];
        }
        Ok(self)
    }
}

/// One ROS 2 node of a process.
pub struct DdsNode {
    // The context must outlive the node's entities; both are kept here.
    _context: Context,
    node: ros2_client::Node,
    /// Every topic an entity was created on, with its type (`package/msg/Type`).
    topics: Vec<(String, &'static str)>,
}

impl DdsNode {
    /// A participant in `settings.domain_id` restricted to `settings.interfaces`, and a node
    /// `name` in namespace `namespace` (empty or `/`: the root).
    pub fn new(settings: &DdsSettings, namespace: &str, name: &str) -> Result<Self, DdsError> {
        let mut builder = DomainParticipantBuilder::new(settings.domain_id);
        if !settings.interfaces.is_empty() {
            builder = builder.with_only_networks(settings.interfaces.iter().copied());
        }
        let participant = builder.build().map_err(|e| DdsError::Create(format!("participant: {e:?}")))?;
        let context = Context::from_domain_participant(participant).map_err(|e| DdsError::Create(format!("{e:?}")))?;
        let ns = if namespace.is_empty() { "/" } else { namespace };
        // rosout off: ros2-client's own `/rosout` writer would be a second writer of the topic
        // beside the node's (`rosout_qos`), with another QoS.
        let node_name = NodeName::new(ns, name)
            .map_err(|e| DdsError::Name { name: format!("{ns}/{name}"), reason: format!("{e:?}") })?;
        let node = context
            .new_node(node_name, NodeOptions::new().enable_rosout(false).start_parameter_services(false))
            .map_err(|e| DdsError::Create(format!("node: {e:?}")))?;
        Ok(DdsNode { _context: context, node, topics: Vec::new() })
    }

    /// Every topic a publisher or subscription was created on, with its message type, in order.
    pub fn topics(&self) -> &[(String, &'static str)] {
        &self.topics
    }

    /// A publisher of `M` on the absolute topic `topic`.
    pub fn publisher<M: RosMessage>(&mut self, topic: &str, qos: &QosProfile) -> Result<Publisher<M>, DdsError> {
        let t = self.topic::<M>(topic, qos)?;
        self.node.create_publisher(&t, None).map_err(|e| DdsError::Create(format!("publisher {topic}: {e:?}")))
    }

    /// A subscription to `M` on the absolute topic `topic`.
    pub fn subscription<M: RosMessage + DeserializeOwned + 'static>(
        &mut self,
        topic: &str,
        qos: &QosProfile,
    ) -> Result<Subscription<M>, DdsError> {
        let t = self.topic::<M>(topic, qos)?;
        self.node.create_subscription(&t, None).map_err(|e| DdsError::Create(format!("subscription {topic}: {e:?}")))
    }

    fn topic<M: RosMessage>(
        &mut self,
        topic: &str,
        qos: &QosProfile,
    ) -> Result<ros2_client::dds::rustdds::Topic, DdsError> {
        let name = topic_name(topic)?;
        self.topics.push((topic.to_string(), M::TYPE_NAME));
        self.node
            .create_topic(&name, message_type::<M>(), qos)
            .map_err(|e| DdsError::Create(format!("topic {topic}: {e:?}")))
    }
}

/// `pkg/msg/Type` → the ROS 2 type name.
fn message_type<M: RosMessage>() -> MessageTypeName {
    let mut parts = M::TYPE_NAME.split('/');
    let package = parts.next().unwrap_or_default();
    let type_name = parts.next_back().unwrap_or_default();
    MessageTypeName::new(package, type_name)
}

/// An absolute topic name split into namespace and base name, as ros2-client takes it.
fn topic_name(topic: &str) -> Result<Name, DdsError> {
    let bad = |reason: &str| DdsError::Name { name: topic.into(), reason: reason.into() };
    if !topic.starts_with('/') {
        return Err(bad("expected an absolute name"));
    }
    let (ns, base) = topic.rsplit_once('/').ok_or_else(|| bad("no base name"))?;
    let ns = if ns.is_empty() { "/" } else { ns };
    Name::new(ns, base).map_err(|e| bad(&format!("{e:?}")))
}

/// Sensor streams: best effort, newest only — matches any publisher, never backs up.
pub fn sensor_qos(depth: usize) -> QosProfile {
    QosProfile::subscription_default().history(History::KeepLast { depth })
}

/// Commands and state the robot publishes: reliable, newest only.
pub fn state_qos(depth: usize) -> QosProfile {
    QosProfile::publisher_default().history(History::KeepLast { depth })
}

/// rcl's `/rosout` profile (`rcl_qos_profile_rosout_default`): reliable, transient local, keep
/// last 1000 — so a reader with rcl's profile matches, and one that joins late still gets the
/// last 1000 entries. rcl also sets a 10 s lifespan; it is left out (the transitions are the
/// mission's record, worth having for a viewer that connects later; lifespan does not enter
/// QoS matching).
pub fn rosout_qos() -> QosProfile {
    latched_qos(1000)
}

/// Reliable and latched: a late subscriber gets the last `depth` samples (`/tf`-like state).
pub fn latched_qos(depth: usize) -> QosProfile {
    QosProfile::publisher_default().history(History::KeepLast { depth }).durability(Durability::TransientLocal)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn message_types_split_into_package_and_type() {
        let t = message_type::<spomp_ros_msgs::Odometry>();
        assert_eq!((t.package_name(), t.type_name()), ("nav_msgs", "Odometry"));
    }

    #[test]
    fn topic_names_must_be_absolute() {
        assert!(topic_name("/ugv1/panorama/depth").is_ok());
        assert!(topic_name("/cmd_vel").is_ok());
        assert!(topic_name("cmd_vel").is_err());
    }
}
