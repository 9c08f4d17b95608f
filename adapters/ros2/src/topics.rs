//! Topic names of a robot: ROS conventions by default, each renamable from the mission.

use std::collections::BTreeMap;

use crate::mission_section::Ros2Spec;

/// Default topic of each role, relative to the robot's namespace (an absolute name stays as
/// it is), with its type: [`spomp_ros_msgs::ROBOT_TOPICS`], the table the recorder shares. The
/// roles are the keys a mission's `ros2.topics` may rename.
pub use spomp_ros_msgs::ROBOT_TOPICS;

/// Node transitions and problems.
pub const ROSOUT_TOPIC: &str = "/rosout";
/// Simulated time.
pub const CLOCK_TOPIC: &str = "/clock";
/// Mission status of every robot (JSON in `std_msgs/String`): goals, claims and visits as the
/// robot knows them — what an operator's console or the simulator farm reads.
pub const STATUS_SUFFIX: &str = "team/status";

/// The resolved topic names of one robot.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct TopicNames {
    namespace: String,
    names: BTreeMap<&'static str, String>,
}

impl TopicNames {
    /// Names for robot `id` from its `ros2:` settings (namespace default `/<id>`).
    pub fn resolve(id: &str, spec: Option<&Ros2Spec>) -> Self {
        let namespace = match spec.and_then(|s| s.namespace.as_deref()) {
            Some(ns) if !ns.is_empty() && ns != "/" => format!("/{}", ns.trim_matches('/')),
            Some(_) => String::new(),
            None => format!("/{id}"),
        };
        let mut names = BTreeMap::new();
        for t in ROBOT_TOPICS {
            let chosen = spec.and_then(|s| s.topics.get(t.role)).map_or(t.name, String::as_str);
            names.insert(t.role, qualify(&namespace, chosen));
        }
        TopicNames { namespace, names }
    }

    /// Whether the robot's tf topics are its own (under its namespace or renamed) rather than
    /// the global `/tf` every robot shares.
    pub fn tf_is_global(&self) -> bool {
        self.get("tf") == "/tf"
    }

    /// The namespace (`/ugv1`; empty for the root).
    pub fn namespace(&self) -> &str {
        &self.namespace
    }

    /// Full name of a role's topic.
    ///
    /// # Panics
    /// Never for the roles of [`ROBOT_TOPICS`]; a role outside them is a programming error.
    pub fn get(&self, role: &str) -> &str {
        self.names.get(role).map_or("/invalid_topic_role", String::as_str)
    }

    /// The mission-status topic.
    pub fn status(&self) -> String {
        qualify(&self.namespace, STATUS_SUFFIX)
    }

    /// Every (role, full name), for docs and `spomp run --topics`.
    pub fn iter(&self) -> impl Iterator<Item = (&'static str, &str)> {
        self.names.iter().map(|(k, v)| (*k, v.as_str()))
    }
}

fn qualify(namespace: &str, name: &str) -> String {
    if name.starts_with('/') { name.to_string() } else { format!("{namespace}/{name}") }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn spec(yaml: &str) -> Ros2Spec {
        serde_saphyr::from_str(yaml).expect("valid ros2 spec")
    }

    #[test]
    fn the_mission_language_accepts_exactly_these_roles() {
        let ours: Vec<&str> = ROBOT_TOPICS.iter().map(|t| t.role).collect();
        assert_eq!(ours, crate::mission_section::ROS2_TOPIC_ROLES);
    }

    #[test]
    fn defaults_are_under_the_robot_id() {
        let t = TopicNames::resolve("ugv1", None);
        assert_eq!(t.get("odom"), "/ugv1/odom");
        assert_eq!(t.get("cmd_vel"), "/ugv1/cmd_vel");
        assert_eq!(t.get("diagnostics"), "/diagnostics");
        assert_eq!(t.status(), "/ugv1/team/status");
        assert_eq!((t.get("tf"), t.get("tf_static")), ("/tf", "/tf_static"));
        assert!(t.tf_is_global());
    }

    #[test]
    fn namespace_and_renames_apply() {
        let s = spec("namespace: husky\ntopics:\n  odom: /odometry/filtered\n  cmd_vel: base/cmd_vel\n");
        let t = TopicNames::resolve("ugv1", Some(&s));
        assert_eq!(t.get("odom"), "/odometry/filtered");
        assert_eq!(t.get("cmd_vel"), "/husky/base/cmd_vel");
        assert_eq!(t.get("path"), "/husky/path");
        let nav2 = spec("namespace: robot1\ntopics: { tf: tf, tf_static: tf_static }\n");
        let t = TopicNames::resolve("ugv1", Some(&nav2));
        assert_eq!((t.get("tf"), t.get("tf_static")), ("/robot1/tf", "/robot1/tf_static"));
        assert!(!t.tf_is_global());
        let root = spec("namespace: /\n");
        assert_eq!(TopicNames::resolve("ugv1", Some(&root)).get("odom"), "/odom");
    }
}
