//! Checks of a log's conventions shared by the tests that record one: one type per topic name
//! (the topic table DDS uses) and a tf tree in which every frame a message names reaches `map`.

use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;

use spomp_mcap::{LogMessage, McapLog, decode_cdr};
use spomp_ros_msgs as ros;

/// The messages of the log at `path`.
pub fn read(path: &Path) -> Vec<LogMessage> {
    let bytes = std::fs::read(path).expect("the log is readable");
    McapLog::from_bytes(bytes).messages().expect("the log decodes")
}

/// Every channel of robot `robot` named as a topic of the table has the table's type
/// (`cmd_vel`: `cmd_vel_type`); the robot's topics the log must hold are in `expected`.
pub fn assert_topic_types(messages: &[LogMessage], robot: &str, expected: &[&str]) {
    let mut seen: BTreeMap<&str, &str> = BTreeMap::new();
    for m in messages {
        seen.insert(m.topic.as_str(), m.schema.as_str());
    }
    for t in ros::ROBOT_TOPICS {
        let name = if t.name.starts_with('/') { t.name.to_string() } else { format!("/{robot}/{}", t.name) };
        if let Some(ty) = seen.get(name.as_str()) {
            assert_eq!(*ty, t.type_name, "{name} ({}) in the log is {ty}, on DDS {}", t.role, t.type_name);
        }
    }
    for role in expected {
        let t = ros::robot_topic(role).expect("a role of the table");
        let name = if t.name.starts_with('/') { t.name.to_string() } else { format!("/{robot}/{}", t.name) };
        assert!(seen.contains_key(name.as_str()), "{name} not in the log: {:?}", seen.keys());
    }
}

/// The frames of the log's tf tree (`/tf`, `/tf_static`) each frame's parent, and the frames
/// every message of `robot` names; each named frame must reach `map`, and no frame may have
/// two parents.
pub fn assert_tf_tree_connects(messages: &[LogMessage], robot: &str) -> BTreeSet<String> {
    let mut parent: BTreeMap<String, String> = BTreeMap::new();
    let mut named: BTreeSet<String> = BTreeSet::new();
    for m in messages {
        match m.topic.as_str() {
            "/tf" | "/tf_static" => {
                let tf: ros::TfMessage = decode_cdr(&m.topic, &m.data).expect("a TFMessage");
                for t in tf.transforms {
                    let old = parent.insert(t.child_frame_id.clone(), t.header.frame_id.clone());
                    assert!(
                        old.is_none_or(|p| p == t.header.frame_id),
                        "{} has two parents on {}: {:?} and {}",
                        t.child_frame_id,
                        m.topic,
                        parent.get(&t.child_frame_id),
                        t.header.frame_id
                    );
                }
            }
            t if t == format!("/{robot}/odom") => {
                let o: ros::Odometry = decode_cdr(t, &m.data).expect("odometry");
                named.insert(o.header.frame_id);
                named.insert(o.child_frame_id);
            }
            t if t == format!("/{robot}/panorama/depth") => {
                let i: ros::Image = decode_cdr(t, &m.data).expect("an image");
                named.insert(i.header.frame_id);
            }
            t if t == format!("/{robot}/reachability") => {
                let s: ros::LaserScan = decode_cdr(t, &m.data).expect("a scan");
                // REP-117: every bin a valid reading (range_min ≤ r < range_max).
                assert!(s.ranges.iter().all(|r| *r >= s.range_min && *r < s.range_max), "{s:?}");
                assert_eq!(s.range_max, spomp_core::scan::REACHABILITY_RANGE_MAX_M);
                named.insert(s.header.frame_id);
            }
            _ => {}
        }
    }
    assert!(!named.is_empty(), "no message of {robot} names a frame");
    for frame in &named {
        let mut at = frame.clone();
        let mut hops = 0;
        while at != "map" {
            at = parent
                .get(&at)
                .unwrap_or_else(|| panic!("{frame} does not reach map (stops at {at}): {parent:?}"))
                .clone();
            hops += 1;
            assert!(hops < 16, "a tf loop from {frame}: {parent:?}");
        }
    }
    named
}
