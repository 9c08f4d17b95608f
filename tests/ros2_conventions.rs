//! What a ROS 2 integrator types and keeps: `use_sim_time` given the ROS way (`--ros-args -p
//! use_sim_time:=true`, a launch file's parameters file) takes effect or is refused, never
//! ignored; logs recorded before depth moved to REP-118's `32FC1` still replay.
//!
//! DDS stays on this machine (`ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST`), each test on a domain
//! of its own.

mod processes;

use std::io::{BufRead, BufReader};
use std::process::Stdio;
use std::sync::mpsc;
use std::time::Duration;

use processes::{Reap, spomp, wait_with_timeout};

/// A mission whose robot does not ask for `/clock` (`ros2.use_sim_time` unset).
const MISSION: &str = "tests/missions/ros2/interop.yaml";

fn domain(offset: u32) -> String {
    (60 + (std::process::id() % 40) * 4 + offset).to_string()
}

/// Starts `spomp run` on `MISSION` with `extra` and returns the line of its start-up banner
/// (which says where its time comes from), then stops it.
fn banner(extra: &[&str], offset: u32) -> String {
    let mut child = Reap(
        spomp()
            .args(["run", MISSION, "--robot", "ugv1", "--domain-id", &domain(offset)])
            .args(extra)
            .stdout(Stdio::null())
            .stderr(Stdio::piped())
            .spawn()
            .expect("spomp run starts"),
    );
    let stderr = child.0.stderr.take().expect("stderr");
    let (tx, rx) = mpsc::channel();
    std::thread::spawn(move || {
        for line in BufReader::new(stderr).lines().map_while(Result::ok) {
            if tx.send(line).is_err() {
                break;
            }
        }
    });
    let mut seen = Vec::new();
    // A bound for a stuck process, not a speed assumption: the banner comes before any DDS work.
    while let Ok(line) = rx.recv_timeout(Duration::from_secs(60)) {
        if line.starts_with("spomp run: robot ugv1") {
            return line;
        }
        seen.push(line);
    }
    panic!("no start-up banner; stderr:\n{}", seen.join("\n"));
}

#[test]
fn use_sim_time_as_a_ros_parameter_takes_effect() {
    assert!(banner(&[], 0).contains("wall-clock time"), "the mission's own setting");
    let line = banner(&["--ros-args", "-p", "use_sim_time:=true"], 1);
    assert!(line.contains("time from /clock"), "{line}");
    // As a launch file passes it: a parameters file for every node.
    let dir = tempfile::tempdir().expect("temp dir");
    let params = dir.path().join("launch_params.yaml");
    std::fs::write(&params, "/**:\n  ros__parameters:\n    use_sim_time: true\n").expect("write");
    let line = banner(&["--ros-args", "--params-file", params.to_str().expect("utf-8"), "--"], 2);
    assert!(line.contains("time from /clock"), "{line}");
}

#[test]
fn ros_arguments_spomp_does_not_take_are_refused_not_ignored() {
    for (args, says) in [
        (&["--ros-args", "-r", "__ns:=/husky"][..], "does not take remappings"),
        (&["--ros-args", "-p", "max_vel:=2.0"][..], "`max_vel` is not a parameter spomp run reads"),
        (&["--ros-args", "-p", "use_sim_time:=sometimes"][..], "use_sim_time must be true or false"),
        (&["--ros-args", "--params-file", "no/such/params.yaml"][..], "no/such/params.yaml"),
    ] {
        let mut child = Reap(
            spomp()
                .args(["run", MISSION, "--robot", "ugv1", "--domain-id", &domain(3)])
                .args(args)
                .stdout(Stdio::null())
                .stderr(Stdio::piped())
                .spawn()
                .expect("spomp run starts"),
        );
        let status = wait_with_timeout(&mut child.0, Duration::from_secs(60)).expect("refused at start");
        let (_, err) = processes::output(&mut child.0);
        assert_eq!(status.code(), Some(2), "{args:?}: {err}");
        assert!(err.contains(says), "{args:?}: {err}");
    }
}

#[test]
fn a_log_recorded_with_mono16_depth_still_replays() {
    // Recorded by an earlier spomp (depth as mono16 counts of 1/512 m): replay reads the
    // robot's inputs from its seam channel, which the depth image's encoding does not touch.
    let log = "fuzz/corpus/replay_log/seed-small-replayable.mcap";
    let bytes = std::fs::read(std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join(log)).expect("the fixture");
    let messages = spomp_mcap::McapLog::from_bytes(bytes).messages().expect("the fixture reads");
    let depth = messages.iter().find(|m| m.topic == "/ugv1/panorama/depth").expect("a depth image");
    let img: spomp_ros_msgs::Image = spomp_mcap::decode_cdr(&depth.topic, &depth.data).expect("an image");
    assert_eq!(img.encoding, "mono16", "the fixture holds the earlier depth encoding");
    let replay = spomp().args(["replay", log, "--robot", "ugv1"]).output().expect("replay runs");
    assert!(replay.status.success(), "{}", String::from_utf8_lossy(&replay.stderr));
    assert!(String::from_utf8_lossy(&replay.stdout).contains("identical"));
}
