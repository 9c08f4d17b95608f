//! A robot's frame ids (REP-105) from its `ros2:` settings, and the check of the frame ids its
//! inputs name.
//!
//! Defaults: `map`, `<prefix>odom`, `<prefix>base_link`, `<prefix>lidar`. The prefix follows the
//! namespace while the robot shares the global `/tf` (`/ugv1` → `ugv1/`, `husky` → `husky/`),
//! so robots in one tree do not collide; it is empty when the robot's tf topics are its own
//! (Nav2's multi-robot bringup: namespaced `tf`/`tf_static`, plain `odom`/`base_link`) or the
//! namespace is the root (a single robot as Nav2 and ros2_control expect it). `frame_prefix`
//! and `frames.*` replace the rule.

use std::collections::BTreeMap;

use crate::mission_section::Ros2Spec;
use spomp_ros_msgs::RobotFrames;

use crate::topics::TopicNames;

/// The frame ids of robot `id` with `spec`, whose topics are `topics`.
pub fn resolve(spec: Option<&Ros2Spec>, topics: &TopicNames) -> RobotFrames {
    let prefix = match spec.and_then(|s| s.frame_prefix.as_deref()) {
        Some("") => String::new(),
        Some(p) => format!("{}/", p.trim_end_matches('/')),
        None if topics.tf_is_global() && !topics.namespace().is_empty() => {
            format!("{}/", topics.namespace().trim_start_matches('/'))
        }
        None => String::new(),
    };
    let mut frames = RobotFrames::with_prefix(&prefix);
    if let Some(given) = spec.map(|s| &s.frames) {
        for (slot, value) in [
            (&mut frames.map, &given.map),
            (&mut frames.odom, &given.odom),
            (&mut frames.base_link, &given.base_link),
            (&mut frames.sensor, &given.sensor),
        ] {
            if let Some(v) = value {
                slot.clone_from(v);
            }
        }
    }
    frames
}

/// Two resolved frames with the same id (a prefix rule and an explicit id can meet), which
/// would fold the tree onto itself: `(field, field, id)`.
pub fn collision(frames: &RobotFrames) -> Option<(&'static str, &'static str, String)> {
    let all: [(&'static str, &String); 4] =
        [("map", &frames.map), ("odom", &frames.odom), ("base_link", &frames.base_link), ("sensor", &frames.sensor)];
    for i in 0..all.len() {
        for j in i + 1..all.len() {
            if all[i].1 == all[j].1 {
                return Some((all[i].0, all[j].0, all[i].1.clone()));
            }
        }
    }
    None
}

/// Which configured frame an input names, as the check reports it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub enum FrameField {
    /// `frames.map`.
    Map,
    /// `frames.odom`.
    Odom,
    /// `frames.base_link`.
    BaseLink,
    /// `frames.sensor`.
    Sensor,
}

impl FrameField {
    /// The setting's name under `ros2.frames`.
    pub fn name(self) -> &'static str {
        match self {
            FrameField::Map => "map",
            FrameField::Odom => "odom",
            FrameField::BaseLink => "base_link",
            FrameField::Sensor => "sensor",
        }
    }

    fn of(self, frames: &RobotFrames) -> &str {
        match self {
            FrameField::Map => &frames.map,
            FrameField::Odom => &frames.odom,
            FrameField::BaseLink => &frames.base_link,
            FrameField::Sensor => &frames.sensor,
        }
    }
}

/// Checks the frame ids inputs name against the configured ones. Each (topic, field, found)
/// mismatch is reported once, as a message naming the topic, the field of the message, the
/// frame found, the frame expected and the setting that sets it; the tf tree an integrator
/// builds from such inputs would not connect, so it must not pass in silence.
#[derive(Debug, Clone)]
pub struct FrameCheck {
    frames: RobotFrames,
    /// Where the robot's settings are, for the message (`team[1] (ugv1) ros2`).
    setting: String,
    reported: BTreeMap<(String, &'static str), String>,
}

impl FrameCheck {
    /// A check against `frames`; `setting` names the robot's `ros2:` section.
    pub fn new(frames: RobotFrames, setting: impl Into<String>) -> Self {
        FrameCheck { frames, setting: setting.into(), reported: BTreeMap::new() }
    }

    /// The frames checked against.
    pub fn frames(&self) -> &RobotFrames {
        &self.frames
    }

    /// Checks that `field_name` of a message on `topic` (`header.frame_id`, `child_frame_id`)
    /// is the configured `field`: the diagnostic when it is not and was not reported for this
    /// value before.
    pub fn check(&mut self, topic: &str, field_name: &'static str, found: &str, field: FrameField) -> Option<String> {
        let expected = field.of(&self.frames);
        if found == expected {
            return None;
        }
        let key = (topic.to_string(), field_name);
        if self.reported.get(&key).is_some_and(|f| f == found) {
            return None;
        }
        self.reported.insert(key, found.to_string());
        Some(format!(
            "{topic}: {field_name} is `{found}`, expected `{expected}` ({}.frames.{}); \
             the tf tree joins `{expected}`, so fix the publisher or set the frame",
            self.setting,
            field.name()
        ))
    }

    /// Every mismatch seen, by topic and message field: the last frame id found.
    pub fn mismatches(&self) -> &BTreeMap<(String, &'static str), String> {
        &self.reported
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn spec(yaml: &str) -> Ros2Spec {
        serde_saphyr::from_str(yaml).expect("valid ros2 spec")
    }

    fn frames_of(id: &str, yaml: Option<&str>) -> RobotFrames {
        let s = yaml.map(spec);
        resolve(s.as_ref(), &TopicNames::resolve(id, s.as_ref()))
    }

    #[test]
    fn the_prefix_follows_the_namespace_while_tf_is_global() {
        assert_eq!(frames_of("ugv1", None), RobotFrames::prefixed("ugv1"));
        let husky = frames_of("ugv1", Some("namespace: husky\n"));
        assert_eq!((husky.map.as_str(), husky.odom.as_str()), ("map", "husky/odom"));
        assert_eq!((husky.base_link.as_str(), husky.sensor.as_str()), ("husky/base_link", "husky/lidar"));
        // A single robot at the root: REP-105's plain names (Nav2, ros2_control).
        assert_eq!(frames_of("ugv1", Some("namespace: /\n")), RobotFrames::with_prefix(""));
    }

    #[test]
    fn namespaced_tf_topics_give_plain_frames_and_explicit_settings_win() {
        let nav2 = frames_of("ugv1", Some("namespace: robot1\ntopics: { tf: tf, tf_static: tf_static }\n"));
        assert_eq!(nav2, RobotFrames::with_prefix(""));
        let prefixed = frames_of("ugv1", Some("namespace: robot1\nframe_prefix: r1\n"));
        assert_eq!(prefixed.odom, "r1/odom");
        let explicit = frames_of("ugv1", Some("frames: { odom: odom_ekf, sensor: os1_lidar }\n"));
        assert_eq!((explicit.odom.as_str(), explicit.sensor.as_str()), ("odom_ekf", "os1_lidar"));
        assert_eq!(explicit.base_link, "ugv1/base_link");
        let folded = frames_of("ugv1", Some("frame_prefix: ''\nframes: { base_link: odom }\n"));
        assert_eq!(collision(&folded), Some(("odom", "base_link", "odom".into())));
        assert_eq!(collision(&RobotFrames::prefixed("ugv1")), None);
    }

    #[test]
    fn a_mismatch_is_reported_once_per_topic_and_value_naming_the_setting() {
        let mut check = FrameCheck::new(RobotFrames::prefixed("ugv1"), "team[1] (ugv1) ros2");
        assert_eq!(check.check("/ugv1/odom", "header.frame_id", "ugv1/odom", FrameField::Odom), None);
        let why = check.check("/ugv1/odom", "header.frame_id", "odom", FrameField::Odom).expect("a mismatch");
        assert!(
            why.contains("`odom`") && why.contains("`ugv1/odom`") && why.contains("team[1] (ugv1) ros2.frames.odom"),
            "{why}"
        );
        assert_eq!(check.check("/ugv1/odom", "header.frame_id", "odom", FrameField::Odom), None, "once");
        assert!(check.check("/ugv1/odom", "child_frame_id", "base_link", FrameField::BaseLink).is_some());
        assert_eq!(check.mismatches().len(), 2);
    }
}
