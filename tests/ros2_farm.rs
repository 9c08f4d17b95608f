//! The simulator as a ROS 2 robot farm, end to end on loopback: `spomp sim --ros2` simulates a
//! UGV's body and sensors, a separate `spomp run` process drives it over DDS.
//!
//! DDS stays on this machine: `ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST` restricts both processes
//! to 127.0.0.1, and each test uses a domain id of its own.

mod processes;

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use processes::{Reap, output, spomp, wait_with_timeout};
use spomp_core::ros;

const MISSION: &str = "tests/missions/ros2/farm-one-ugv.yaml";
const FAR_MISSION: &str = "tests/missions/ros2/farm-kill.yaml";
const UAV_MISSION: &str = "tests/missions/ros2/farm-uav.yaml";

/// A domain id of this process and test (offsets below 100): parallel runs of the suite and
/// the tests of one run do not hear each other.
fn domain(offset: u32) -> String {
    (10 + (std::process::id() % 50) * 4 + offset / 100).to_string()
}

fn start_sim(mission: &str, domain: &str, out: &Path, extra: &[&str]) -> Reap {
    let child = spomp()
        .args(["sim", mission, "--ros2", "--domain-id", domain, "--json", "--out"])
        .arg(out)
        .args(extra)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("spomp sim starts");
    Reap(child)
}

fn start_run(mission: &str, domain: &str, extra: &[&str]) -> Reap {
    start_robot(mission, "ugv1", domain, extra)
}

fn start_robot(mission: &str, robot: &str, domain: &str, extra: &[&str]) -> Reap {
    let child = spomp()
        .args(["run", mission, "--robot", robot, "--use-sim-time", "--json", "--domain-id", domain])
        .args(extra)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("spomp run starts");
    Reap(child)
}

/// How a farm run ended.
struct FarmEnd {
    /// The simulator's summary (`--json`).
    summary: serde_json::Value,
    /// How the robot process exited after SIGINT, if it did within 20 s.
    run_status: Option<std::process::ExitStatus>,
    /// What the robot process printed.
    run_out: String,
    run_err: String,
}

/// Waits for the farm's run to end (it must succeed, within 300 s), then stops the robot
/// process with SIGINT and reads both processes' output.
fn finish_farm(mut sim: Reap, mut run: Reap) -> FarmEnd {
    let status = wait_with_timeout(&mut sim.0, Duration::from_secs(300));
    let (sim_out, sim_err) = output(&mut sim.0);
    let _ = Command::new("kill").args(["-INT", &run.0.id().to_string()]).status();
    let run_status = wait_with_timeout(&mut run.0, Duration::from_secs(20));
    let (run_out, run_err) = output(&mut run.0);
    let status = status.expect("the farm run ends within 300 s");
    assert!(status.success(), "spomp sim --ros2 failed ({status}):\n{sim_out}\n{sim_err}\n--- run:\n{run_err}");
    let summary = serde_json::from_str(&sim_out).expect("sim prints its summary as JSON");
    FarmEnd { summary, run_status, run_out, run_err }
}

fn temp_dir(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("spomp-ros2-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    dir
}

#[test]
fn a_ugv_driven_by_a_separate_spomp_run_process_reaches_its_goals() {
    let d = domain(0);
    let out = temp_dir("reach");
    std::fs::create_dir_all(&out).expect("temp dir");
    let robot_log = out.join("ugv1.mcap");
    let sim = start_sim(MISSION, &d, &out.join("sim"), &["--rate", "4", "--no-mcap"]);
    let run = start_run(MISSION, &d, &["--record", robot_log.to_str().expect("utf-8 path")]);
    // The robot process stops on SIGINT with a safe command and its figures.
    let FarmEnd { summary, run_status, run_out, run_err } = finish_farm(sim, run);
    let trial = &summary["runs"][0];
    assert_eq!(trial["outcome"], "complete", "{summary:#}");
    assert_eq!(trial["goals_visited"], 2, "{summary:#}");
    let goals = trial["goals"].as_array().expect("goals");
    assert!(goals.iter().all(|g| g["visited_by"] == "ugv1"), "{goals:#?}");

    assert!(run_status.is_some_and(|s| s.success()), "spomp run did not stop cleanly on SIGINT:\n{run_err}");
    let report: serde_json::Value = serde_json::from_str(&run_out).expect("run prints its figures as JSON");
    assert!(report["ticks"].as_u64().unwrap_or(0) > 50, "{report:#}");
    assert!(report["received"]["panoramas"].as_u64().unwrap_or(0) > 5, "{report:#}");
    assert!(report["received"]["odometry"].as_u64().unwrap_or(0) > 100, "{report:#}");
    assert!(
        report["received"]["team"].as_u64().unwrap_or(0) > 0,
        "the basestation's messages reach the robot: {report:#}"
    );
    assert_eq!(report["malformed_inputs"], 0, "{report:#}");

    // The robot's own log replays: a fresh robot fed the recorded inputs decides the same.
    let replay =
        spomp().args(["replay"]).arg(&robot_log).args(["--robot", "ugv1", "--json"]).output().expect("replay runs");
    let text = String::from_utf8_lossy(&replay.stdout);
    assert!(
        replay.status.success(),
        "the robot log does not replay identically:\n{text}\n{}",
        String::from_utf8_lossy(&replay.stderr)
    );
    // Its heavy skills ran on worker threads, and the replay repeated that work where the
    // robot took it and had it back.
    let replayed: serde_json::Value = serde_json::from_str(&text).expect("replay --json is JSON");
    assert!(replayed["skill_jobs"].as_u64().unwrap_or(0) > 0, "{replayed:#}");
    assert!(report["skill_jobs"].as_u64().unwrap_or(0) > 0, "{report:#}");
    let _ = std::fs::remove_dir_all(&out);
}

#[test]
fn killing_the_robot_process_stops_the_simulated_robot() {
    let d = domain(100);
    let out = temp_dir("kill");
    let mut sim = start_sim(FAR_MISSION, &d, &out, &["--rate", "2", "--time-limit-s", "60"]);
    let mut run = start_run(FAR_MISSION, &d, &[]);
    // Let it drive for a while, then kill it without warning: no stop command gets out.
    std::thread::sleep(Duration::from_secs(12));
    run.0.kill().expect("kill spomp run");
    let _ = run.0.wait();
    let status = wait_with_timeout(&mut sim.0, Duration::from_secs(240)).expect("the farm run ends");
    let (sim_out, sim_err) = output(&mut sim.0);
    assert!(status.code().is_some_and(|c| c <= 1), "spomp sim failed ({status}):\n{sim_out}\n{sim_err}");

    let commands = applied_commands(&out.join("trial-1/run.mcap"));
    let last_moving = commands.iter().filter(|(_, c)| *c > 1e-6).map(|(t, _)| *t).fold(f64::NAN, f64::max);
    assert!(last_moving.is_finite(), "the robot never moved: {} commands", commands.len());
    let end = commands.last().map_or(0.0, |(t, _)| *t);
    // Killed about 24 s of simulated time after the start (12 s wall at 2×): the farm's
    // watchdog must have stopped it well before the 60 s limit and kept it stopped.
    assert!(last_moving < end - 15.0, "still commanded at {last_moving:.1} s of {end:.1} s");
    let _ = std::fs::remove_dir_all(&out);
}

/// Velocity commands the farm applied to ugv1: (simulated time s, |v| + |ω|).
fn applied_commands(log: &Path) -> Vec<(f64, f64)> {
    let bytes = std::fs::read(log).expect("the farm records its run");
    spomp_mcap::McapLog::from_bytes(bytes)
        .messages()
        .expect("log reads")
        .into_iter()
        .filter(|m| m.topic == "/ugv1/cmd_vel")
        .map(|m| {
            let t: ros::Twist = spomp_mcap::decode_cdr(&m.topic, &m.data).expect("twist");
            (m.log_time as f64 * 1e-9, t.linear.x.abs() + t.angular.z.abs())
        })
        .collect()
}

#[test]
fn the_e_stop_halts_the_robot_until_released() {
    use spomp_ros2::dds::{DdsNode, DdsSettings, state_qos};
    let d = domain(200);
    let out = temp_dir("estop");
    let mut sim = start_sim(FAR_MISSION, &d, &out, &["--rate", "2", "--time-limit-s", "70"]);
    let mut run = start_run(FAR_MISSION, &d, &[]);
    let settings = DdsSettings {
        domain_id: d.parse().expect("domain id"),
        interfaces: vec![std::net::IpAddr::from([127, 0, 0, 1])],
    };
    let mut operator = DdsNode::new(&settings, "/", "operator").expect("operator node");
    let estop = operator.publisher::<ros::BoolMsg>("/ugv1/estop", &state_qos(1)).expect("e-stop publisher");
    let press = |engaged: bool, for_s: u64| {
        let until = Instant::now() + Duration::from_secs(for_s);
        while Instant::now() < until {
            let _ = estop.publish(ros::BoolMsg { data: engaged });
            std::thread::sleep(Duration::from_millis(200));
        }
    };
    press(false, 10); // driving
    press(true, 8); // e-stop: 16 s of simulated time
    press(false, 2); // released
    let status = wait_with_timeout(&mut sim.0, Duration::from_secs(240)).expect("the farm run ends");
    let (sim_out, sim_err) = output(&mut sim.0);
    assert!(status.code().is_some_and(|c| c <= 1), "spomp sim failed ({status}):\n{sim_out}\n{sim_err}");
    let _ = Command::new("kill").args(["-INT", &run.0.id().to_string()]).status();
    let _ = wait_with_timeout(&mut run.0, Duration::from_secs(20));

    let commands = applied_commands(&out.join("trial-1/run.mcap"));
    // The longest stretch of zero commands between two moving ones: the e-stop.
    let (mut longest, mut zero_since, mut moved) = (0.0_f64, None, false);
    for &(t, c) in &commands {
        if c > 1e-6 {
            if let (true, Some(z)) = (moved, zero_since) {
                longest = longest.max(t - z);
            }
            moved = true;
            zero_since = None;
        } else if moved && zero_since.is_none() {
            zero_since = Some(t);
        }
    }
    assert!(longest >= 10.0, "no stop of 10 s or more between two moving stretches (longest {longest:.1} s)");
    let _ = std::fs::remove_dir_all(&out);
}

#[test]
fn a_uav_driven_over_ros2_maps_the_city_for_the_team() {
    let d = domain(300);
    let out = temp_dir("uav");
    std::fs::create_dir_all(&out).expect("temp dir");
    let log = out.join("uav1.mcap");
    let sim = start_sim(UAV_MISSION, &d, &out.join("sim"), &["--drive", "uav1", "--rate", "4", "--no-mcap"]);
    let run = start_robot(UAV_MISSION, "uav1", &d, &["--record", log.to_str().expect("utf-8 path")]);
    let FarmEnd { summary, run_out, .. } = finish_farm(sim, run);
    // The only map the team has is the one the driven UAV built from the camera tiles the farm
    // published: the simulator's UGV found the vehicle cluster in it and visited it.
    let trial = &summary["runs"][0];
    assert_eq!(trial["outcome"], "complete", "{summary:#}");
    assert!(trial["goals_visited"].as_u64().unwrap_or(0) >= 1, "{summary:#}");
    let report: serde_json::Value = serde_json::from_str(&run_out).expect("run prints its figures as JSON");
    assert!(report["received"]["camera_tiles"].as_u64().unwrap_or(0) > 100, "{report:#}");
    assert!(report["received"]["poses"].as_u64().unwrap_or(0) > 100, "{report:#}");
    assert_eq!(report["malformed_inputs"], 0, "{report:#}");
    // The UAV's log replays: the tiles and positions it was given make the same flight.
    let replay = spomp().args(["replay"]).arg(&log).args(["--robot", "uav1"]).output().expect("replay runs");
    assert!(
        replay.status.success(),
        "the UAV's log does not replay identically:\n{}\n{}",
        String::from_utf8_lossy(&replay.stdout),
        String::from_utf8_lossy(&replay.stderr)
    );
    let _ = std::fs::remove_dir_all(&out);
}
