//! ROS names (`/ns/topic`, `relative/topic`, node names) checked into
//! `ros2-client`'s types, errors naming the setting.

use crate::{Error, Result};
use ros2_client::{Name, NodeName};

/// A topic or action name.
pub fn topic_name(text: &str, field: &str) -> Result<Name> {
    Name::parse(text).map_err(|e| {
        Error::invalid(
            field,
            format!("{text:?} is not a ROS name ({e:?}): letters, digits, _ and /"),
        )
    })
}

/// A node's name in its namespace (`""` or `/`: the root).
pub fn node_name(namespace: &str, name: &str) -> Result<NodeName> {
    let namespace = match namespace {
        "" => "/".to_string(),
        ns if ns.starts_with('/') => ns.to_string(),
        ns => format!("/{ns}"),
    };
    NodeName::new(&namespace, name).map_err(|e| {
        Error::invalid(
            "node_name",
            format!("{namespace:?} / {name:?} is not a ROS node name ({e:?})"),
        )
    })
}
