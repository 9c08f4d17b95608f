//! The simulator as a ROS 2 robot farm, end to end on loopback: `spomp sim --ros2` simulates a
//! UGV's body and sensors, a separate `spomp run` process drives it over DDS.
//!
//! DDS stays on this machine: `ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST` restricts both processes
//! to 127.0.0.1, and each test uses a domain id of its own.

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use spomp_core::ros;

const MISSION: &str = "tests/missions/ros2/farm-one-ugv.yaml";
const FAR_MISSION: &str = "tests/missions/ros2/farm-kill.yaml";

fn spomp() -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_spomp"));
    c.current_dir(env!("CARGO_MANIFEST_DIR"));
    c.env("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST");
    c.env_remove("ROS_DOMAIN_ID");
    c
}

/// A domain id of this process and test (offsets below 100): parallel runs of the suite and
/// the tests of one run do not hear each other.
fn domain(offset: u32) -> String {
    (10 + (std::process::id() % 100) * 2 + offset / 100).to_string()
}

/// Kills the child when the test ends, however it ends.
struct Reap(Child);
impl Drop for Reap {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

fn wait_with_timeout(child: &mut Child, limit: Duration) -> Option<std::process::ExitStatus> {
    let deadline = Instant::now() + limit;
    while Instant::now() < deadline {
        if let Ok(Some(status)) = child.try_wait() {
            return Some(status);
        }
        std::thread::sleep(Duration::from_millis(100));
    }
    None
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

fn start_run(mission: &str, domain: &str) -> Reap {
    let child = spomp()
        .args(["run", mission, "--robot", "ugv1", "--use-sim-time", "--json", "--domain-id", domain])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("spomp run starts");
    Reap(child)
}

fn output(child: &mut Child) -> (String, String) {
    use std::io::Read;
    let mut out = String::new();
    let mut err = String::new();
    if let Some(mut s) = child.stdout.take() {
        let _ = s.read_to_string(&mut out);
    }
    if let Some(mut s) = child.stderr.take() {
        let _ = s.read_to_string(&mut err);
    }
    (out, err)
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
    let mut sim = start_sim(MISSION, &d, &out, &["--rate", "4", "--no-mcap"]);
    let mut run = start_run(MISSION, &d);
    let status = wait_with_timeout(&mut sim.0, Duration::from_secs(300));
    let (sim_out, sim_err) = output(&mut sim.0);
    // The robot process stops on SIGINT with a safe command and its figures.
    let _ = Command::new("kill").args(["-INT", &run.0.id().to_string()]).status();
    let run_status = wait_with_timeout(&mut run.0, Duration::from_secs(20));
    let (run_out, run_err) = output(&mut run.0);
    let status = status.expect("the farm run ends within 300 s");
    assert!(status.success(), "spomp sim --ros2 failed ({status}):\n{sim_out}\n{sim_err}\n--- run:\n{run_err}");
    let summary: serde_json::Value = serde_json::from_str(&sim_out).expect("sim prints its summary as JSON");
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
    let _ = std::fs::remove_dir_all(&out);
}

#[test]
fn killing_the_robot_process_stops_the_simulated_robot() {
    let d = domain(100);
    let out = temp_dir("kill");
    let mut sim = start_sim(FAR_MISSION, &d, &out, &["--rate", "2", "--time-limit-s", "60"]);
    let mut run = start_run(FAR_MISSION, &d);
    // Let it drive for a while, then kill it without warning: no stop command gets out.
    std::thread::sleep(Duration::from_secs(12));
    run.0.kill().expect("kill spomp run");
    let _ = run.0.wait();
    let status = wait_with_timeout(&mut sim.0, Duration::from_secs(240)).expect("the farm run ends");
    let (sim_out, sim_err) = output(&mut sim.0);
    assert!(status.code().is_some_and(|c| c <= 1), "spomp sim failed ({status}):\n{sim_out}\n{sim_err}");

    let bytes = std::fs::read(out.join("trial-1/run.mcap")).expect("the farm records its run");
    let log = spomp_mcap::McapLog::from_bytes(bytes);
    let commands: Vec<(f64, f64)> = log
        .messages()
        .expect("log reads")
        .into_iter()
        .filter(|m| m.topic == "/ugv1/cmd_vel")
        .map(|m| {
            let t: ros::Twist = spomp_mcap::decode_cdr(&m.topic, &m.data).expect("twist");
            (m.log_time as f64 * 1e-9, t.linear.x.abs() + t.angular.z.abs())
        })
        .collect();
    let last_moving = commands.iter().filter(|(_, c)| *c > 1e-6).map(|(t, _)| *t).fold(f64::NAN, f64::max);
    assert!(last_moving.is_finite(), "the robot never moved: {} commands", commands.len());
    let end = commands.last().map_or(0.0, |(t, _)| *t);
    // Killed about 24 s of simulated time after the start (12 s wall at 2×): the farm's
    // watchdog must have stopped it well before the 60 s limit and kept it stopped.
    assert!(last_moving < end - 15.0, "still commanded at {last_moving:.1} s of {end:.1} s");
    let _ = std::fs::remove_dir_all(&out);
}
