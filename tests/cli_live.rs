//! `spomp sim --live` watched as Foxglove watches it: a WebSocket viewer connects to the run,
//! subscribes to two channels and decodes their messages with the advertised ROS 2 schemas;
//! and the MCAP log carries the same channels a person watching needs (`/tf`, `/map`, `/goals`,
//! each robot's active node path).

#![allow(clippy::unwrap_used, clippy::expect_used)] // tests fail loudly by design

use std::collections::BTreeMap;
use std::io::{BufRead, BufReader};
use std::net::SocketAddr;
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::Duration;

use spomp_live::viewer::Viewer;
use spomp_mcap::{McapLog, decode_cdr};
use spomp_ros_msgs::{self as ros, RosMessage};

fn root() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

const WAIT: Duration = Duration::from_secs(120);

#[test]
fn a_viewer_subscribes_to_a_live_run_and_decodes_its_messages_with_the_advertised_schemas() {
    let out = tempfile::tempdir().unwrap();
    // At 10× real time; the viewer has seen enough long before the time limit, and the run is
    // stopped then.
    let mut sim = Command::new(assert_cmd::cargo::cargo_bin("spomp"))
        .current_dir(root())
        .args(["sim", "missions/patrol-return-home.yaml", "--time-limit-s", "600", "--rate", "10"])
        .args(["--live", "127.0.0.1:0", "--json", "--no-mcap", "--out"])
        .arg(out.path())
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut stderr = BufReader::new(sim.stderr.take().unwrap());
    let mut line = String::new();
    let addr: SocketAddr = loop {
        line.clear();
        assert!(stderr.read_line(&mut line).unwrap() > 0, "spomp sim ended before serving");
        if let Some(rest) = line.trim().strip_prefix("live view: ws://") {
            break rest.split_whitespace().next().unwrap().parse().unwrap();
        }
    };
    // Whatever else it says goes on being read, so the process never blocks on a full pipe.
    let rest_of_stderr = std::thread::spawn(move || {
        let mut text = String::new();
        for l in stderr.lines() {
            text.push_str(&l.unwrap_or_default());
            text.push('\n');
        }
        text
    });
    let mut viewer = Viewer::connect(addr, WAIT).unwrap();
    assert!(viewer.server_info["name"].as_str().unwrap().contains("patrol"), "{}", viewer.server_info);
    viewer.wait_for_channels(&["/tf", "/ugv1/cmd_vel"], WAIT).unwrap();
    for (topic, name, definition) in [
        ("/tf", ros::TfMessage::TYPE_NAME, ros::TfMessage::DEFINITION),
        ("/ugv1/cmd_vel", ros::TwistStamped::TYPE_NAME, ros::TwistStamped::DEFINITION),
    ] {
        let c = &viewer.channels[topic];
        assert_eq!(
            (c.encoding.as_str(), c.schema_encoding.as_str(), c.schema_name.as_str(), c.schema.as_str()),
            ("cdr", "ros2msg", name, definition),
            "{topic}"
        );
    }
    viewer.subscribe(&["/tf", "/ugv1/cmd_vel"]).unwrap();
    let mut frames: BTreeMap<String, usize> = BTreeMap::new();
    let mut commands = Vec::new();
    let mut last_tf_ns = 0;
    while frames.values().sum::<usize>() < 20 || commands.len() < 10 {
        let m = match viewer.next_message(WAIT) {
            Ok(m) => m,
            Err(e) => {
                let _ = sim.kill();
                panic!(
                    "{e} after {frames:?} and {} commands; the server said {:?}; spomp sim said: {}",
                    commands.len(),
                    viewer.statuses,
                    rest_of_stderr.join().unwrap()
                );
            }
        };
        match m.topic.as_str() {
            "/tf" => {
                let tf: ros::TfMessage = decode_cdr(&m.topic, &m.data).unwrap();
                let t = &tf.transforms[0];
                // `map → R/odom` and `R/odom → R/base_link` (a robot with odometry), or
                // `map → R/base_link`.
                assert!(t.header.frame_id == "map" || t.header.frame_id.ends_with("/odom"), "{t:?}");
                // The log time is the simulated time of the message's stamp.
                let stamp_ns = t.header.stamp.sec as u64 * 1_000_000_000 + u64::from(t.header.stamp.nanosec);
                assert_eq!(m.log_time_ns, stamp_ns);
                assert!(m.log_time_ns >= last_tf_ns, "in time order");
                last_tf_ns = m.log_time_ns;
                let q = t.transform.rotation;
                assert!((q.z * q.z + q.w * q.w - 1.0).abs() < 1e-9, "a yaw rotation");
                *frames.entry(t.child_frame_id.clone()).or_default() += 1;
            }
            "/ugv1/cmd_vel" => {
                let twist = decode_cdr::<ros::TwistStamped>(&m.topic, &m.data).unwrap().twist;
                assert!(twist.linear.x.is_finite() && twist.linear.x.abs() <= 1.5 + 1e-9, "{twist:?}");
                assert!(twist.angular.z.abs() <= 1.0 + 1e-9, "{twist:?}");
                commands.push(twist.linear.x);
            }
            other => panic!("a message on {other}, which was not subscribed to"),
        }
    }
    assert!(frames.contains_key("ugv1/base_link") && frames.contains_key("ugv2/base_link"), "{frames:?}");
    assert!(commands.iter().any(|v| *v > 0.1), "the patroller drives: {commands:?}");
    assert!(viewer.server_time_ns.is_some(), "the run's time is broadcast");
    assert_eq!(sim.try_wait().unwrap(), None, "the run was still going: {}", {
        let _ = sim.kill();
        rest_of_stderr.join().unwrap()
    });
    sim.kill().unwrap();
    sim.wait().unwrap();
}

#[test]
fn live_needs_one_trial_and_rate_needs_live_or_ros2() {
    let run = |extra: &[&str]| {
        Command::new(assert_cmd::cargo::cargo_bin("spomp"))
            .current_dir(root())
            .args(["sim", "missions/patrol-return-home.yaml", "--no-mcap"])
            .args(extra)
            .output()
            .unwrap()
    };
    let o = run(&["--live", "--trials", "2"]);
    assert_eq!(o.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&o.stderr).contains("--live shows one trial"));
    let o = run(&["--rate", "3"]);
    assert_eq!(o.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&o.stderr).contains("--rate paces"));
    let o = run(&["--live", "localhost"]);
    assert_eq!(o.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&o.stderr).contains("HOST:PORT"), "{}", String::from_utf8_lossy(&o.stderr));
}

#[test]
fn the_log_carries_what_a_person_watching_needs() {
    let out = tempfile::tempdir().unwrap();
    // Mission goals and a prior map from the start; two UGVs claim and drive.
    let o = Command::new(assert_cmd::cargo::cargo_bin("spomp"))
        .current_dir(root())
        .args(["sim", "missions/manual-goals.yaml", "--time-limit-s", "20", "--json", "--out"])
        .arg(out.path())
        .output()
        .unwrap();
    assert!(matches!(o.status.code(), Some(0 | 1)), "{}", String::from_utf8_lossy(&o.stderr));
    let bytes = std::fs::read(out.path().join("trial-1").join("run.mcap")).unwrap();
    let messages = McapLog::from_bytes(bytes).messages().unwrap();
    let on = |topic: &str| messages.iter().filter(|m| m.topic == topic).collect::<Vec<_>>();

    let tf = on("/tf");
    let children: std::collections::BTreeSet<String> = tf
        .iter()
        .flat_map(|m| decode_cdr::<ros::TfMessage>(&m.topic, &m.data).unwrap().transforms)
        .map(|t| t.child_frame_id)
        .collect();
    // The basestation has no odometry: its body hangs from `map`; the UGVs' from their `odom`.
    assert_eq!(
        children.into_iter().collect::<Vec<_>>(),
        ["base/base_link", "ugv1/base_link", "ugv1/odom", "ugv2/base_link", "ugv2/odom"]
    );
    assert_eq!(tf[0].schema, ros::TfMessage::TYPE_NAME);

    // The prior map, once: known cells scaled by traversability, unknown −1.
    let maps = on("/map");
    assert_eq!(maps.len(), 1, "a prior map is shown once");
    assert_eq!(maps[0].schema, ros::OccupancyGrid::TYPE_NAME);
    let grid: ros::OccupancyGrid = decode_cdr("/map", &maps[0].data).unwrap();
    assert_eq!(grid.data.len(), grid.info.width as usize * grid.info.height as usize);
    assert_eq!((grid.info.width, grid.info.height, grid.info.resolution), (800, 600, 0.5));
    assert!(grid.data.iter().all(|&v| v == -1 || (0..=100).contains(&v)));
    assert!(grid.data.iter().filter(|&&v| v == 0).count() > 1000, "roads are free");
    assert!(grid.data.contains(&100), "buildings are impassable");

    // Goals as markers: the last set shows every mission goal, some claimed.
    let goals = on("/goals");
    assert!(!goals.is_empty());
    let last: ros::MarkerArray = decode_cdr("/goals", &goals[goals.len() - 1].data).unwrap();
    let labels: Vec<&str> = last.markers.iter().filter(|m| m.r#type == 9).map(|m| m.text.as_str()).collect();
    assert!(labels.len() >= 2, "{labels:?}");
    assert!(labels.iter().any(|l| l.contains("claimed by ugv")), "{labels:?}");

    // Each UGV's active path: the running leaf of its tree (driving to its goal), written when
    // it changes.
    let mut changes = 0;
    for robot in ["ugv1", "ugv2"] {
        let paths: Vec<String> = on(&format!("/{robot}/active_path"))
            .iter()
            .map(|m| decode_cdr::<ros::StringMsg>(&m.topic, &m.data).unwrap().data)
            .collect();
        assert!(paths.windows(2).all(|w| w[0] != w[1]), "only changes: {paths:?}");
        let first = paths.first().unwrap_or_else(|| panic!("{robot} has an active path"));
        assert!(first.starts_with("visitor/") && first.ends_with("/navigate_to"), "{robot}: {paths:?}");
        assert!(!first.contains(" | "), "one leaf runs, not its ancestors: {first}");
        changes += paths.len();
    }
    assert!(changes > 2, "a robot's path changes as it claims and drives");
}

#[test]
fn a_robot_run_over_ros2_is_served_live_too() {
    // `spomp run` with nobody publishing to it: its inputs are stale, so it publishes stop
    // commands at its tick rate — and the viewer sees them as it would see a robot's.
    let domain = (150 + std::process::id() % 50).to_string();
    let mut run = Command::new(assert_cmd::cargo::cargo_bin("spomp"))
        .current_dir(root())
        .env("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
        .args(["run", "tests/missions/ros2/interop.yaml", "--robot", "ugv1", "--domain-id", &domain])
        .args(["--live", "127.0.0.1:0", "--json", "--until-s", "60"])
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut stderr = BufReader::new(run.stderr.take().unwrap());
    let mut line = String::new();
    let addr: SocketAddr = loop {
        line.clear();
        assert!(stderr.read_line(&mut line).unwrap() > 0, "spomp run ended before serving");
        if let Some(rest) = line.trim().strip_prefix("live view: ws://") {
            break rest.split_whitespace().next().unwrap().parse().unwrap();
        }
    };
    let drain = std::thread::spawn(move || for _ in stderr.lines() {});
    let mut viewer = Viewer::connect(addr, WAIT).unwrap();
    viewer.wait_for_channels(&["/ugv1/cmd_vel"], WAIT).unwrap();
    assert_eq!(viewer.channels["/ugv1/cmd_vel"].schema_name, ros::TwistStamped::TYPE_NAME);
    viewer.subscribe(&["/ugv1/cmd_vel"]).unwrap();
    for _ in 0..5 {
        let m = viewer.next_message(WAIT).unwrap();
        assert_eq!(m.topic, "/ugv1/cmd_vel");
        let twist = decode_cdr::<ros::TwistStamped>(&m.topic, &m.data).unwrap().twist;
        assert_eq!((twist.linear.x, twist.angular.z), (0.0, 0.0), "stale inputs: a stop command");
    }
    run.kill().unwrap();
    run.wait().unwrap();
    drain.join().unwrap();
}
