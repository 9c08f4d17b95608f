//! A simulator log holds each robot topic with the type it has on DDS, and a whole tf tree: every
//! frame a message names reaches `map` (so odometry, panoramas and the reachability scan can be
//! placed in a 3-D panel), in the frames the robot's `ros2:` settings give.

#![allow(clippy::unwrap_used, clippy::expect_used)] // tests fail loudly by design

mod log_checks;

use std::path::Path;

use assert_cmd::Command;

fn sim_log(mission: &str, out: &Path) -> Vec<spomp_mcap::LogMessage> {
    let run = Command::cargo_bin("spomp")
        .unwrap()
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .args(["sim", mission, "--time-limit-s", "12", "--seed", "3", "--json", "--pano-every-s", "2", "--out"])
        .arg(out)
        .output()
        .unwrap();
    assert!(run.status.code().is_some_and(|c| c <= 1), "{}", String::from_utf8_lossy(&run.stderr));
    log_checks::read(&out.join("trial-3").join("run.mcap"))
}

#[test]
fn a_simulator_log_has_the_dds_types_and_a_connected_tf_tree() {
    let out = tempfile::tempdir().unwrap();
    let messages = sim_log("tests/missions/ros2/farm-one-ugv.yaml", out.path());
    log_checks::assert_topic_types(&messages, "ugv1", &["odom", "cmd_vel", "pose_estimate", "reachability"]);
    let frames = log_checks::assert_tf_tree_connects(&messages, "ugv1");
    let expected: std::collections::BTreeSet<String> =
        ["ugv1/odom", "ugv1/base_link", "ugv1/lidar"].iter().map(|s| s.to_string()).collect();
    assert_eq!(frames, expected);
    // Depth in REP-118's canonical encoding: metres, +inf where nothing returned.
    let depth = depth_image(&messages);
    assert_eq!((depth.encoding.as_str(), depth.step), ("32FC1", depth.width * 4));
    let ranges: Vec<f32> = depth.data.chunks_exact(4).map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]])).collect();
    assert!(ranges.iter().any(|r| r.is_finite() && *r > 0.3 && *r < 60.0), "the ground is seen");
    assert!(ranges.iter().all(|r| *r == f32::INFINITY || (r.is_finite() && *r > 0.0)), "no zeros or NaN");
}

fn depth_image(messages: &[spomp_mcap::LogMessage]) -> spomp_ros_msgs::Image {
    let m = messages.iter().find(|m| m.topic == "/ugv1/panorama/depth").expect("a depth panorama");
    spomp_mcap::decode_cdr(&m.topic, &m.data).unwrap()
}

#[test]
fn a_simulator_log_names_the_frames_and_tf_topics_of_the_robots_settings() {
    // Nav2's multi-robot layout: the robot's own tf topics and plain frames.
    let dir = tempfile::tempdir().unwrap();
    let mission = std::fs::read_to_string(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/missions/ros2/farm-one-ugv.yaml"),
    )
    .unwrap()
    .replace(
        "ros2: { use_sim_time: true,",
        "ros2: { namespace: robot1, topics: { tf: tf, tf_static: tf_static }, cmd_vel_type: twist, depth_encoding: mono16, use_sim_time: true,",
    );
    assert!(mission.contains("namespace: robot1"), "the fixture changed");
    let path = dir.path().join("nav2.yaml");
    std::fs::write(&path, mission).unwrap();
    let messages = sim_log(path.to_str().unwrap(), &dir.path().join("out"));
    let topics: std::collections::BTreeSet<&str> = messages.iter().map(|m| m.topic.as_str()).collect();
    assert!(topics.contains("/robot1/tf") && topics.contains("/robot1/tf_static"), "{topics:?}");
    let odom = messages.iter().find(|m| m.topic == "/ugv1/odom").expect("odometry");
    let odom: spomp_ros_msgs::Odometry = spomp_mcap::decode_cdr(&odom.topic, &odom.data).unwrap();
    assert_eq!((odom.header.frame_id.as_str(), odom.child_frame_id.as_str()), ("odom", "base_link"));
    let cmd = messages.iter().find(|m| m.topic == "/ugv1/cmd_vel").expect("commands");
    assert_eq!(cmd.schema, "geometry_msgs/msg/Twist", "the robot's command type");
    // The earlier encoding, kept as an option: counts of 1/512 m.
    let depth = depth_image(&messages);
    assert_eq!((depth.encoding.as_str(), depth.step), ("mono16", depth.width * 2));
}
