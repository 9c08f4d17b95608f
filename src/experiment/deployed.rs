//! A trial run as robots run it (`spomp experiment --deployed`, a configuration's `deployed:`):
//! the simulator as a lockstep robot farm in this process, and one `spomp run --lockstep`
//! process per robot of the team, children of this one, over loopback.
//!
//! Each trial has its own DDS domain id (one no other process on this machine uses) and, over
//! the Zenoh link, its own ports and freshly generated keys, so trials run side by side
//! (`--jobs`) without hearing each other. The farm's clock waits for every robot's answer, so
//! the machine's load slows a trial down without changing it; over the farm's radio model the
//! row is the in-process row, field for field but wall time.
//!
//! A robot process that does not report, stops answering (dies or hangs) or does not exit is
//! reported in the row (`process_problems`) and killed; it is never waited on for ever. The
//! processes are killed and reaped however the trial ends (Ctrl-C, an error, a panic).

use std::collections::{BTreeMap, BTreeSet};
use std::io::Read;
use std::net::{IpAddr, Ipv4Addr, TcpListener, UdpSocket};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use anyhow::{Context, Result, bail};
use spomp_behaviors::NodeRegistry;
use spomp_core::{FlightCommand, GridSpec, MapTile, Odometry, PanoramaFrame, PoseEstimate, RobotId, Time, Twist2};
use spomp_robot::RobotRuntime;
use spomp_sim::run::{DrivenStep, DrivenTeamMessage, ExternalDrivers, Outcome, SimOptions, Simulation};
use spomp_teamstate::{GoalView, TierSet};

use super::rows::{self, ByteCounter, TrialRow};
use super::spec::{ResolvedConfiguration, TeamChannel, Trial};
use crate::farm_cmd::{FarmDrivers, FarmOptions, LockstepOptions};

/// How long the farm waits for every robot process to say it is ready, wall seconds: each
/// process loads the mission and builds the world first, several at once on a loaded machine.
const START_WAIT_S: f64 = 180.0;
/// A robot process that does not answer a lockstep call within this long is dropped from the
/// run (its body stops) and named in the row, wall seconds.
const LOCKSTEP_TIMEOUT_S: f64 = 30.0;
/// How long the robot processes may take to exit once the farm ended the run.
const EXIT_WAIT: Duration = Duration::from_secs(20);

/// Where a deployed trial's processes find what they need.
pub struct Deployment<'a> {
    /// Folders besides the mission's own its files may be in (the experiment's, `--allow-dir`).
    pub allow_dirs: &'a [PathBuf],
    /// Folder under which each trial gets a working folder (mission, keys, process output);
    /// a trial's folder is removed when it ran without a problem.
    pub work_dir: &'a Path,
}

/// DDS domain ids held by this process's running trials.
static DOMAINS: Mutex<BTreeSet<u16>> = Mutex::new(BTreeSet::new());
/// Zenoh ports handed to this process's running trials.
static PORTS: Mutex<BTreeSet<u16>> = Mutex::new(BTreeSet::new());

/// A DDS domain id a trial holds until it ends.
struct DomainLease(u16);

impl DomainLease {
    /// A domain id no trial of this process holds and no participant on this machine uses
    /// (from a start that depends on the process, so two experiments rarely probe alike).
    fn take() -> Result<DomainLease> {
        let mut held = DOMAINS.lock().map_err(|_| anyhow::anyhow!("a trial thread panicked"))?;
        let start = (std::process::id() % 200) as u16;
        for k in 0..232u16 {
            let d = 1 + (start + k) % 232;
            if !held.contains(&d) && domain_unused(d) {
                held.insert(d);
                return Ok(DomainLease(d));
            }
        }
        bail!("no free DDS domain id on this machine (every one of 1–232 is in use)")
    }
}

impl Drop for DomainLease {
    fn drop(&mut self) {
        if let Ok(mut held) = DOMAINS.lock() {
            held.remove(&self.0);
        }
    }
}

/// Whether no DDS participant of domain `d` runs on this machine: the first participant of a
/// domain takes its well-known discovery port (RTPS: 7400 + 250 d + 10), so if that port can
/// be bound, nobody is there.
fn domain_unused(d: u16) -> bool {
    let port = 7410 + 250 * u32::from(d);
    u16::try_from(port).is_ok_and(|p| UdpSocket::bind((Ipv4Addr::UNSPECIFIED, p)).is_ok())
}

/// Loopback TCP ports a trial's Zenoh link listens on, released when it ends.
struct PortLease(Vec<u16>);

impl PortLease {
    /// `n` ports free now and not handed to another trial of this process.
    fn take(n: usize) -> Result<PortLease> {
        let mut held = PORTS.lock().map_err(|_| anyhow::anyhow!("a trial thread panicked"))?;
        let mut ports = Vec::new();
        for _ in 0..n * 20 {
            if ports.len() == n {
                break;
            }
            let port = TcpListener::bind((Ipv4Addr::LOCALHOST, 0))
                .and_then(|l| l.local_addr())
                .context("finding a free loopback port")?
                .port();
            if held.insert(port) {
                ports.push(port);
            }
        }
        if ports.len() < n {
            for p in &ports {
                held.remove(p);
            }
            bail!("could not find {n} free loopback ports for the team link");
        }
        Ok(PortLease(ports))
    }
}

impl Drop for PortLease {
    fn drop(&mut self) {
        if let Ok(mut held) = PORTS.lock() {
            for p in &self.0 {
                held.remove(p);
            }
        }
    }
}

/// One robot's `spomp run` process.
struct RobotProcess {
    id: String,
    child: Child,
    /// Where its standard output (the JSON report) goes.
    report: PathBuf,
    /// Where its standard error goes.
    log: PathBuf,
}

/// The trial's robot processes: killed and reaped when dropped, however the trial ends.
struct Processes(Vec<RobotProcess>);

impl Drop for Processes {
    fn drop(&mut self) {
        for p in &mut self.0 {
            let _ = p.child.kill();
            let _ = p.child.wait();
        }
    }
}

impl Processes {
    /// Waits (at most [`EXIT_WAIT`] in all) for the processes to exit after the run's end;
    /// those that do not are killed. Each robot's JSON report, when it printed one; what went
    /// wrong goes to `problems`.
    fn finish(mut self, problems: &mut Vec<String>) -> BTreeMap<String, serde_json::Value> {
        let deadline = Instant::now() + EXIT_WAIT;
        let mut reports = BTreeMap::new();
        for p in &mut self.0 {
            let status = loop {
                match p.child.try_wait() {
                    Ok(Some(status)) => break Some(status),
                    Ok(None) if Instant::now() < deadline => std::thread::sleep(Duration::from_millis(50)),
                    _ => break None,
                }
            };
            match status {
                None => {
                    let _ = p.child.kill();
                    let _ = p.child.wait();
                    problems.push(format!("{}'s process did not exit after the run ended: killed", p.id));
                }
                Some(s) if !s.success() => {
                    problems.push(format!("{}'s process exited with {s}: {}", p.id, last_line(&p.log)));
                }
                Some(_) => {}
            }
            let text = std::fs::read_to_string(&p.report).unwrap_or_default();
            match serde_json::from_str::<serde_json::Value>(&text) {
                Ok(report) => {
                    reports.insert(p.id.clone(), report);
                }
                Err(_) if status.is_some_and(|s| s.success()) => {
                    problems.push(format!("{}'s process printed no report", p.id));
                }
                Err(_) => {}
            }
        }
        reports
    }
}

/// The last non-empty line of a process's standard error (clipped), for a row.
fn last_line(path: &Path) -> String {
    let mut text = String::new();
    if let Ok(f) = std::fs::File::open(path) {
        let _ = f.take(1 << 20).read_to_string(&mut text);
    }
    let line = text.lines().rev().find(|l| !l.trim().is_empty()).unwrap_or("(no output)").trim();
    line.chars().take(300).collect()
}

/// The farm, counting the team-state bytes the driven robots send over its radio model (the
/// simulator's observer sees only its own robots' messages).
struct CountingFarm {
    farm: FarmDrivers,
    bytes: Arc<Mutex<ByteCounter>>,
}

impl ExternalDrivers for CountingFarm {
    fn drives(&self, robot: &RobotId) -> bool {
        self.farm.drives(robot)
    }
    fn begin_step(&mut self, now: Time) {
        self.farm.begin_step(now);
    }
    fn odometry(&mut self, robot: &RobotId, odom: &Odometry) {
        self.farm.odometry(robot, odom);
    }
    fn panorama(&mut self, robot: &RobotId, frame: &PanoramaFrame) {
        self.farm.panorama(robot, frame);
    }
    fn pose(&mut self, robot: &RobotId, estimate: &PoseEstimate, z_m: f64) {
        self.farm.pose(robot, estimate, z_m);
    }
    fn camera_tiles(&mut self, robot: &RobotId, now: Time, tiles: &[MapTile], grid: &GridSpec) {
        self.farm.camera_tiles(robot, now, tiles, grid);
    }
    fn command(&mut self, robot: &RobotId, now: Time) -> Option<Twist2> {
        self.farm.command(robot, now)
    }
    fn flight(&mut self, robot: &RobotId, now: Time) -> Option<FlightCommand> {
        self.farm.flight(robot, now)
    }
    fn take_team_messages(&mut self) -> Vec<DrivenTeamMessage> {
        self.farm.take_team_messages()
    }
    fn deliver_team_message(&mut self, to: &RobotId, from: &RobotId, bytes: &[u8]) {
        self.farm.deliver_team_message(to, from, bytes);
    }
    fn goals(&self, robot: &RobotId) -> &[GoalView] {
        self.farm.goals(robot)
    }
    fn tree_done(&self, robot: &RobotId) -> bool {
        self.farm.tree_done(robot)
    }
    fn lockstep(&self) -> bool {
        self.farm.lockstep()
    }
    fn exchange_work(&mut self, robot: &RobotId, now: Time) {
        self.farm.exchange_work(robot, now);
    }
    fn team_message_for(
        &mut self,
        robot: &RobotId,
        to: &RobotId,
        tiers: TierSet,
        budget_bytes: usize,
    ) -> Option<Vec<u8>> {
        let sent = self.farm.team_message_for(robot, to, tiers, budget_bytes);
        if let (Some(bytes), Ok(mut counter)) = (sent.as_deref(), self.bytes.lock()) {
            counter.count(robot, tiers, bytes);
        }
        sent
    }
    fn tick(&mut self, robot: &RobotId, now: Time) {
        self.farm.tick(robot, now);
    }
    fn end_step(&mut self, now: Time) {
        self.farm.end_step(now);
    }
    fn step_of(&self, robot: &RobotId) -> Option<&DrivenStep> {
        self.farm.step_of(robot)
    }
    fn halt(&mut self, robot: &RobotId, now: Time) {
        self.farm.halt(robot, now);
    }
    fn tree_status(&self, robot: &RobotId) -> Option<String> {
        self.farm.tree_status(robot)
    }
    fn end_run(&mut self) {
        self.farm.end_run();
    }
    fn joined(&mut self) -> Vec<RobotId> {
        self.farm.joined()
    }
}

/// Adds the team-state bytes each robot process's Zenoh link reports having sent (every tier
/// over every link: the link has no range) to `bytes`.
fn count_link_bytes(reports: &BTreeMap<String, serde_json::Value>, bytes: &mut ByteCounter) {
    for (robot, report) in reports {
        let Some(peers) = report.pointer("/team_link/sent").and_then(|v| v.as_object()) else { continue };
        for tiers in peers.values().filter_map(|t| t.as_object()) {
            for (tier, counts) in tiers {
                let b = counts.get("bytes").and_then(serde_json::Value::as_u64).unwrap_or(0);
                *bytes.full.entry(robot.clone()).or_default() += b;
                let k = match tier.as_str() {
                    "scans" => 1,
                    "maps" => 2,
                    _ => 0,
                };
                bytes.by_tier[k] += b;
            }
        }
    }
}

/// Runs `trial` deployed over its team channel; `None` when a signal cut it short.
pub fn run_deployed_trial(
    trial: &Trial,
    configuration: &ResolvedConfiguration,
    hash: &str,
    registry: &NodeRegistry<RobotRuntime>,
    deployment: &Deployment<'_>,
    interrupted: &AtomicBool,
) -> Result<Option<TrialRow>> {
    let started = Instant::now();
    let Some(channel) = trial.deployed else { bail!("not a deployed trial") };
    let loaded = &configuration.loaded;
    let Some(mission) = loaded.mission.as_ref() else { bail!("the mission did not load") };
    let dir = deployment.work_dir.join(format!("{}-seed{}-{channel}", configuration.name, trial.seed));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).with_context(|| format!("creating {}", dir.display()))?;
    let mission_path = dir.join("mission.json");
    crate::output::write(&mission_path, configuration.patched.as_bytes())?;
    let ids: Vec<String> = mission.team.iter().map(|r| r.id.clone()).collect();
    let domain = DomainLease::take()?;
    let ports = match channel {
        TeamChannel::Zenoh => Some(PortLease::take(ids.len())?),
        TeamChannel::Radio => None,
    };
    let keys = dir.join("keys");
    if channel == TeamChannel::Zenoh {
        let robots: Vec<RobotId> = ids.iter().map(|id| RobotId::new(id)).collect();
        spomp_zenoh::KeyDir::generate(&keys, &mission.mission, &robots)
            .with_context(|| format!("generating the team's keys in {}", keys.display()))?;
    }
    let exe = std::env::current_exe().context("finding the spomp executable")?;
    let mut processes = Processes(Vec::new());
    for (i, id) in ids.iter().enumerate() {
        let mut cmd = Command::new(&exe);
        cmd.arg("run")
            .arg(&mission_path)
            .args(["--robot", id.as_str(), "--lockstep", "--json", "--interface", "127.0.0.1"])
            .args(["--seed", &trial.seed.to_string(), "--domain-id", &domain.0.to_string()])
            .arg("--resolve-in")
            .arg(loaded.base_dir());
        for d in deployment.allow_dirs {
            cmd.arg("--allow-dir").arg(d);
        }
        if let Some(ports) = &ports {
            // Each robot listens on its port and connects to every robot before it: a full
            // mesh on loopback, whatever order the processes come up in.
            cmd.arg("--keys").arg(&keys).args(["--listen", &format!("tcp/127.0.0.1:{}", ports.0[i])]);
            for p in &ports.0[..i] {
                cmd.args(["--connect", &format!("tcp/127.0.0.1:{p}")]);
            }
        }
        let report = dir.join(format!("{id}.json"));
        let log = dir.join(format!("{id}.log"));
        let out = std::fs::File::create(&report).with_context(|| format!("creating {}", report.display()))?;
        let err = std::fs::File::create(&log).with_context(|| format!("creating {}", log.display()))?;
        let child = cmd
            .env("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
            .env_remove("ROS_DOMAIN_ID")
            .stdin(Stdio::null())
            .stdout(out)
            .stderr(err)
            .spawn()
            .with_context(|| format!("starting {id}'s process ({})", exe.display()))?;
        processes.0.push(RobotProcess { id: id.clone(), child, report, log });
    }
    let world = spomp_world::world_for_mission(mission, &loaded.base_dir(), trial.seed)
        .with_context(|| format!("building the world of `{}`", mission.mission))?;
    // As the in-process trial runs (so that over the radio model the rows are equal).
    let options = SimOptions { seed: trial.seed, ..SimOptions::default() };
    let skill_latency = options.skill_latency;
    let mut sim = Simulation::new(loaded, registry, Arc::new(world), options)
        .with_context(|| format!("setting up `{}`", mission.mission))?;
    let notes = Arc::new(Mutex::new(Vec::new()));
    let farm = FarmDrivers::new(
        mission,
        &FarmOptions {
            rate: None,
            domain_id: Some(domain.0),
            interfaces: vec![IpAddr::from(Ipv4Addr::LOCALHOST)],
            drive: ids.clone(),
            wait_s: START_WAIT_S,
            lockstep: Some(LockstepOptions { seed: trial.seed, skill_latency, timeout_s: LOCKSTEP_TIMEOUT_S }),
            notes: Some(notes.clone()),
        },
    )?;
    let radio_bytes = Arc::new(Mutex::new(ByteCounter::default()));
    sim.drive_externally(Box::new(CountingFarm { farm, bytes: radio_bytes.clone() }))
        .context("handing the robots to the farm")?;
    let result = sim.run_until(&mut rows::TrialObserver, &mut || interrupted.load(Ordering::Relaxed));
    if result.summary.outcome == Outcome::Interrupted {
        return Ok(None);
    }
    // The simulator's own robots counted what they sent; the farm's, what its radio carried.
    let mut bytes = ByteCounter::of_robots(&result.team_traffic);
    let mut problems: Vec<String> = notes.lock().map(|n| n.clone()).unwrap_or_default();
    let reports = processes.finish(&mut problems);
    match channel {
        TeamChannel::Radio => {
            if let Ok(radio) = radio_bytes.lock() {
                bytes.add(&radio);
            }
        }
        TeamChannel::Zenoh => count_link_bytes(&reports, &mut bytes),
    }
    drop((domain, ports));
    let mut row = rows::row_of(trial.index, &configuration.name, hash, &result.summary, &bytes);
    row.deployed = Some(channel);
    row.wall_s = started.elapsed().as_secs_f64();
    if problems.is_empty() {
        let _ = std::fs::remove_dir_all(&dir);
    } else {
        problems.push(format!("the processes' output is in {}", dir.display()));
    }
    row.process_problems = problems;
    Ok(Some(row))
}
