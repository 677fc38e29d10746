//! DDS plumbing shared by the node, the stand-in cell and the controller
//! client: DDS failures as errors, QoS profiles, and topics, readers and
//! writers by their ROS names (resolved in the node's namespace; errors
//! name the setting).

use super::config::Reliability;
use super::names::resolved_topic;
use crate::{Error, Result};
use ros2_client::qos::{History, WhenFull};
use ros2_client::{MessageTypeName, Node, Publisher, QosProfile, Subscription};
use serde::de::DeserializeOwned;

/// A DDS failure as an error.
pub fn dds(what: &str, e: impl std::fmt::Debug) -> Error {
    Error::Numerical(format!("ROS 2 {what}: {e:?}"))
}

/// A profile of `reliability` with history depth `depth`.
pub fn qos(reliability: Reliability, depth: usize) -> QosProfile {
    let base = QosProfile::subscription_default().history(History::KeepLast { depth });
    match reliability {
        Reliability::BestEffort => base.reliability_best_effort(),
        Reliability::Reliable => base.reliability_reliable(WhenFull::DEFAULT),
    }
}

/// The topic `topic` (the setting `setting`) of type `ty` with `qos`.
pub fn topic(
    node: &Node,
    topic: &str,
    setting: &str,
    ty: (&str, &str),
    qos: &QosProfile,
) -> Result<ros2_client::dds::rustdds::Topic> {
    let namespace = node.namespace().to_string();
    node.create_topic(
        &resolved_topic(&namespace, topic, setting)?,
        MessageTypeName::new(ty.0, ty.1),
        qos,
    )
    .map_err(|e| dds(&format!("topic {topic}"), e))
}

/// A reader of the topic `name` (the setting `setting`).
pub fn subscribe<M: 'static + DeserializeOwned>(
    node: &mut Node,
    name: &str,
    setting: &str,
    ty: (&str, &str),
    qos: &QosProfile,
) -> Result<Subscription<M>> {
    let t = topic(node, name, setting, ty, qos)?;
    node.create_subscription::<M>(&t, None)
        .map_err(|e| dds(&format!("subscription {name}"), e))
}

/// A writer of the topic `name` (the setting `setting`).
pub fn advertise<M: serde::Serialize>(
    node: &mut Node,
    name: &str,
    setting: &str,
    ty: (&str, &str),
    qos: &QosProfile,
) -> Result<Publisher<M>> {
    let t = topic(node, name, setting, ty, qos)?;
    node.create_publisher::<M>(&t, None)
        .map_err(|e| dds(&format!("publisher {name}"), e))
}
