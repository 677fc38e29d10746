//! ROS names (`/ns/topic`, `relative/topic`, node names) checked into
//! `ros2-client`'s types, errors naming the setting.

use crate::{Error, Result};
use ros2_client::{Name, NodeName};

/// A topic or action name as the node resolves it: an absolute one as it
/// is, a relative one inside `namespace` (ROS's rule; resolved here so the
/// DDS name is `rt/ns/topic` also for the root namespace).
pub fn resolved_topic(namespace: &str, text: &str, field: &str) -> Result<Name> {
    let ns = namespace.trim_matches('/');
    let full = match (text.starts_with('/'), ns.is_empty()) {
        (true, _) => text.to_string(),
        (false, true) => format!("/{text}"),
        (false, false) => format!("/{ns}/{text}"),
    };
    topic_name(&full, field)
}

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

#[cfg(test)]
mod tests {
    use super::*;
    use ros2_client::NodeName;

    #[test]
    fn relative_names_resolve_in_the_namespace() {
        let node = NodeName::new("/", "dpmp").unwrap();
        let dds = |ns: &str, t: &str| {
            resolved_topic(ns, t, "t")
                .unwrap()
                .to_dds_name("rt", &node, "")
        };
        assert_eq!(
            dds("", "camera/color/image_raw"),
            "rt/camera/color/image_raw"
        );
        assert_eq!(dds("/", "joint_states"), "rt/joint_states");
        assert_eq!(dds("picker", "dpmp/target"), "rt/picker/dpmp/target");
        assert_eq!(
            dds("/cell/picker", "dpmp/target"),
            "rt/cell/picker/dpmp/target"
        );
        assert_eq!(dds("picker", "/joint_states"), "rt/joint_states");
        assert!(resolved_topic("", "bad topic", "t").is_err());
    }
}
