//! The simulator as a ROS 2 robot farm, end to end on loopback: `spomp sim --ros2` simulates the
//! robots' bodies and sensors, separate `spomp run` processes drive them over DDS.
//!
//! The tests run the farm in lockstep (`--lockstep`): its time advances only when every robot
//! has answered the step, so what they check does not depend on the machine's load, and a
//! lockstep run is the very run `spomp sim` makes with the robots inside it. (The UAV test ran
//! paced at 4× real time, so its outcome hung on the machine keeping up with the camera. The
//! paced farm still runs in CI's Cyclone DDS step, `scripts/cyclonedds-farm.py`, which checks that
//! it runs, not what it achieves.)
//!
//! DDS stays on this machine: `ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST` restricts both processes
//! to 127.0.0.1, and each test uses a domain id of its own.

mod log_checks;
mod processes;

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use processes::{Reap, output, spomp, wait_with_timeout};
use spomp_ros_msgs as ros;

const MISSION: &str = "tests/missions/ros2/farm-one-ugv.yaml";
const FAR_MISSION: &str = "tests/missions/ros2/farm-kill.yaml";
const UAV_MISSION: &str = "tests/missions/ros2/farm-uav.yaml";
const TEAM_MISSION: &str = "tests/missions/ros2/farm-team-link.yaml";

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

/// `spomp run` of `robot` in the farm's lockstep.
fn start_lockstep_robot(mission: &str, robot: &str, domain: &str, extra: &[&str]) -> Reap {
    start_robot(mission, robot, domain, &[&["--lockstep"], extra].concat())
}

/// `spomp sim MISSION ARGS --json --no-mcap` in-process: the first run's summary.
fn in_process(mission: &str, out: &Path, args: &[&str]) -> serde_json::Value {
    let run = spomp()
        .args(["sim", mission, "--json", "--no-mcap", "--out"])
        .arg(out)
        .args(args)
        .output()
        .expect("spomp sim runs");
    assert!(run.status.success(), "{}", String::from_utf8_lossy(&run.stderr));
    let summary: serde_json::Value = serde_json::from_slice(&run.stdout).expect("sim prints its summary as JSON");
    summary["runs"][0].clone()
}

/// A run's summary without its wall-clock figures: what a lockstep farm run and the in-process
/// run of the same seed must agree on, field for field.
fn without_wall_time(run: &serde_json::Value) -> serde_json::Value {
    let mut run = run.clone();
    if let Some(fields) = run.as_object_mut() {
        fields.remove("wall_s");
        fields.remove("speedup");
    }
    run
}

/// The fields in which two summaries differ, for a failure message.
fn differences(a: &serde_json::Value, b: &serde_json::Value) -> String {
    let (Some(a), Some(b)) = (a.as_object(), b.as_object()) else { return format!("{a}\nvs\n{b}") };
    a.iter()
        .filter(|(k, v)| b.get(*k) != Some(*v))
        .map(|(k, v)| format!("{k}: {v}\n  in-process: {}", b.get(k).cloned().unwrap_or_default()))
        .collect::<Vec<_>>()
        .join("\n")
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
fn a_ugv_driven_by_a_separate_spomp_run_process_in_lockstep_reaches_its_goals_as_in_the_simulator() {
    let d = domain(0);
    let out = temp_dir("reach");
    std::fs::create_dir_all(&out).expect("temp dir");
    let robot_log = out.join("ugv1.mcap");
    // The basestation has no process: the farm simulates it (and does not wait for it).
    let latency = ["--skill-latency", "typical"];
    let sim = start_sim(
        MISSION,
        &d,
        &out.join("sim"),
        &[&["--lockstep", "--drive", "ugv1", "--no-mcap"], &latency[..]].concat(),
    );
    let run = start_lockstep_robot(MISSION, "ugv1", &d, &["--record", robot_log.to_str().expect("utf-8 path")]);
    // The robot process ends with the farm's run, with a safe command and its figures.
    let FarmEnd { summary, run_status, run_out, run_err } = finish_farm(sim, run);
    let trial = &summary["runs"][0];
    assert_eq!(trial["outcome"], "complete", "{summary:#}");
    assert_eq!(trial["goals_visited"], 2, "{summary:#}");
    let goals = trial["goals"].as_array().expect("goals");
    assert!(goals.iter().all(|g| g["visited_by"] == "ugv1"), "{goals:#?}");
    // The run the simulator makes with the robot inside it, to the last field.
    let inside = in_process(MISSION, &out.join("in-process"), &latency);
    assert_eq!(without_wall_time(trial), without_wall_time(&inside), "{}", differences(trial, &inside));

    assert!(run_status.is_some_and(|s| s.success()), "spomp run did not end cleanly:\n{run_err}");
    let report: serde_json::Value = serde_json::from_str(&run_out).expect("run prints its figures as JSON");
    assert!(report["ticks"].as_u64().unwrap_or(0) > 50, "{report:#}");
    assert!(report["received"]["panoramas"].as_u64().unwrap_or(0) > 5, "{report:#}");
    assert!(report["received"]["odometry"].as_u64().unwrap_or(0) > 100, "{report:#}");
    assert!(
        report["received"]["team"].as_u64().unwrap_or(0) > 0,
        "the basestation's messages reach the robot: {report:#}"
    );
    assert_eq!(report["malformed_inputs"], 0, "{report:#}");

    // The robot's log holds each topic with its DDS type, and the whole tf tree: the robot's
    // `map → odom`, `odom → base_link` from its odometry, the sensor mount.
    let messages = log_checks::read(&robot_log);
    log_checks::assert_topic_types(&messages, "ugv1", &["odom", "cmd_vel", "pose_estimate", "reachability", "tf"]);
    let frames = log_checks::assert_tf_tree_connects(&messages, "ugv1");
    assert!(frames.contains("ugv1/lidar") && frames.contains("ugv1/base_link"), "{frames:?}");
    // `--record` writes depth as the farm publishes it: REP-118's 32FC1 by default.
    let depth = messages.iter().find(|m| m.topic == "/ugv1/panorama/depth").expect("the robot logs its panoramas");
    let depth: ros::Image = spomp_mcap::decode_cdr(&depth.topic, &depth.data).expect("an image");
    assert_eq!((depth.encoding.as_str(), depth.step), ("32FC1", depth.width * 4));

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
fn a_robot_process_that_stops_answering_is_dropped_and_its_body_stops() {
    let d = domain(100);
    let out = temp_dir("kill");
    let mut sim = start_sim(
        FAR_MISSION,
        &d,
        &out,
        &["--lockstep", "--lockstep-timeout-s", "3", "--drive", "ugv1", "--time-limit-s", "60"],
    );
    // The robot's process goes away at 20 s of simulated time without a word to the farm.
    let mut run = start_lockstep_robot(FAR_MISSION, "ugv1", &d, &["--until-s", "20"]);
    let status = wait_with_timeout(&mut sim.0, Duration::from_secs(240)).expect("the farm run ends");
    let (sim_out, sim_err) = output(&mut sim.0);
    let _ = wait_with_timeout(&mut run.0, Duration::from_secs(20));
    assert!(status.code().is_some_and(|c| c <= 1), "spomp sim failed ({status}):\n{sim_out}\n{sim_err}");
    assert!(sim_err.contains("ugv1 dropped at 20.0 s"), "the farm reports the robot it dropped:\n{sim_err}");

    let commands = applied_commands(&out.join("trial-1/run.mcap"));
    let last_moving = commands.iter().filter(|(_, c)| *c > 1e-6).map(|(t, _)| *t).fold(f64::NAN, f64::max);
    assert!(last_moving.is_finite(), "the robot never moved: {} commands", commands.len());
    let end = commands.last().map_or(0.0, |(t, _)| *t);
    // Driven until 20 s, stopped from then on, and the run went on to its 60 s limit.
    assert!(last_moving <= 20.0 + 1e-6, "still commanded at {last_moving:.1} s of {end:.1} s");
    assert!(end >= 59.0, "the run ended at {end:.1} s");
    let _ = std::fs::remove_dir_all(&out);
}

#[test]
fn a_robot_process_that_starts_late_drives_its_robot_from_then_on() {
    let d = domain(600);
    let out = temp_dir("late");
    // The farm waits 1 s, then simulates ugv1 itself (at most 2× real time) until its process
    // reports.
    let mut sim = start_sim(
        FAR_MISSION,
        &d,
        &out,
        &["--lockstep", "--rate", "2", "--wait-s", "1", "--time-limit-s", "60", "--no-mcap"],
    );
    std::thread::sleep(Duration::from_secs(4));
    let mut run = start_lockstep_robot(FAR_MISSION, "ugv1", &d, &[]);
    let status = wait_with_timeout(&mut sim.0, Duration::from_secs(240)).expect("the farm run ends");
    let (sim_out, sim_err) = output(&mut sim.0);
    let _ = wait_with_timeout(&mut run.0, Duration::from_secs(20));
    let (run_out, run_err) = output(&mut run.0);
    assert!(status.code().is_some_and(|c| c <= 1), "spomp sim failed ({status}):\n{sim_out}\n{sim_err}");
    assert!(sim_err.contains("the simulator runs them until one does"), "{sim_err}");
    assert!(sim_err.contains("ugv1's process reported at"), "{sim_err}");
    let report: serde_json::Value =
        serde_json::from_str(&run_out).unwrap_or_else(|_| panic!("run prints its figures:\n{run_out}\n{run_err}"));
    assert!(report["ticks"].as_u64().unwrap_or(0) > 50, "the late process drove its robot: {report:#}");
    let _ = std::fs::remove_dir_all(&out);
}

#[test]
fn a_lockstep_farm_refuses_a_robot_set_up_with_another_seed() {
    let d = domain(400);
    let out = temp_dir("seed");
    let mut sim = start_sim(MISSION, &d, &out, &["--lockstep", "--drive", "ugv1", "--seed", "2", "--no-mcap"]);
    let _run = start_lockstep_robot(MISSION, "ugv1", &d, &["--seed", "1"]);
    let status = wait_with_timeout(&mut sim.0, Duration::from_secs(120)).expect("the farm gives up");
    let (_, sim_err) = output(&mut sim.0);
    assert!(!status.success());
    assert!(sim_err.contains("start it with --seed 2"), "{sim_err}");
}

/// Four processes — basestation, UAV and two UGVs — drive every robot of the farm, and their team
/// state goes over the farm's radio model: the run is the simulator's, field for field.
#[test]
fn a_lockstep_farm_of_four_processes_runs_exactly_as_the_simulator() {
    let d = domain(500);
    let out = temp_dir("identical");
    std::fs::create_dir_all(&out).expect("temp dir");
    let sim = start_sim(TEAM_MISSION, &d, &out.join("sim"), &["--lockstep", "--seed", "2", "--no-mcap"]);
    let robots: Vec<Reap> = ["base", "uav1", "ugv1", "ugv2"]
        .iter()
        .map(|r| start_lockstep_robot(TEAM_MISSION, r, &d, &["--seed", "2"]))
        .collect();
    let mut sim = sim;
    let status = wait_with_timeout(&mut sim.0, Duration::from_secs(300)).expect("the farm run ends within 300 s");
    let (sim_out, sim_err) = output(&mut sim.0);
    drop(robots);
    assert!(status.success(), "spomp sim --ros2 --lockstep failed ({status}):\n{sim_out}\n{sim_err}");
    assert!(
        sim_err.contains("driving base, uav1, ugv1, ugv2"),
        "every robot with a process is driven by it:\n{sim_err}"
    );
    let summary: serde_json::Value = serde_json::from_str(&sim_out).expect("sim prints its summary as JSON");
    let farm = &summary["runs"][0];
    assert_eq!(farm["outcome"], "complete", "{summary:#}");
    let inside = in_process(TEAM_MISSION, &out.join("in-process"), &["--seed", "2"]);
    assert_eq!(without_wall_time(farm), without_wall_time(&inside), "{}", differences(farm, &inside));
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
            let t = spomp_mcap::decode_cdr::<ros::TwistStamped>(&m.topic, &m.data).expect("twist").twist;
            (m.log_time as f64 * 1e-9, t.linear.x.abs() + t.angular.z.abs())
        })
        .collect()
}

#[test]
fn the_e_stop_halts_the_robot_until_released() {
    use spomp_ros2::dds::{DdsNode, DdsSettings, sensor_qos, state_qos};
    let d = domain(200);
    let out = temp_dir("estop");
    let mut sim = start_sim(FAR_MISSION, &d, &out, &["--lockstep", "--drive", "ugv1", "--time-limit-s", "70"]);
    let mut run = start_lockstep_robot(FAR_MISSION, "ugv1", &d, &[]);
    let settings = DdsSettings {
        domain_id: d.parse().expect("domain id"),
        interfaces: vec![std::net::IpAddr::from([127, 0, 0, 1])],
    };
    let mut operator = DdsNode::new(&settings, "/", "operator").expect("operator node");
    let estop = operator.publisher::<ros::BoolMsg>("/ugv1/estop", &state_qos(1)).expect("e-stop publisher");
    let clock = operator.subscription::<ros::Clock>("/clock", &sensor_qos(1)).expect("clock subscription");
    // The operator watches the farm's clock: the e-stop is pressed from 15 s to 35 s of
    // simulated time, released before and after, however fast the lockstep runs.
    let mut now_s = 0.0_f64;
    let deadline = Instant::now() + Duration::from_secs(240);
    while Instant::now() < deadline && sim.0.try_wait().ok().flatten().is_none() {
        while let Ok(Some((c, _))) = clock.take() {
            now_s = now_s.max(f64::from(c.clock.sec) + f64::from(c.clock.nanosec) * 1e-9);
        }
        let _ = estop.publish(ros::BoolMsg { data: (15.0..35.0).contains(&now_s) });
        std::thread::sleep(Duration::from_millis(5));
    }
    let status = wait_with_timeout(&mut sim.0, Duration::from_secs(240)).expect("the farm run ends");
    let (sim_out, sim_err) = output(&mut sim.0);
    assert!(status.code().is_some_and(|c| c <= 1), "spomp sim failed ({status}):\n{sim_out}\n{sim_err}");
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

/// A UAV's whole survey over ROS 2, in lockstep (it ran paced, and so depended on the machine's
/// speed).
#[test]
fn a_uav_driven_over_ros2_maps_the_city_for_the_team() {
    let d = domain(300);
    let out = temp_dir("uav");
    std::fs::create_dir_all(&out).expect("temp dir");
    let log = out.join("uav1.mcap");
    let sim = start_sim(UAV_MISSION, &d, &out.join("sim"), &["--lockstep", "--drive", "uav1", "--no-mcap"]);
    let run = start_lockstep_robot(UAV_MISSION, "uav1", &d, &["--record", log.to_str().expect("utf-8 path")]);
    let FarmEnd { summary, run_out, .. } = finish_farm(sim, run);
    // The only map the team has is the one the driven UAV built from the camera tiles the farm
    // published: the simulator's UGV found the vehicle cluster in it and visited it.
    let trial = &summary["runs"][0];
    assert_eq!(trial["outcome"], "complete", "{summary:#}");
    assert!(trial["goals_visited"].as_u64().unwrap_or(0) >= 1, "{summary:#}");
    // Regression: a position setpoint carries no speed, and the farm flew the UAV at the
    // simulator's 5 m/s default instead of the mission's 10 m/s (half the survey when paced).
    // The speed now travels on `setpoint_position/speed`; in-process this UAV averages 9.8 m/s
    // over its flying time.
    let uav = trial["robots"].as_array().and_then(|r| r.iter().find(|r| r["id"] == "uav1")).expect("uav1");
    let (flown, flying) = (uav["distance_m"].as_f64().unwrap_or(0.0), uav["travel_time_s"].as_f64().unwrap_or(0.0));
    assert!(flying > 0.0 && flown / flying > 6.0, "the UAV flew {flown:.0} m in {flying:.0} s: {summary:#}");
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
