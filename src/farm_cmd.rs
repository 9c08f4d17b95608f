//! `spomp sim --ros2`: the simulator as a ROS 2 robot farm. The simulator moves the bodies and
//! renders the sensors; `spomp run` processes (one per robot that has one) decide what the robots
//! do, and the simulator runs the others itself.
//!
//! Two ways to keep time: paced (the default; simulated time runs at real time × `--rate`, the
//! processes take it from `/clock`, and what they do depends on how fast their machine is), and
//! lockstep (`--lockstep`; each step waits for every robot's answer, and the run is the one
//! `spomp sim` makes with the robots inside it — see `spomp_ros2::lockstep`).

use std::collections::{BTreeMap, BTreeSet};
use std::net::IpAddr;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use anyhow::{Context, Result, bail};
use spomp_behaviors::mission::{MissionFile, MissionSection};
use spomp_core::{
    FlightCommand, GridSpec, MapTile, Odometry, OdometryCovariance, PanoramaFrame, PoseEstimate, RobotId, Time, Twist2,
};
use spomp_ros2::lockstep::{Hello, LockstepError, Op, PROTOCOL, StepDone};
use spomp_ros2::{DdsSettings, FarmLink};
use spomp_sim::run::{DrivenStep, DrivenTeamMessage, ExternalDrivers, RealTimePacer, SkillLatency};
use spomp_teamstate::{GoalView, TierSet};

/// How the farm runs.
#[derive(Debug, Clone)]
pub struct FarmOptions {
    /// Simulated seconds per wall second; `None`: 1 when paced, as fast as the robots answer in
    /// lockstep.
    pub rate: Option<f64>,
    /// DDS domain (default: the first driven robot's `ros2.domain_id`).
    pub domain_id: Option<u16>,
    /// Interfaces DDS may use (empty: every one).
    pub interfaces: Vec<IpAddr>,
    /// Robots that may be driven (empty: every robot of the team).
    pub drive: Vec<String>,
    /// How long to wait for the `spomp run` processes before the clock starts, wall seconds.
    pub wait_s: f64,
    /// Run in lockstep with the robots' processes.
    pub lockstep: Option<LockstepOptions>,
    /// Where the farm's messages (robots driven, absent, dropped, joined) go: this list when
    /// given (`spomp experiment --deployed` puts them in the trial's row), else stderr.
    pub notes: Option<Arc<Mutex<Vec<String>>>>,
}

/// Says the farm's messages where [`FarmOptions::notes`] asks.
#[derive(Debug, Clone, Default)]
struct Notes(Option<Arc<Mutex<Vec<String>>>>);

impl Notes {
    fn say(&self, message: String) {
        match &self.0 {
            Some(list) => {
                if let Ok(mut l) = list.lock() {
                    l.push(message);
                }
            }
            None => errln!("{message}"),
        }
    }
}

/// The lockstep's settings.
#[derive(Debug, Clone)]
pub struct LockstepOptions {
    /// The run's seed (the robots' must be the same).
    pub seed: u64,
    /// The simulator's skill-latency model, which the robots follow.
    pub skill_latency: Option<SkillLatency>,
    /// A robot that does not answer a call within this long is reported and dropped, wall
    /// seconds.
    pub timeout_s: f64,
}

/// The lockstep state of the farm.
struct Lockstep {
    timeout: Duration,
    /// Each driven robot's answer to the step's tick, once it came.
    steps: BTreeMap<String, DrivenStep>,
    /// Each driven robot's latest answer.
    last: BTreeMap<String, StepDone>,
    /// Robots told to tick this step.
    ticking: Vec<String>,
    /// Robots that stopped answering: their bodies stop, nothing more is asked of them until
    /// their process answers a hello again.
    dropped: BTreeSet<String>,
    /// What the farm says to a robot that (re)joins.
    hello: Hello,
    /// When the dropped robots were last said hello to.
    last_hello: Instant,
}

/// What a robot dropped from the lockstep does: nothing.
static STOPPED: DrivenStep = DrivenStep {
    ticked: true,
    command: None,
    estimate_after_panorama: None,
    estimate: None,
    transitioned: Vec::new(),
    problems: Vec::new(),
};

/// The farm's side of the simulation.
pub struct FarmDrivers {
    link: FarmLink,
    driven: Vec<String>,
    /// Robots the farm may drive whose process has not reported: the simulator runs them until
    /// it does.
    absent: Vec<String>,
    /// Robots whose process reported late, for the simulator to hand over.
    joined: Vec<RobotId>,
    /// Real time × rate, from the first step.
    pacer: Option<RealTimePacer>,
    lockstep: Option<Lockstep>,
    /// The step's simulated time.
    now: Time,
    notes: Notes,
}

impl FarmDrivers {
    /// A farm for `mission`: waits (at most `wait_s`) for the `spomp run` process of each robot it
    /// may drive, and drives those that reported; the simulator runs the others.
    pub fn new(mission: &MissionFile, options: &FarmOptions) -> Result<Self> {
        let candidates: Vec<String> = if options.drive.is_empty() {
            mission.team.iter().map(|r| r.id.clone()).collect()
        } else {
            options.drive.clone()
        };
        let mut robots: Vec<(String, Option<spomp_ros2::Ros2Spec>)> = Vec::with_capacity(candidates.len());
        for id in &candidates {
            let spec = match mission.team.iter().find(|r| &r.id == id) {
                Some(r) if spomp_ros2::Ros2Spec::given_for(r) => Some(spomp_ros2::Ros2Spec::of_robot(r)?),
                _ => None,
            };
            robots.push((id.clone(), spec));
        }
        let first = robots.iter().find_map(|(_, s)| s.clone()).unwrap_or_default();
        let mut dds = DdsSettings::for_robot(&first).map_err(anyhow::Error::msg)?;
        if let Some(d) = options.domain_id {
            dds.domain_id = d;
        }
        if !options.interfaces.is_empty() {
            dds.interfaces = options.interfaces.clone();
        }
        let mut link =
            FarmLink::new(&dds, &robots, options.lockstep.is_some()).context("starting the farm's ROS 2 node")?;
        let how = match (&options.lockstep, options.rate) {
            (Some(_), None) => "in lockstep, as fast as the robots answer".to_string(),
            (Some(_), Some(rate)) => format!("in lockstep, at most {rate}× real time"),
            (None, rate) => format!("at {}× real time", rate.unwrap_or(1.0)),
        };
        let notes = Notes(options.notes.clone());
        if notes.0.is_none() {
            errln!(
                "spomp sim --ros2: waiting up to {:.0} s for the processes of {} on DDS domain {} ({how}); start `spomp run MISSION --robot ID {}` for each",
                options.wait_s,
                candidates.join(", "),
                dds.domain_id,
                if options.lockstep.is_some() { "--lockstep" } else { "--use-sim-time" },
            );
            if !dds.interfaces.is_empty() {
                let ports = dds.rtps_ports();
                errln!(
                    "note: {} (this domain: ports {}-{})",
                    spomp_ros2::dds::RECEIVE_ON_ALL_INTERFACES,
                    ports.start(),
                    ports.end()
                );
            }
        }
        let wait = Duration::from_secs_f64(options.wait_s);
        let driven: Vec<String> = match &options.lockstep {
            Some(l) => {
                let hello = Hello {
                    protocol: PROTOCOL,
                    seed: l.seed,
                    skill_latency_s: l.skill_latency.map(|s| (s.perception_s, s.planner_s)),
                };
                let mut ready = Vec::new();
                for (id, answer) in link.connect_lockstep(&hello, wait) {
                    match answer {
                        Ok(()) => ready.push(id),
                        Err(LockstepError::Refused(why)) => bail!("{why}"),
                        Err(_) => {}
                    }
                }
                ready
            }
            None => wait_for_status(&mut link, &candidates, wait),
        };
        let absent: Vec<String> = candidates.iter().filter(|c| !driven.contains(c)).cloned().collect();
        let simulated: Vec<&str> = absent.iter().map(String::as_str).collect();
        if !simulated.is_empty() {
            notes.say(format!(
                "spomp sim --ros2: no process reported for {} within {:.0} s: the simulator runs {} until {} does",
                simulated.join(", "),
                options.wait_s,
                if simulated.len() == 1 { "it" } else { "them" },
                if simulated.len() == 1 { "it" } else { "one" }
            ));
        }
        if notes.0.is_none() {
            errln!(
                "spomp sim --ros2: driving {}",
                if driven.is_empty() { "no robot".into() } else { driven.join(", ") }
            );
        }
        let pacer = match (&options.lockstep, options.rate) {
            (Some(_), None) => None,
            (_, rate) => Some(RealTimePacer::new(rate.unwrap_or(1.0))),
        };
        let lockstep = options.lockstep.as_ref().map(|l| Lockstep {
            timeout: Duration::from_secs_f64(l.timeout_s),
            steps: BTreeMap::new(),
            last: BTreeMap::new(),
            ticking: Vec::new(),
            dropped: BTreeSet::new(),
            hello: Hello {
                protocol: PROTOCOL,
                seed: l.seed,
                skill_latency_s: l.skill_latency.map(|s| (s.perception_s, s.planner_s)),
            },
            last_hello: Instant::now(),
        });
        Ok(FarmDrivers { link, driven, absent, joined: Vec::new(), pacer, lockstep, now: Time::ZERO, notes })
    }

    /// Whether `id` is in lockstep and still answering.
    fn answering(&self, id: &str) -> bool {
        self.lockstep.as_ref().is_some_and(|l| !l.dropped.contains(id))
    }

    fn call(&mut self, id: &RobotId, op: Op) {
        if self.answering(id.as_str()) {
            self.link.lockstep_call(id.as_str(), op);
        }
    }

    /// A robot stopped answering: reported, and driven no more (its body stops).
    fn drop_robot(&mut self, id: &str, now: Time, why: &LockstepError) {
        self.notes.say(format!(
            "spomp sim --ros2 --lockstep: {id} dropped at {:.1} s ({why}); its body stops and the run goes on",
            now.as_secs_f64()
        ));
        if let Some(l) = self.lockstep.as_mut() {
            l.dropped.insert(id.to_string());
            l.steps.remove(id);
        }
    }

    /// Says hello to the dropped robots and those that never reported (twice a wall second): a
    /// process that answers (restarted, back, or late) is driven from this step on.
    fn rejoin_dropped(&mut self, now: Time) {
        let Some(l) = self.lockstep.as_mut() else { return };
        if (l.dropped.is_empty() && self.absent.is_empty()) || l.last_hello.elapsed() < Duration::from_millis(500) {
            return;
        }
        l.last_hello = Instant::now();
        for id in l.dropped.clone() {
            if self.link.lockstep_rejoin(&id, &l.hello) {
                l.dropped.remove(&id);
                self.notes.say(format!("spomp sim --ros2 --lockstep: {id} rejoined at {:.1} s", now.as_secs_f64()));
            }
        }
        let hello = l.hello.clone();
        for id in std::mem::take(&mut self.absent) {
            if self.link.lockstep_rejoin(&id, &hello) {
                self.join(id, now);
            } else {
                self.absent.push(id);
            }
        }
    }

    /// A process reported late: it drives its robot from this step on.
    fn join(&mut self, id: String, now: Time) {
        self.notes.say(format!(
            "spomp sim --ros2: {id}'s process reported at {:.1} s: it drives {id} from now on",
            now.as_secs_f64()
        ));
        self.joined.push(RobotId::new(&id));
        self.driven.push(id);
    }

    fn last(&self, id: &str) -> Option<&StepDone> {
        self.lockstep.as_ref().and_then(|l| l.last.get(id))
    }
}

/// Publishes `/clock` at zero until every candidate reports its status or `wait` passes; the
/// robots that reported.
fn wait_for_status(link: &mut FarmLink, candidates: &[String], wait: Duration) -> Vec<String> {
    let deadline = Instant::now() + wait;
    loop {
        link.publish_clock(Time::ZERO);
        link.poll(Time::ZERO);
        let all = candidates.iter().all(|id| !link.tree_status(id).is_empty());
        if all || Instant::now() >= deadline {
            return candidates.iter().filter(|id| !link.tree_status(id).is_empty()).cloned().collect();
        }
        std::thread::sleep(Duration::from_millis(50));
    }
}

impl ExternalDrivers for FarmDrivers {
    fn drives(&self, robot: &RobotId) -> bool {
        self.driven.iter().any(|d| d == robot.as_str())
    }

    fn begin_step(&mut self, now: Time) {
        self.now = now;
        if let Some(p) = self.pacer.as_mut() {
            p.wait_until(now);
        }
        self.link.publish_clock(now);
        if self.lockstep.is_some() {
            self.rejoin_dropped(now);
            for id in self.driven.clone() {
                self.call(&RobotId::new(&id), Op::Begin(now));
            }
        } else {
            self.link.poll(now);
            for id in std::mem::take(&mut self.absent) {
                if self.link.tree_status(&id).is_empty() {
                    self.absent.push(id);
                } else {
                    self.join(id, now);
                }
            }
        }
    }

    fn odometry(&mut self, robot: &RobotId, odom: &Odometry) {
        match self.lockstep {
            Some(_) => self.call(robot, Op::Odometry(*odom)),
            None => self.link.publish_odometry(robot.as_str(), odom),
        }
    }

    fn odometry_with_covariance(&mut self, robot: &RobotId, odom: &Odometry, covariance: &OdometryCovariance) {
        match self.lockstep {
            Some(_) => self.call(robot, Op::Odometry(*odom)),
            None => self.link.publish_odometry_with_covariance(robot.as_str(), odom, covariance),
        }
    }

    fn panorama(&mut self, robot: &RobotId, frame: &PanoramaFrame) {
        match self.lockstep {
            Some(_) => self.call(robot, Op::Panorama(frame.clone())),
            None => self.link.publish_panorama(robot.as_str(), frame),
        }
    }

    fn pose(&mut self, robot: &RobotId, estimate: &PoseEstimate, z_m: f64) {
        match self.lockstep {
            Some(_) => self.call(robot, Op::ExternalPose(*estimate)),
            None => self.link.publish_pose(robot.as_str(), estimate, z_m),
        }
    }

    fn camera_tiles(&mut self, robot: &RobotId, now: Time, tiles: &[MapTile], grid: &GridSpec) {
        match self.lockstep {
            Some(_) => self.call(robot, Op::CameraTiles(tiles.to_vec())),
            None => self.link.publish_camera_tiles(robot.as_str(), now, tiles, grid),
        }
    }

    fn command(&mut self, robot: &RobotId, now: Time) -> Option<Twist2> {
        self.link.command(robot.as_str(), now)
    }

    fn flight(&mut self, robot: &RobotId, now: Time) -> Option<FlightCommand> {
        match self.lockstep {
            Some(_) if self.answering(robot.as_str()) => self.last(robot.as_str()).and_then(|d| d.flight),
            Some(_) => None,
            None => self.link.setpoint(robot.as_str(), now),
        }
    }

    fn take_team_messages(&mut self) -> Vec<DrivenTeamMessage> {
        self.link
            .take_team_packets()
            .into_iter()
            .map(|p| DrivenTeamMessage { from: RobotId::new(&p.from), to: RobotId::new(&p.to), bytes: p.bytes })
            .collect()
    }

    fn deliver_team_message(&mut self, to: &RobotId, from: &RobotId, bytes: &[u8]) {
        match self.lockstep {
            Some(_) => self.call(to, Op::TeamIn { from: from.clone(), bytes: bytes.to_vec() }),
            None => self.link.deliver_team(to.as_str(), from.as_str(), bytes),
        }
    }

    fn goals(&self, robot: &RobotId) -> &[GoalView] {
        match self.lockstep {
            Some(_) => self.last(robot.as_str()).map_or(&[], |d| d.goals.as_slice()),
            None => self.link.goals(robot.as_str()),
        }
    }

    fn tree_done(&self, robot: &RobotId) -> bool {
        let status = match self.lockstep {
            Some(_) => self.last(robot.as_str()).map_or("", |d| d.tree.as_str()),
            None => self.link.tree_status(robot.as_str()),
        };
        matches!(status, "success" | "failure")
    }

    fn lockstep(&self) -> bool {
        self.lockstep.is_some()
    }

    fn exchange_work(&mut self, robot: &RobotId, _now: Time) {
        self.call(robot, Op::ExchangeWork);
    }

    fn team_message_for(
        &mut self,
        robot: &RobotId,
        to: &RobotId,
        tiers: TierSet,
        budget_bytes: usize,
    ) -> Option<Vec<u8>> {
        let l = self.lockstep.as_ref()?;
        if l.dropped.contains(robot.as_str()) {
            return None;
        }
        let timeout = l.timeout;
        match self.link.lockstep_team_out(robot.as_str(), to, tiers.bits(), budget_bytes as u64, timeout) {
            Ok(bytes) => bytes,
            Err(e) => {
                self.drop_robot(robot.as_str(), self.now, &e);
                None
            }
        }
    }

    fn tick(&mut self, robot: &RobotId, _now: Time) {
        if self.answering(robot.as_str()) {
            self.link.lockstep_call(robot.as_str(), Op::Tick);
            if let Some(l) = self.lockstep.as_mut() {
                l.ticking.push(robot.to_string());
            }
        }
    }

    fn end_step(&mut self, now: Time) {
        let Some(l) = self.lockstep.as_mut() else { return };
        let ticking = std::mem::take(&mut l.ticking);
        let timeout = l.timeout;
        for id in ticking {
            match self.link.lockstep_done(&id, timeout) {
                Ok(done) => {
                    if let Some(l) = self.lockstep.as_mut() {
                        let step = DrivenStep {
                            ticked: done.ticked,
                            command: done.command,
                            estimate_after_panorama: done.estimate_after_panorama,
                            estimate: done.estimate,
                            transitioned: done.transitioned.clone(),
                            problems: done.problems.clone(),
                        };
                        l.steps.insert(id.clone(), step);
                        l.last.insert(id, done);
                    }
                }
                Err(e) => self.drop_robot(&id, now, &e),
            }
        }
    }

    fn step_of(&self, robot: &RobotId) -> Option<&DrivenStep> {
        let l = self.lockstep.as_ref()?;
        if l.dropped.contains(robot.as_str()) {
            return Some(&STOPPED);
        }
        l.steps.get(robot.as_str())
    }

    fn halt(&mut self, robot: &RobotId, _now: Time) {
        self.call(robot, Op::Halt);
    }

    fn tree_status(&self, robot: &RobotId) -> Option<String> {
        self.last(robot.as_str()).map(|d| d.tree.clone())
    }

    fn joined(&mut self) -> Vec<RobotId> {
        std::mem::take(&mut self.joined)
    }

    fn end_run(&mut self) {
        for id in self.driven.clone() {
            self.call(&RobotId::new(&id), Op::End);
        }
    }
}
