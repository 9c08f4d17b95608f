//! The ROS 2 node itself: a RustDDS participant, its node and typed entities, and the QoS
//! profiles the robot and the farm use.

use ros2_client::dds::rustdds::DomainParticipantBuilder;
use ros2_client::qos::{Durability, History, QosProfile};
use ros2_client::{Context, MessageTypeName, Name, NodeName, NodeOptions, Publisher, Subscription};
use serde::de::DeserializeOwned;
use spomp_ros_msgs::RosMessage;

use super::{DdsError, DdsSettings};

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
