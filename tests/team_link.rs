//! The team link end to end on loopback: four `spomp run` processes (basestation, UAV, two
//! UGVs) drive the robots of `spomp sim --ros2` over DDS, and their team state goes between them
//! over Zenoh, signed with keys from `spomp keys generate`. A rogue that has the team's transport
//! password but not its signing keys injects goals, claims and visits all along.
//!
//! The farm runs in lockstep with the robots (`--lockstep`): its clock waits for every robot's
//! answer, so a loaded machine slows the run down instead of changing it. The team state still
//! travels over the real link, in real time.
//!
//! DDS stays on 127.0.0.1 (`ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST`, a domain id per test);
//! Zenoh listens and connects on 127.0.0.1 ports only, multicast scouting off.

mod processes;

use std::collections::BTreeMap;
use std::net::TcpListener;
use std::path::PathBuf;
use std::process::{Command, Stdio};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::time::{Duration, Instant};

use processes::{Reap, output, spomp, wait_with_timeout};
use spomp_core::{GoalId, Point2, RobotId, Time};
use spomp_teamstate::{GoalOrigin, RecordKey, TeamState, TeamStateParams, Tier, TierSet};
use spomp_zenoh::{KeyDir, LinkConfig, TeamLink};

const MISSION: &str = "tests/missions/ros2/farm-team-link.yaml";
const ROBOTS: [&str; 4] = ["base", "uav1", "ugv1", "ugv2"];

fn domain(offset: u32) -> String {
    (12 + (std::process::id() % 50) * 4 + offset / 100).to_string()
}

fn free_port() -> u16 {
    TcpListener::bind("127.0.0.1:0").map(|l| l.local_addr().map(|a| a.port()).unwrap_or(0)).unwrap_or(0)
}

/// A test's processes: the farm, the team's key folder, each robot's port and state file.
struct Team {
    dir: PathBuf,
    domain: String,
    mission: &'static str,
    ports: BTreeMap<&'static str, u16>,
}

impl Team {
    fn new(name: &str, domain: String) -> Team {
        Team::of(name, domain, MISSION, &ROBOTS)
    }

    /// The team of `mission`, whose robots are `robots`.
    fn of(name: &str, domain: String, mission: &'static str, robots: &[&'static str]) -> Team {
        let dir = std::env::temp_dir().join(format!("spomp-team-link-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).expect("temp dir");
        let keys = spomp().args(["keys", "generate", mission, "--out"]).arg(dir.join("keys")).output().expect("keys");
        assert!(keys.status.success(), "{}", String::from_utf8_lossy(&keys.stderr));
        let ports = robots.iter().map(|r| (*r, free_port())).collect();
        Team { dir, domain, mission, ports }
    }

    fn keys(&self) -> PathBuf {
        self.dir.join("keys")
    }

    fn state_file(&self, robot: &str) -> PathBuf {
        self.dir.join(format!("{robot}.state"))
    }

    /// The farm in lockstep; `extra` after the rest (`--rate` caps its speed; a
    /// `--lockstep-timeout-s` there replaces the default 5 s).
    fn start_farm(&self, extra: &[&str]) -> Reap {
        let timeout: &[&str] =
            if extra.contains(&"--lockstep-timeout-s") { &[] } else { &["--lockstep-timeout-s", "5"] };
        let child = spomp()
            .args(["sim", self.mission, "--ros2", "--lockstep"])
            .args(timeout)
            .args(["--domain-id", &self.domain, "--json", "--no-mcap"])
            .args(extra)
            .arg("--out")
            .arg(self.dir.join("sim"))
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .expect("spomp sim starts");
        Reap(child)
    }

    /// `spomp run` of `robot`: listening on its port, connecting to the basestation's and
    /// ugv1's (gossip finds the rest).
    fn start_robot(&self, robot: &str, extra: &[&str]) -> Reap {
        let mut cmd = spomp();
        cmd.args(["run", self.mission, "--robot", robot, "--lockstep", "--json", "--domain-id", &self.domain]);
        cmd.arg("--keys").arg(self.keys());
        cmd.args(["--listen", &format!("tcp/127.0.0.1:{}", self.ports[robot])]);
        for hub in ["base", "ugv1"].iter().filter(|h| **h != robot && self.ports.contains_key(*h)) {
            cmd.args(["--connect", &format!("tcp/127.0.0.1:{}", self.ports[hub])]);
        }
        cmd.arg("--state-file").arg(self.state_file(robot)).args(["--state-period-s", "1"]).args(extra);
        Reap(cmd.stdout(Stdio::piped()).stderr(Stdio::piped()).spawn().expect("spomp run starts"))
    }

    /// A robot's team state from its state file, checked with the team's keys.
    fn team_state(&self, robot: &str) -> Option<TeamState> {
        let bytes = spomp_zenoh::read_state(&self.state_file(robot), robot).ok()??;
        // The robot's resume state: [entries length][entries JSON][team snapshot].
        let (len, rest) = bytes.split_first_chunk::<4>()?;
        let team = rest.get(u32::from_le_bytes(*len) as usize..)?;
        let id = RobotId::new(robot);
        let mut state = TeamState::new(id.clone(), 1, TeamStateParams::default()).ok()?;
        let keys = KeyDir::load(&self.keys()).ok()?;
        state.set_security(Arc::new(keys.security(&id).ok()?)).ok()?;
        state.restore(team).ok()?;
        Some(state)
    }
}

impl Drop for Team {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.dir);
    }
}

/// The rogue: the team's transport password (a leaked one), no signing key of the team. Until
/// `stop`, it sends every robot forged goals, claims on every mission goal and visits of them, in
/// ugv1's name (signed with its own key) and in a non-member's, every 0.3 s once the basestation
/// is reachable from both of its links; `rounds` counts the rounds sent.
fn start_rogue(team: &Team, stop: Arc<AtomicBool>, rounds: Arc<AtomicUsize>) -> std::thread::JoinHandle<()> {
    let keys = KeyDir::load(&team.keys()).expect("team keys");
    let credentials = keys.credentials(&RobotId::new("base")).expect("credentials");
    let own_keys_dir = team.dir.join("rogue-keys");
    let own = KeyDir::generate(&own_keys_dir, "farm-team-link", &[RobotId::new("ugv1"), RobotId::new("mallory")])
        .expect("rogue keys");
    let configs: Vec<LinkConfig> = ["ugv1", "mallory"]
        .iter()
        .map(|name| {
            let mut config = LinkConfig::new("farm-team-link", RobotId::new(name));
            config.listen = vec![format!("tcp/127.0.0.1:{}", free_port())];
            config.connect =
                vec![format!("tcp/127.0.0.1:{}", team.ports["base"]), format!("tcp/127.0.0.1:{}", team.ports["ugv1"])];
            config.credentials = Some(credentials.clone());
            config
        })
        .collect();
    std::thread::spawn(move || {
        let links: Vec<TeamLink> = configs.iter().filter_map(|c| TeamLink::open(c).ok()).collect();
        if links.len() != configs.len() {
            return;
        }
        let mut forgers: Vec<TeamState> = ["ugv1", "mallory"]
            .iter()
            .map(|name| {
                let id = RobotId::new(name);
                let mut s = TeamState::new(id.clone(), 0, TeamStateParams::default()).expect("state");
                s.set_security(Arc::new(own.security(&id).expect("rogue key"))).expect("secure");
                s.set_session(1);
                for k in 0..3 {
                    let _ = s.add_mission_goal(k, Point2::new(30.0 + 20.0 * k as f64, 9.0));
                }
                let _ = s.identify_goal(Point2::new(110.0, 90.0), GoalOrigin::Detected, Time::ZERO);
                for k in 0..3 {
                    let g = GoalId { origin: RobotId::new("mission"), seq: k };
                    let _ = s.claim(&g, Time::from_secs_f64(1e6));
                    if k > 0 {
                        let _ = s.mark_visited(&g, Time::from_secs_f64(1.0));
                    }
                }
                s
            })
            .collect();
        // A lockstep run lasts seconds: send only once the victims can hear it.
        let base = RobotId::new("base");
        let deadline = std::time::Instant::now() + Duration::from_secs(60);
        while !links.iter().all(|l| l.reachable().contains(&base)) && std::time::Instant::now() < deadline {
            std::thread::sleep(Duration::from_millis(100));
        }
        while !stop.load(Ordering::SeqCst) {
            for (forger, link) in forgers.iter_mut().zip(&links) {
                for victim in ROBOTS {
                    let to = RobotId::new(victim);
                    if let Some(m) = forger.make_sync(&to, TierSet::ALL, usize::MAX) {
                        link.send(&to, Tier::Coordination, m.encode());
                    }
                    forger.reset_peer(&to);
                }
            }
            rounds.fetch_add(1, Ordering::SeqCst);
            std::thread::sleep(Duration::from_millis(300));
        }
    })
}

/// Goal group → the robots that visited it, from a team state's records.
fn visits(state: &TeamState) -> BTreeMap<GoalId, Vec<RobotId>> {
    let mut out: BTreeMap<GoalId, Vec<RobotId>> = BTreeMap::new();
    for r in state.records() {
        if let RecordKey::Visit { goal, robot } = &r.key {
            let group = state.goal(goal).map(|v| v.id.clone()).unwrap_or_else(|| goal.clone());
            out.entry(group).or_default().push(robot.clone());
        }
    }
    out
}

/// Stops the robot processes with SIGINT; their JSON reports.
fn stop_robots(robots: Vec<(&str, Reap)>) -> BTreeMap<String, serde_json::Value> {
    let mut out = BTreeMap::new();
    for (_, r) in &robots {
        let _ = Command::new("kill").args(["-INT", &r.0.id().to_string()]).status();
    }
    for (name, mut r) in robots {
        let _ = wait_with_timeout(&mut r.0, Duration::from_secs(20));
        let (stdout, stderr) = output(&mut r.0);
        let report =
            serde_json::from_str(&stdout).unwrap_or_else(|_| panic!("{name} printed no report:\n{stdout}\n{stderr}"));
        out.insert(name.to_string(), report);
    }
    out
}

/// The farm's summary and what it printed on stderr.
fn finish_farm(farm: &mut Reap, limit: Duration) -> (serde_json::Value, String) {
    let status = wait_with_timeout(&mut farm.0, limit);
    let (out, err) = output(&mut farm.0);
    let status = status.unwrap_or_else(|| panic!("the farm run did not end within {limit:?}:\n{err}"));
    assert!(status.success(), "spomp sim --ros2 failed ({status}):\n{out}\n{err}");
    (serde_json::from_str(&out).expect("sim prints its summary as JSON"), err)
}

#[test]
fn four_processes_complete_a_mission_over_the_signed_team_link_and_a_rogue_changes_nothing() {
    let team = Team::new("complete", domain(600));
    let robots: Vec<(&str, Reap)> = ROBOTS.iter().map(|r| (*r, team.start_robot(r, &[]))).collect();
    let stop = Arc::new(AtomicBool::new(false));
    let rounds = Arc::new(AtomicUsize::new(0));
    let rogue = start_rogue(&team, stop.clone(), rounds.clone());
    // The rogue's forgeries must reach the robots before the run ends, and a lockstep run is
    // over in seconds: the farm starts once a few rounds went out to a reachable team.
    let deadline = std::time::Instant::now() + Duration::from_secs(90);
    while rounds.load(Ordering::SeqCst) < 5 && std::time::Instant::now() < deadline {
        std::thread::sleep(Duration::from_millis(100));
    }
    assert!(rounds.load(Ordering::SeqCst) >= 5, "the rogue never reached the basestation");
    let mut farm = team.start_farm(&[]);

    let (summary, farm_err) = finish_farm(&mut farm, Duration::from_secs(400));
    stop.store(true, Ordering::SeqCst);
    let _ = rogue.join();
    let reports = stop_robots(robots);
    let trial = &summary["runs"][0];
    assert_eq!(trial["outcome"], "complete", "{summary:#}");
    assert_eq!(trial["goals_visited"], 3, "{summary:#}");

    // What every robot ended with: the three mission goals, no forged one; every visit by a
    // real UGV, and no goal visited twice.
    for robot in ROBOTS {
        let state = team.team_state(robot).unwrap_or_else(|| panic!("{robot}'s state file"));
        assert_eq!(state.goals().len(), 3, "{robot}: {:?}", state.goals());
        for (goal, by) in visits(&state) {
            let history: Vec<String> = state
                .records()
                .filter(|r| r.key.goal().is_some())
                .map(|r| format!("{:?} dot {} {:?}", r.key, r.dot, r.body))
                .collect();
            assert_eq!(by.len(), 1, "{robot}: goal {goal} visited by {by:?}\n{}", history.join("\n"));
            assert!(["ugv1", "ugv2"].contains(&by[0].as_str()), "{robot}: goal {goal} visited by {by:?}");
        }
    }
    // The forgeries arrived and were refused and counted, in ugv1's name and mallory's.
    let rejected: u64 = reports
        .values()
        .flat_map(|r| r["team_rejected"].as_object().into_iter().flatten().map(|(_, n)| n.as_u64().unwrap_or(0)))
        .sum();
    assert!(rejected > 0, "{reports:#?}");
    // mallory is no member: refused by the link and counted, never kept by name.
    assert!(reports["base"]["team_rejected_unknown_sender"].as_u64().unwrap_or(0) > 0, "{:#}", reports["base"]);
    assert!(reports["base"]["team_rejected"].get("mallory").is_none(), "{:#}", reports["base"]);
    for robot in ROBOTS {
        // Every message of a teammate checks (ugv1's name is the rogue's too).
        for teammate in ROBOTS.iter().filter(|r| **r != "ugv1") {
            assert!(
                reports[robot]["team_rejected"].get(teammate).is_none(),
                "{robot} refused {teammate}'s messages: {:#}",
                reports[robot]
            );
        }
    }
    // Every robot with a process is driven by it, the basestation too: the farm simulates no
    // phantom of it.
    assert!(farm_err.contains("driving base, uav1, ugv1, ugv2"), "{farm_err}");
    // Bytes per link and tier, for the note.
    eprintln!("ugv1's link: {:#}", reports["ugv1"]["team_link"]);
    eprintln!("mission time {:.0} s", trial["end_s"].as_f64().unwrap_or(0.0));
}

#[test]
fn a_killed_ugv_frees_its_goal_after_the_lease_and_resumes_from_its_state_file() {
    let team = Team::new("resume", domain(700));
    // At most 2× real time: the test watches the robots' state files on the wall clock, and a
    // run that ended before ugv2's reboot would leave nothing to rejoin.
    let mut farm = team.start_farm(&["--rate", "2"]);
    let mut robots: Vec<(&str, Reap)> = ROBOTS.iter().map(|r| (*r, team.start_robot(r, &[]))).collect();

    // Wait until ugv2 holds a goal (its state file says so), then kill it without warning.
    let start = Instant::now();
    let held = loop {
        assert!(start.elapsed() < Duration::from_secs(120), "ugv2 never held a goal");
        let claim = team.team_state("ugv2").and_then(|s| {
            s.goals().iter().find(|v| v.is_held_by(&RobotId::new("ugv2")) && v.visited.is_none()).map(|v| v.id.clone())
        });
        if let Some(g) = claim {
            break g;
        }
        std::thread::sleep(Duration::from_millis(200));
    };
    let (_, mut ugv2) = robots.remove(3);
    let _ = ugv2.0.kill();
    let _ = ugv2.0.wait();

    // ugv1 takes that goal once ugv2's lease has run out, and visits it.
    let start = Instant::now();
    let visitor = loop {
        assert!(start.elapsed() < Duration::from_secs(240), "goal {held} held by the dead ugv2 was never visited");
        let by = team.team_state("ugv1").and_then(|s| s.goal(&held).and_then(|v| v.visited.clone()));
        if let Some((_, robot)) = by {
            break robot;
        }
        std::thread::sleep(Duration::from_millis(250));
    };
    assert_eq!(visitor.as_str(), "ugv1");

    // ugv2 reboots: it resumes from its state file and re-converges with the team.
    let before = team.team_state("ugv2").expect("ugv2's state file survived");
    assert!(before.goal(&held).is_some_and(|v| v.visited.is_none()), "ugv2 died before learning of the visit");
    let restarted = Instant::now();
    let log = team.dir.join("ugv2-resumed.mcap");
    robots.push(("ugv2", team.start_robot("ugv2", &["--record", log.to_str().expect("utf-8 path")])));
    let converged = loop {
        assert!(restarted.elapsed() < Duration::from_secs(60), "ugv2 did not re-converge within 60 s");
        let views = |r: &str| {
            team.team_state(r)
                .map(|s| s.goals().iter().map(|v| (v.id.clone(), v.status, v.visited.clone())).collect::<Vec<_>>())
        };
        if let (Some(a), Some(b)) = (views("ugv2"), views("ugv1"))
            && a == b
            && a.iter().any(|(g, _, visited)| g == &held && visited.is_some())
        {
            break restarted.elapsed();
        }
        std::thread::sleep(Duration::from_millis(100));
    };
    eprintln!("ugv2 re-converged {converged:?} (wall) after its restart");
    let (summary, farm_err) = finish_farm(&mut farm, Duration::from_secs(400));
    let reports = stop_robots(robots);
    assert_eq!(summary["runs"][0]["outcome"], "complete", "{summary:#}");
    // The farm dropped ugv2 when its process died, and drove it again once it was back.
    assert!(farm_err.contains("ugv2 dropped at"), "{farm_err}");
    assert!(farm_err.contains("ugv2 rejoined at"), "{farm_err}");
    assert!(reports["ugv2"]["states_saved"].as_u64().unwrap_or(0) > 0, "{:#}", reports["ugv2"]);

    // The resumed, signing robot's log replays: the resume is a seam call, and with the team's
    // keys the replay signs its messages as the robot did.
    let replay =
        spomp().args(["replay"]).arg(&log).args(["--robot", "ugv2", "--json", "--keys"]).arg(team.keys()).output();
    let replay = replay.expect("replay runs");
    assert!(
        replay.status.success(),
        "the resumed robot's log does not replay:\n{}\n{}",
        String::from_utf8_lossy(&replay.stdout),
        String::from_utf8_lossy(&replay.stderr)
    );
    let without_keys = spomp().args(["replay"]).arg(&log).args(["--robot", "ugv2"]).output().expect("replay runs");
    assert!(!without_keys.status.success());
    assert!(String::from_utf8_lossy(&without_keys.stderr).contains("--keys"));
}

/// A robot's resume state carries its role's `persist` entries: a rebooted UAV continues its
/// survey at the waypoint it had reached. Another robot's state, or an entry the role does not
/// keep, is refused whole.
#[test]
fn a_resumed_uav_continues_its_survey_where_it_was() {
    use spomp_behaviors::mission::{LoadOptions, load_mission_with};
    let registry = spomp::registry();
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join(MISSION);
    let loaded = load_mission_with(&path, &registry, &LoadOptions::default());
    assert!(loaded.is_valid(), "{:#?}", loaded.diagnostics);
    let mission = loaded.mission.as_ref().expect("mission");
    let world = spomp_world::world_for_mission(mission, &loaded.base_dir(), 1).expect("world");
    let area = spomp_world::operating_area(mission, &world).expect("area");
    let make = |id: &str| spomp_robot::Robot::from_mission(&loaded, id, &area, 1, &registry).expect("robot");

    let state = make("uav1").resume_state();
    let (len, rest) = state.split_first_chunk::<4>().expect("framed");
    let (entries, team) = rest.split_at(u32::from_le_bytes(*len) as usize);
    assert_eq!(std::str::from_utf8(entries).expect("json"), r#"{"next_waypoint":0}"#);
    // As if it had reached waypoint 2 before the reboot.
    let reframe = |json: &str| {
        let mut out = (json.len() as u32).to_le_bytes().to_vec();
        out.extend_from_slice(json.as_bytes());
        out.extend_from_slice(team);
        out
    };
    let mut rebooted = make("uav1");
    rebooted.resume(Time::ZERO, reframe(r#"{"next_waypoint":2}"#)).expect("resume");
    assert!(rebooted.resume_state().windows(17).any(|w| w == br#"{"next_waypoint":"#), "entries kept");
    assert!(String::from_utf8_lossy(&rebooted.resume_state()).contains(r#""next_waypoint":2"#));

    assert!(make("uav1").resume(Time::ZERO, reframe(r#"{"speed":3}"#)).is_err(), "an entry the role does not keep");
    assert!(
        make("uav1").resume(Time::ZERO, reframe(r#"{"next_waypoint":"two"}"#)).is_err(),
        "a value of the wrong type"
    );
    assert!(make("ugv1").resume(Time::ZERO, reframe("{}")).is_err(), "the UAV's team state given to ugv1");
    assert!(make("uav1").resume(Time::ZERO, state[..state.len() / 2].to_vec()).is_err(), "cut short");
}

const OPERATOR_MISSION: &str = "tests/missions/ros2/farm-operator.yaml";
const OPERATOR_ROBOTS: [&str; 3] = ["base", "ugv1", "ugv2"];

/// `spomp operator` of `team` with the key folder `keys`, connecting to the basestation:
/// its exit code and its `--json` outcome.
fn operator(team: &Team, keys: &std::path::Path, args: &[&str]) -> (Option<i32>, serde_json::Value) {
    operator_waiting(team, keys, 30, args)
}

/// [`operator`] waiting at most `wait_s` wall seconds for the robots.
fn operator_waiting(
    team: &Team,
    keys: &std::path::Path,
    wait_s: u32,
    args: &[&str],
) -> (Option<i32>, serde_json::Value) {
    let out = spomp()
        .args(["operator", team.mission, "--keys"])
        .arg(keys)
        .args(["--connect", &format!("tcp/127.0.0.1:{}", team.ports["base"]), "--json"])
        .args(["--wait-s", &wait_s.to_string()])
        .args(args)
        .output()
        .expect("spomp operator runs");
    let stdout = String::from_utf8_lossy(&out.stdout);
    let value = serde_json::from_str(&stdout).unwrap_or_else(|_| {
        panic!("spomp operator {args:?} printed no JSON:\n{stdout}\n{}", String::from_utf8_lossy(&out.stderr))
    });
    (out.status.code(), value)
}

/// Waits (at most `limit` of wall time) until `found` finds something in `robot`'s state file.
fn wait_for<T>(team: &Team, robot: &str, limit: Duration, what: &str, found: impl Fn(&TeamState) -> Option<T>) -> T {
    let start = Instant::now();
    loop {
        if let Some(t) = team.team_state(robot).as_ref().and_then(&found) {
            return t;
        }
        assert!(start.elapsed() < limit, "{what}: not within {limit:?}");
        std::thread::sleep(Duration::from_millis(100));
    }
}

/// A key folder that claims to be the operator's but signs with ugv1's key: `team.json` lists
/// ugv1's public key as the operator's, `operator.key.json` holds ugv1's secret key (and the
/// operator's real transport password, so the link admits it). A compromised robot's key
/// trying to command the team.
fn robot_key_as_operator(team: &Team) -> PathBuf {
    let real = team.keys();
    let rogue = team.dir.join("rogue-operator-keys");
    std::fs::create_dir_all(&rogue).expect("rogue dir");
    let read = |name: &str| -> serde_json::Value {
        serde_json::from_str(&std::fs::read_to_string(real.join(name)).expect("key file")).expect("json")
    };
    let mut team_json = read("team.json");
    let ugv1_public = team_json["members"]["ugv1"].clone();
    team_json["operators"]["operator"] = ugv1_public;
    let mut operator_key = read("operator.key.json");
    operator_key["secret_key"] = read("ugv1.key.json")["secret_key"].clone();
    let write = |name: &str, text: String| {
        use std::os::unix::fs::PermissionsExt;
        let path = rogue.join(name);
        std::fs::write(&path, text).expect("write");
        std::fs::set_permissions(&path, std::fs::Permissions::from_mode(0o600)).expect("chmod");
    };
    write("team.json", team_json.to_string());
    write("operator.key.json", operator_key.to_string());
    write("transport.passwords", std::fs::read_to_string(real.join("transport.passwords")).expect("passwords"));
    rogue
}

/// Issue 37's acceptance, in a lockstep farm with the signed Zenoh link: the operator adds a
/// goal from the command line once the farm's clock has passed 300 s and a UGV claims and
/// visits it; a cancel while a UGV holds a goal makes it drop the claim at once (the release is
/// stamped no later than one sync round after the robot applied the cancel) and the goal is
/// never visited; `recall ugv2` brings ugv2 home; a command signed with a robot's key is
/// refused by every robot and counted; a point published from a viewer to the basestation's
/// live view (the stdlib Python Foxglove client) adds a goal the team sees.
///
/// Wall time only bounds the waits: the farm's speed is capped (`--rate 8`), and every check
/// is on the robots' own records and clocks.
#[test]
fn the_operator_adds_cancels_and_recalls_over_the_signed_link_and_a_robot_key_cannot_command() {
    let team = Team::of("operator", domain(800), OPERATOR_MISSION, &OPERATOR_ROBOTS);
    let live_port = free_port();
    let live = format!("127.0.0.1:{live_port}");
    // A robot the loaded machine keeps waiting is not dropped by the farm: the run would go on
    // without it.
    let mut farm = team.start_farm(&["--rate", "8", "--lockstep-timeout-s", "60"]);
    // ugv2 records its run: the operator's commands and its acknowledgements must be in its log.
    let ugv2_log = team.dir.join("ugv2-operator.mcap");
    let ugv2_log_arg = ugv2_log.to_str().expect("utf-8 path").to_string();
    let robots: Vec<(&str, Reap)> = OPERATOR_ROBOTS
        .iter()
        .map(|r| {
            let extra: Vec<&str> = match *r {
                "base" => vec!["--live", &live, "--live-operator"],
                "ugv2" => vec!["--record", &ugv2_log_arg],
                _ => Vec::new(),
            };
            (*r, team.start_robot(r, &extra))
        })
        .collect();
    let keys = team.keys();
    let (ugv1, ugv2) = (RobotId::new("ugv1"), RobotId::new("ugv2"));

    // t = 300 s of the farm's clock, as ugv1's records say.
    let t = wait_for(&team, "ugv1", Duration::from_secs(400), "the farm's clock passing 300 s", |s| {
        s.robot_pose(&ugv1).map(|(_, t)| t).filter(|t| t.as_secs_f64() >= 300.0)
    });
    eprintln!("operator acts at t = {:.1} s", t.as_secs_f64());

    // goal add: every robot acknowledges; a UGV claims and visits the goal.
    let (code, add) = operator(&team, &keys, &["goal", "add", "--at", "70,10", "--name", "east"]);
    assert_eq!(code, Some(0), "{add:#}");
    for r in OPERATOR_ROBOTS {
        assert!(add["acknowledged"].get(r).is_some(), "{r} did not acknowledge: {add:#}");
        assert!(add["acknowledged"][r].as_f64().unwrap_or(0.0) >= 300.0, "{add:#}");
    }
    let east = goal_id(&add);
    let visitor = wait_for(&team, "ugv1", Duration::from_secs(240), "the added goal visited", |s| {
        s.goal(&east).and_then(|g| g.visited.clone())
    });
    assert!(["ugv1", "ugv2"].contains(&visitor.1.as_str()), "{visitor:?}");
    assert!(visitor.0.as_secs_f64() > t.as_secs_f64(), "visited before it was added: {visitor:?}");

    // goal cancel while a UGV holds it.
    let (code, far) = operator(&team, &keys, &["goal", "add", "--at", "108,60", "--name", "far"]);
    assert_eq!(code, Some(0), "{far:#}");
    let far = goal_id(&far);
    let holder = wait_for(&team, "ugv1", Duration::from_secs(60), "a UGV claiming the far goal", |s| {
        s.goal(&far).and_then(|g| g.claimant.as_ref().map(|c| c.robot.clone()))
    });
    let (code, cancel) = operator(&team, &keys, &["goal", "cancel", "far"]);
    assert_eq!(code, Some(0), "{cancel:#}");
    let cancel_id = cancel["id"].as_str().expect("command id").to_string();
    // In the holder's own records: the acknowledgement of the cancel, and its claim released
    // no later than one sync round (1 s) after it.
    let holder_name: &'static str = if holder == ugv1 { "ugv1" } else { "ugv2" };
    let (acked_at, released_at) =
        wait_for(&team, holder_name, Duration::from_secs(60), "the holder's release of the cancelled goal", |s| {
            let acked = s
                .commands()
                .into_iter()
                .find(|c| c.id.to_string() == cancel_id)?
                .acked_by
                .into_iter()
                .find(|(r, _)| r == &holder)?
                .1;
            let released = s.records().find_map(|r| match (&r.key, &r.body) {
                (RecordKey::Claim { goal, claimant }, spomp_teamstate::RecordBody::Claim(c))
                    if goal == &far && claimant == &holder && !c.active =>
                {
                    Some(c.stamp)
                }
                _ => None,
            })?;
            Some((acked, released))
        });
    assert!(
        released_at.as_secs_f64() <= acked_at.as_secs_f64() + 1.0,
        "{holder} applied the cancel at {acked_at:?} but released its claim only at {released_at:?}"
    );

    // recall ugv2: it drives home (its start, 12,85) and stays.
    let home = Point2::new(12.0, 85.0);
    let away = team.team_state("ugv2").and_then(|s| s.robot_pose(&ugv2)).map(|(p, _)| p.position().distance(home));
    assert!(away.is_some_and(|d| d > 10.0), "ugv2 is home already ({away:?} m): the recall would prove nothing");
    let (code, recall) = operator(&team, &keys, &["recall", "ugv2"]);
    assert_eq!(code, Some(0), "{recall:#}");
    assert_eq!(recall["acknowledged"].as_object().map(|o| o.len()), Some(1), "only ugv2 is concerned: {recall:#}");
    wait_for(&team, "ugv2", Duration::from_secs(120), "ugv2 home after the recall", |s| {
        s.robot_pose(&ugv2).filter(|(p, _)| p.position().distance(home) < 3.0)
    });

    // A command signed with ugv1's key: nobody applies it, every robot refuses and counts it.
    let rogue = robot_key_as_operator(&team);
    let (code, forged) = operator_waiting(&team, &rogue, 5, &["hold", "all"]);
    assert_eq!(code, Some(2), "{forged:#}");
    assert_eq!(forged["acknowledged"].as_object().map(|o| o.len()), Some(0), "{forged:#}");

    // A point published to the basestation's live view, as Foxglove's 3-D panel does.
    let python = Command::new("python3").arg("--version").output().is_ok_and(|o| o.status.success());
    if python {
        let out = Command::new("python3")
            .arg("scripts/foxglove-publish-point.py")
            .arg(format!("ws://{live}"))
            .args(["62", "50"])
            .current_dir(env!("CARGO_MANIFEST_DIR"))
            .output()
            .expect("python3 runs");
        assert_eq!(out.status.code(), Some(0), "{}", String::from_utf8_lossy(&out.stdout));
        wait_for(&team, "ugv1", Duration::from_secs(60), "the viewer's goal reaching ugv1", |s| {
            s.goals().iter().find(|g| g.position.distance(Point2::new(62.0, 50.0)) < 0.5).map(|g| g.id.clone())
        });
    } else {
        eprintln!("no python3: the viewer's part skipped");
    }

    // The status the operator sees at the end.
    let (code, status) = operator(&team, &keys, &["status"]);
    assert_eq!(code, Some(0), "{status:#}");
    let modes: BTreeMap<String, String> = status["robots"]
        .as_array()
        .into_iter()
        .flatten()
        .map(|r| (r["robot"].as_str().unwrap_or("").to_string(), r["mode"].as_str().unwrap_or("").to_string()))
        .collect();
    assert_eq!(modes.get("ugv2").map(String::as_str), Some("recall"), "{status:#}");
    assert_eq!(modes.get("ugv1").map(String::as_str), Some("mission"), "the forged hold held nobody: {status:#}");

    let _ = Command::new("kill").args(["-INT", &farm.0.id().to_string()]).status();
    let _ = wait_with_timeout(&mut farm.0, Duration::from_secs(30));
    let reports = stop_robots(robots);
    for robot in OPERATOR_ROBOTS {
        let refused = reports[robot]["team_rejected_by_kind"]["bad_signature"].as_u64().unwrap_or(0);
        assert!(refused > 0, "{robot} did not count the forged command: {:#}", reports[robot]);
    }
    // ugv2's log: each command it heard, and its own acknowledgement of the recall, on
    // /team/events as the simulator writes them.
    let log = spomp_mcap::read_replay_log(&std::fs::read(&ugv2_log).expect("ugv2's log")).expect("ugv2's log reads");
    let events: Vec<serde_json::Value> = log
        .messages
        .iter()
        .filter(|m| m.topic == "/team/events")
        .map(|m| {
            let msg: spomp_ros_msgs::StringMsg = spomp_mcap::decode_cdr(&m.topic, &m.data).expect("a string message");
            serde_json::from_str(&msg.data).expect("JSON")
        })
        .collect();
    let recall_id = recall["id"].as_str().expect("command id");
    let has = |event: &str, robot: &str| {
        events.iter().any(|e| e["event"] == event && e["command"] == recall_id && e["robot"] == robot)
    };
    assert!(has("operator_command_heard", "ugv2"), "the recall is not in ugv2's log: {events:#?}");
    assert!(has("operator_acknowledged", "ugv2"), "ugv2's acknowledgement is not in its log: {events:#?}");
    for kind in ["goal_add", "goal_cancel", "recall"] {
        assert!(events.iter().any(|e| e["kind"] == kind), "no {kind} command in ugv2's log: {events:#?}");
    }

    // The far goal was never visited, by anyone's records.
    for robot in OPERATOR_ROBOTS {
        let state = team.team_state(robot).unwrap_or_else(|| panic!("{robot}'s state file"));
        let g = state.goal(&far).unwrap_or_else(|| panic!("{robot} does not know the far goal"));
        assert!(g.visited.is_none() && g.cancelled.is_some(), "{robot}: {g:?}");
    }
}

/// The goal an `goal add` outcome's command added (`operator/<seq>`).
fn goal_id(outcome: &serde_json::Value) -> GoalId {
    let id = outcome["id"].as_str().unwrap_or_else(|| panic!("no command id: {outcome:#}"));
    let (operator, seq) = id.split_once('#').unwrap_or_else(|| panic!("command id `{id}`"));
    GoalId { origin: RobotId::new(operator), seq: seq.parse().unwrap_or_else(|_| panic!("command id `{id}`")) }
}
