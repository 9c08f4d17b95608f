//! Lockstep runs of a whole mission: every robot's body, sensors and behaviour tree stepped
//! against one simulated clock, the radio carrying team-state sync between them, faults
//! injected on schedule. Deterministic for a seed; as fast as the CPU allows.
//!
//! One step (`dt_s`, 0.1 s by default):
//! 1. bodies move with the commands of the previous tick (UGV kinematics among the others, UAV
//!    flight toward its waypoint); kills take effect;
//! 2. sensors: odometry, panoramas when due (other robots drawn in), the UAV camera's tiles,
//!    GPS or ground truth where the mission asks for it — all fed to the robots' runtimes;
//! 3. the radio: each link that is up carries one sync message each way, limited to the tiers
//!    and bytes its range and bandwidth allow (every `sync_period_s`);
//! 4. each robot whose tick is due ticks its tree; the nodes' commands are read back.
//!
//! Steps 2 (for the UGVs' own sensing and perception) and 4 touch one robot at a time: with
//! [`SimOptions::parallel_robots`] they run on rayon's threads, and observers hear of them after,
//! in robot order — the same run, summary and log as in order on one thread.
//!
//! Everything a run produces goes to a [`SimObserver`] (the CLI records it to MCAP) and into
//! the [`RunSummary`]. Each robot records its own seam calls when the observer keeps them
//! (`RobotObserver::wants_seam`); the runner hands them over after each phase, in robot order.
//!
//! By concern: `options` (what a run is given besides the mission), `observer` (what it
//! tells), `robots` (one simulated robot and the per-robot work of a step), `radio_sync` (the
//! sync round), `goals` (team-level goal bookkeeping), `finish` (the summary), `external`
//! (robots driven by other processes), `setup` (mission → world, radio, faults, area), `pace`
//! (real-time pacing); this module holds the run and its step.

mod external;
mod finish;
mod goals;
mod observer;
mod operator;
mod options;
mod pace;
mod radio_sync;
mod robots;
mod setup;
mod summary;

use std::collections::BTreeMap;
use std::sync::Arc;
use std::time::Instant;

use rayon::prelude::*;
use serde::Serialize;
use spomp_behaviors::NodeRegistry;
use spomp_behaviors::mission::schema::CompleteWhen;
use spomp_behaviors::mission::{LoadedMission, MissionFile, MissionSection};
use spomp_behaviors::trace::Recorder;
use spomp_core::{
    AerialMap, ClassId, GoalId, Odometry, PanoramaFrame, PanoramaGeometry, Point2, Pose2, PoseEstimate, RobotId,
    RobotKind, Time, Twist2, normalize_angle,
};
use spomp_mapping::{CompressionParams, PngLevel};
use spomp_robot::runtime::{FinishedWork, SkillWork, WorkKind};
use spomp_robot::{
    CommsSpec, LinkCredit, ModelledWork, PoseInput, Robot, RobotObserver, RobotRuntime, RobotSetup, RobotView,
    RoundShape, SetupOptions, TeamTraffic,
};
use spomp_teamstate::{GoalOrigin, Tier, TierSet};

pub use external::{DrivenStep, DrivenTeamMessage, ExternalDrivers};
pub use observer::{NoObserver, RobotSnapshot, SimEvent, SimObserver};
pub use operator::{OperatorCommandSummary, OperatorTraffic};
pub use options::{SimOptions, SkillLatency};
pub use pace::RealTimePacer;
pub use setup::{faults_for_mission, radio_for_mission};
pub use summary::{
    ClusterSummary, ErrorStats, GoalSummary, NavigationInForce, Outcome, ProblemCount, RobotSummary, RunSummary,
};

use robots::{
    Body, SimRobot, TickedRobot, for_each_robot, join_on_rayon, note_claim, note_localization, note_problem,
    observe_scan, others_than, sense_ugv, tick_robot,
};

use crate::error::SimError;
use crate::panorama::{PanoramaSensor, SensorParams};
use crate::radio::{Faults, Link, LinkTier, Radio, RadioNode};
use crate::uav::{OrthoCamera, Uav, UavParams};
use crate::ugv::{NoisyPoseSource, OdometryModel, OdometryNoiseParams, PoseNoiseParams, Ugv, UgvParams};
use spomp_world::Obstacle;
use spomp_world::World;

/// Everything a finished run leaves: the summary and what plots need.
pub struct RunResult {
    /// The summary.
    pub summary: RunSummary,
    /// The world it ran in.
    pub world: Arc<World>,
    /// Ground-truth track of each robot (id, kind, points every second).
    pub trajectories: Vec<(RobotId, RobotKind, Vec<Point2>)>,
    /// Position error of each UGV's own estimate over time: (id, [(simulated time s, error m)]),
    /// sampled at panoramas, at most once a second (see [`Simulation::localization_error_series`]).
    pub localization_errors: Vec<(RobotId, Vec<(f64, f64)>)>,
    /// Each robot's team-state traffic as its robot counted it (what the simulator ran of it:
    /// a robot driven from outside counts in its own process).
    pub team_traffic: Vec<(RobotId, TeamTraffic)>,
}

/// A mission running in the simulator.
pub struct Simulation {
    mission: MissionFile,
    options: SimOptions,
    world: Arc<World>,
    radio: Radio,
    ugv_to_ugv: bool,
    robots: Vec<SimRobot>,
    now: Time,
    dt_ns: i64,
    time_limit: Time,
    next_sync: Time,
    next_second: Time,
    next_record: Time,
    links: Vec<(usize, usize, Link)>,
    goals: BTreeMap<GoalId, GoalSummary>,
    goal_order: Vec<GoalId>,
    /// Goal ids some robot's team state merged into another goal (alias → canonical).
    aliases: BTreeMap<GoalId, GoalId>,
    /// Visits each robot made itself, as its own team state recorded them: (goal, robot) → time.
    own_visits: BTreeMap<(GoalId, usize), Time>,
    /// Last time each pair of robots had a direct link (row-major, robot index pairs).
    last_link: Vec<Option<Time>>,
    problems: BTreeMap<(String, String), ProblemCount>,
    outcome: Option<Outcome>,
    obstacles: Vec<Obstacle>,
    /// The class the UGVs' bodies show as in each other's panoramas: the vehicle class as the
    /// world's table names it (through the mission's `classes:`), resolved once at setup.
    ugv_body_class: ClassId,
    /// What drives the robots driven from outside, if any are.
    drivers: Option<Box<dyn ExternalDrivers>>,
    /// Messages driven robots sent, waiting for the next radio period.
    driven_outbox: Vec<DrivenTeamMessage>,
    /// Holds each step back to real time × a rate (see [`Simulation::pace`]).
    pacer: Option<RealTimePacer>,
    /// Observers were shown a map (a prior one, or a published version).
    map_shown: bool,
    /// Whether the robots record their seam calls: what the observer of the last step wanted.
    recording_seam: bool,
    /// The operator of `sim.operator:` (issue 37), if the mission scripts one.
    operator: Option<operator::SimOperator>,
}

/// A UGV whose every commanded motion was refused for this long is stuck (a counted event and
/// a problem), seconds.
pub const STUCK_AFTER_S: f64 = 5.0;

/// A robot that stays within this distance of where it stood is motionless (summary's
/// `longest_motionless_driving_s`), metres.
pub const MOTIONLESS_RADIUS_M: f64 = 0.25;

/// The vehicle class's index in the built-in table: what UGV bodies show as in a world whose
/// table has no vehicle class at all.
const BUILTIN_VEHICLE_CLASS: ClassId = 4;

/// Most distinct problem messages kept in a summary.
const MAX_PROBLEMS: usize = 200;

impl Simulation {
    /// Sets up a validated mission in `world`.
    pub fn new(
        loaded: &LoadedMission,
        registry: &NodeRegistry<RobotRuntime>,
        world: Arc<World>,
        options: SimOptions,
    ) -> Result<Self, SimError> {
        let mission = loaded
            .mission
            .clone()
            .filter(|_| loaded.is_valid())
            .ok_or_else(|| SimError::invalid("mission", "the mission is not valid; run `spomp validate` on it"))?;
        if !(options.dt_s.is_finite() && options.dt_s > 0.0 && options.sync_period_s > 0.0) {
            return Err(SimError::invalid("simulation options", "dt_s and sync_period_s must be positive"));
        }
        let faults = faults_for_mission(&mission, &options.faults)?;
        let radio = Radio::new(radio_for_mission(&mission)?, &faults)?;
        let area =
            spomp_world::operating_area(&mission, &world).map_err(|e| SimError::invalid("mission", e.to_string()))?;
        let ugv_to_ugv = CommsSpec::of_mission(&mission)
            .map_err(|e| SimError::invalid("mission", e.to_string()))?
            .ugv_to_ugv
            .unwrap_or(true);
        // Through the mission's mapping: looked up by the built-in name alone, a renamed table's
        // bodies (`Car`) fell back to index 4, another class there (the yard's grass).
        let ugv_body_class = spomp_robot::class_names::ClassNames::new(&mission, world.classes())
            .resolve("vehicle")
            .and_then(|name| world.classes().by_name(&name))
            .map_or(BUILTIN_VEHICLE_CLASS, |c| c.index);
        let mut robots = Vec::with_capacity(mission.team.len());
        for (i, spec) in mission.team.iter().enumerate() {
            let robot_error =
                |e: &dyn std::fmt::Display| SimError::invalid("team", format!("robot `{}`: {e}", spec.id));
            let inputs = SetupOptions {
                map_publish_period_s: options.map_publish_period_s,
                map_compression: options.map_compression.clone(),
                robot_seed: None,
            };
            let setup = RobotSetup::from_mission_with(&mission, &spec.id, &area, options.seed, &inputs)
                .map_err(|e| robot_error(&e))?;
            let start = setup.config.start();
            let id = setup.config.id().clone();
            let mut robot = Robot::from_setup(loaded, setup, registry).map_err(|e| robot_error(&e))?;
            robot.set_background_skills(options.skill_latency.is_some());
            robot.set_perception_join(options.parallel_robots.then_some(join_on_rayon as spomp_robot::JoinFn));
            let pose_input = robot.pose_input();
            let seed = options.seed.wrapping_mul(31).wrapping_add(i as u64 * 7919 + 17);
            let body = match spec.kind {
                RobotKind::Ugv => {
                    let ugv = Ugv::new(&world, options.ugv.clone(), start).map_err(|e| {
                        SimError::invalid(
                            "team",
                            format!(
                                "robot `{}`: start ({:.1}, {:.1}) is not drivable ground in this world: {e}",
                                spec.id, start.x, start.y
                            ),
                        )
                    })?;
                    let truth_source = match pose_input {
                        PoseInput::GroundTruth { noise_m } => Some(Box::new(NoisyPoseSource::new(
                            PoseNoiseParams { position_std_m: noise_m, yaw_std_rad: noise_m * 0.02 },
                            faults.localization_noise_scale,
                            seed ^ 0x5EED,
                        ))),
                        PoseInput::OwnEstimate | PoseInput::External => None,
                    };
                    Body::Ugv {
                        ugv: Box::new(ugv),
                        odometry: Box::new(OdometryModel::new(
                            options.odometry_noise.clone(),
                            faults.odometry_noise_scale,
                            start,
                            seed,
                        )),
                        sensor: Box::new(PanoramaSensor::new(&options.sensor)?),
                        truth_source,
                        last_scan_stamp: None,
                    }
                }
                RobotKind::Uav => Body::Uav {
                    uav: Box::new(Uav::new(options.uav.clone(), start)?),
                    camera: Box::new(OrthoCamera::new(&options.uav, &world, seed)?),
                    flying_to: None,
                },
                RobotKind::Basestation => Body::Fixed { pose: start },
            };
            let mut node_paths = Vec::new();
            robot.tree().root().visit(0, &mut |slot, _| node_paths.push(slot.info().path.to_string()));
            let hz = robot.tick_hz();
            robots.push(SimRobot {
                id: id.clone(),
                kind: spec.kind,
                pose_input,
                robot,
                body,
                tick_period_ns: ((1e9 / hz).round() as i64).max(1),
                next_tick: Time::ZERO,
                kill_at: faults.kill_time(&id),
                killed_s: None,
                command: Twist2::ZERO,
                ticked: vec![false; node_paths.len()],
                node_paths,
                claim_time_s: BTreeMap::new(),
                held: None,
                work_out: options.skill_latency.map(|l| ModelledWork::new(l.into())),
                link_credit: LinkCredit::default(),
                localization_errors: Vec::new(),
                localization_error_series: Vec::new(),
                last_path_len: 0,
                trajectory: vec![start.position()],
                external: false,
                map_shown: None,
                other_bodies: Vec::new(),
                refused_since: None,
                refusal_counted: false,
                stuck_events: 0,
                still_since: None,
                longest_still_driving_s: 0.0,
            });
        }
        let time_limit_s = options.time_limit_s.unwrap_or(mission.time_limit_s);
        let n_robots = robots.len();
        let operator = operator::SimOperator::for_mission(&mission)?;
        Ok(Simulation {
            ugv_to_ugv,
            mission,
            dt_ns: (options.dt_s * 1e9).round() as i64,
            options,
            world,
            radio,
            robots,
            now: Time::ZERO,
            time_limit: Time::from_secs_f64(time_limit_s),
            next_sync: Time::ZERO,
            next_second: Time::ZERO,
            next_record: Time::ZERO,
            links: Vec::new(),
            goals: BTreeMap::new(),
            goal_order: Vec::new(),
            aliases: BTreeMap::new(),
            own_visits: BTreeMap::new(),
            last_link: vec![None; n_robots * n_robots],
            problems: BTreeMap::new(),
            outcome: None,
            obstacles: Vec::new(),
            ugv_body_class,
            drivers: None,
            driven_outbox: Vec::new(),
            pacer: None,
            map_shown: false,
            recording_seam: false,
            operator,
        })
    }

    /// Hands the robots `drivers` drives over to it (see [`ExternalDrivers`]): UGVs (odometry,
    /// panoramas out; velocity in), UAVs (position and camera tiles out; setpoints in) and
    /// basestations (their surveyed position out). Returns the ids now driven.
    pub fn drive_externally(&mut self, drivers: Box<dyn ExternalDrivers>) -> Result<Vec<RobotId>, SimError> {
        let mut driven = Vec::new();
        for r in &mut self.robots {
            if drivers.drives(&r.id) {
                r.external = true;
                driven.push(r.id.clone());
            }
        }
        self.drivers = Some(drivers);
        Ok(driven)
    }

    /// Runs at real time × `rate` from now on (simulated seconds per wall second) instead of as
    /// fast as possible: for someone watching the run live. The results do not change.
    pub fn pace(&mut self, rate: f64) {
        self.pacer = Some(RealTimePacer::new(rate));
    }

    /// Simulated time now.
    pub fn now(&self) -> Time {
        self.now
    }

    /// The world.
    pub fn world(&self) -> &Arc<World> {
        &self.world
    }

    /// The outcome, once the run has ended.
    pub fn outcome(&self) -> Option<Outcome> {
        self.outcome
    }

    /// A robot, read-only (tests, tools, live views).
    pub fn robot(&self, id: &str) -> Option<RobotView<'_>> {
        self.robots.iter().find(|r| r.id.as_str() == id).map(|r| r.robot.view())
    }

    /// A robot's ground-truth pose.
    pub fn true_pose(&self, id: &str) -> Option<Pose2> {
        self.robots.iter().find(|r| r.id.as_str() == id).map(SimRobot::truth)
    }

    /// A UGV's position error (its own estimate against the truth) over the run so far:
    /// (simulated time s, error m), sampled at its panoramas at most once a second. Empty until
    /// the robot has an estimate; `None` for an unknown id.
    pub fn localization_error_series(&self, id: &str) -> Option<&[(f64, f64)]> {
        self.robots.iter().find(|r| r.id.as_str() == id).map(|r| r.localization_error_series.as_slice())
    }

    /// Moves a UGV to `pose` at once without its odometry noticing (the kidnapped-robot test).
    pub fn teleport(&mut self, id: &str, pose: Pose2) -> Result<(), SimError> {
        let world = self.world.clone();
        let robot = self
            .robots
            .iter_mut()
            .find(|r| r.id.as_str() == id)
            .ok_or_else(|| SimError::invalid("teleport", format!("no robot `{id}`")))?;
        match &mut robot.body {
            Body::Ugv { ugv, odometry, .. } => {
                ugv.teleport(&world, pose)?;
                odometry.carried_to(pose);
                Ok(())
            }
            _ => Err(SimError::invalid("teleport", format!("`{id}` is not a UGV"))),
        }
    }

    /// Whether two robots have a radio link right now.
    pub fn linked(&self, a: &str, b: &str) -> Option<LinkTier> {
        let ia = self.robots.iter().position(|r| r.id.as_str() == a)?;
        let ib = self.robots.iter().position(|r| r.id.as_str() == b)?;
        let (i, j) = (ia.min(ib), ia.max(ib));
        self.links.iter().find(|(x, y, _)| *x == i && *y == j).map(|(_, _, l)| l.tier)
    }

    /// Runs to the end and summarises.
    pub fn run(self, observer: &mut dyn SimObserver) -> RunResult {
        self.run_until(observer, &mut || false)
    }

    /// Runs to the end, or until `stop` (asked before each step) says to stop; a stopped run
    /// ends [`Outcome::Interrupted`] after the step in progress and is summarised all the same.
    pub fn run_until(mut self, observer: &mut dyn SimObserver, stop: &mut dyn FnMut() -> bool) -> RunResult {
        let wall = Instant::now();
        while self.outcome.is_none() {
            if stop() {
                self.outcome = Some(Outcome::Interrupted);
                observer.on_event(self.now, &SimEvent::MissionEnded { outcome: Outcome::Interrupted });
                break;
            }
            self.step(observer);
        }
        self.finish(observer, wall.elapsed().as_secs_f64())
    }

    /// Advances one step; a no-op once the run has ended.
    pub fn step(&mut self, observer: &mut dyn SimObserver) {
        if self.outcome.is_some() {
            return;
        }
        self.now = Time::from_nanos(self.now.nanos + self.dt_ns);
        let now = self.now;
        let dt = self.options.dt_s;
        if let Some(p) = self.pacer.as_mut() {
            p.wait_until(now);
        }
        // The robots record their calls themselves when the observer keeps them.
        if observer.wants_seam() != self.recording_seam {
            self.recording_seam = observer.wants_seam();
            for r in &mut self.robots {
                r.robot.record_seam(self.recording_seam);
            }
        }
        if let Some(d) = self.drivers.as_mut() {
            d.begin_step(now);
            for id in d.joined() {
                if let Some(r) = self.robots.iter_mut().find(|r| r.id == id && r.alive()) {
                    r.external = true;
                }
            }
            self.driven_outbox.extend(d.take_team_messages());
        }
        self.apply_kills(observer);
        self.move_bodies(dt);
        self.report_stuck(observer);
        self.sense(observer);
        self.exchange_work(observer);
        self.operator_step(observer);
        if now >= self.next_sync {
            self.sync_radio(observer);
            self.next_sync = Time::from_nanos(now.nanos + (self.options.sync_period_s * 1e9).round() as i64);
        }
        self.tick_trees(observer);
        if now >= self.next_record {
            let period = observer.record_period_s().max(self.options.dt_s);
            self.next_record = Time::from_nanos(now.nanos + (period * 1e9).round() as i64 - 1);
            for r in &self.robots {
                let driven = self.drivers.as_ref().filter(|_| r.external).and_then(|d| d.step_of(&r.id));
                let snap = RobotSnapshot {
                    kind: r.kind,
                    truth: r.truth(),
                    z_m: r.z_m(),
                    estimate: match driven {
                        Some(step) => step.estimate,
                        None => r.robot.pose(),
                    },
                    command: r.command,
                };
                observer.on_state(&r.id, now, &snap);
            }
        }
        if now >= self.next_second {
            self.next_second = Time::from_nanos(now.nanos + 1_000_000_000 - 1);
            for r in &mut self.robots {
                r.trajectory.push(r.truth().position());
            }
            self.track_still();
            self.track_goals(observer);
            self.track_acknowledgements(observer);
            self.show_maps(observer);
            self.check_end(observer);
        }
    }

    /// Shows observers each map version a robot published since the last call, and a prior map
    /// once at the start.
    fn show_maps(&mut self, observer: &mut dyn SimObserver) {
        let now = self.now;
        for r in &mut self.robots {
            let published = r.robot.team().latest_map(&r.id).map(|v| v.version);
            let fresh = published.is_some() && published != r.map_shown;
            let prior = !self.map_shown && published.is_none();
            if !(fresh || prior) {
                continue;
            }
            if let Some(map) = r.robot.aerial_map().filter(|m| fresh || m.map().known_cells() > 0) {
                observer.on_map(&r.id, now, map.map());
                r.map_shown = published;
                self.map_shown = true;
            }
        }
    }

    /// Counts and reports each UGV whose commanded motion the simulator has refused for
    /// [`STUCK_AFTER_S`] on end: never a silent refusal.
    fn report_stuck(&mut self, observer: &mut dyn SimObserver) {
        let now = self.now;
        for r in &mut self.robots {
            let Some(since) = r.refused_since else { continue };
            if r.refusal_counted || now.secs_since(since) < STUCK_AFTER_S {
                continue;
            }
            r.refusal_counted = true;
            r.stuck_events += 1;
            let at = r.truth().position();
            let message = format!(
                "simulator: stuck at ({:.1}, {:.1}): every commanded motion refused for {STUCK_AFTER_S:.0} s (wedged against obstacles)",
                at.x, at.y
            );
            observer.on_problem(&r.id, now, &message);
            note_problem(&mut self.problems, &r.id, message, now);
            observer.on_event(now, &SimEvent::RobotStuck { robot: r.id.to_string(), position: [at.x, at.y] });
        }
    }

    /// Once a second: the time each robot has stood still while its tree drove it (a velocity
    /// command in force, or a drive with a planned path running).
    fn track_still(&mut self) {
        let now = self.now;
        for r in &mut self.robots {
            let driving = r.alive()
                && r.kind == RobotKind::Ugv
                && (r.command.v.abs() > 1e-3 || r.command.omega.abs() > 1e-3 || r.robot.planned_path().is_some());
            let here = r.truth().position();
            match r.still_since {
                Some((at, since)) if driving && at.distance(here) <= MOTIONLESS_RADIUS_M => {
                    r.longest_still_driving_s = r.longest_still_driving_s.max(now.secs_since(since));
                }
                _ => r.still_since = driving.then_some((here, now)),
            }
        }
    }

    fn apply_kills(&mut self, observer: &mut dyn SimObserver) {
        let now = self.now;
        for r in &mut self.robots {
            if r.alive() && r.kill_at.is_some_and(|k| now >= k) {
                r.killed_s = Some(now.as_secs_f64());
                r.command = Twist2::ZERO;
                r.robot.halt(now);
                r.robot.deliver_recorded(observer);
                if let Some(d) = self.drivers.as_mut().filter(|_| r.external) {
                    d.halt(&r.id, now);
                }
                observer.on_event(now, &SimEvent::RobotKilled { robot: r.id.to_string() });
            }
        }
    }

    fn move_bodies(&mut self, dt: f64) {
        // Every UGV is an obstacle for the others (and shows in their panoramas).
        self.obstacles.clear();
        for r in &self.robots {
            if let Body::Ugv { ugv, .. } = &r.body {
                let base = ugv.base_elevation_m();
                self.obstacles.push(Obstacle {
                    center: ugv.pose().position(),
                    radius_m: ugv.params().limits.radius_m,
                    bottom_m: base,
                    top_m: base + 0.8,
                    class: self.ugv_body_class,
                });
            }
        }
        let world = &self.world;
        let mut ugv_index = 0;
        for r in &mut self.robots {
            let alive = r.alive();
            match &mut r.body {
                Body::Ugv { ugv, .. } => {
                    let own = ugv_index;
                    ugv_index += 1;
                    let cmd = if alive { r.command } else { Twist2::ZERO };
                    others_than(&self.obstacles, own, &mut r.other_bodies);
                    let before = ugv.pose();
                    let step = ugv.step_among(world, cmd, dt, &r.other_bodies);
                    // A command the body did not follow at all: refused (a collision is counted
                    // once per contact; a robot wedged in contact is refused step after step).
                    let commanded = cmd.v.abs() > 1e-3 || cmd.omega.abs() > 1e-3;
                    let moved = step.moved_m > 1e-6 || normalize_angle(ugv.pose().yaw - before.yaw).abs() > 1e-6;
                    if commanded && step.blocked && step.moved_m <= 1e-6 {
                        r.refused_since.get_or_insert(self.now);
                    } else if moved {
                        r.refused_since = None;
                        r.refusal_counted = false;
                    }
                }
                Body::Uav { uav, flying_to, .. } => {
                    if !alive {
                        continue;
                    }
                    let flight = match self.drivers.as_mut() {
                        Some(d) if r.external => d.flight(&r.id, self.now),
                        _ => r.robot.flight(),
                    };
                    match flight {
                        Some(cmd) => {
                            if *flying_to != Some(cmd.target) {
                                uav.go_to(cmd.target);
                                *flying_to = Some(cmd.target);
                            }
                            uav.set_speed_mps(cmd.speed_mps);
                            uav.step(dt);
                        }
                        None => *flying_to = None,
                    }
                }
                Body::Fixed { .. } => {}
            }
        }
    }

    /// Background skills ([`SimOptions::skill_latency`]): work due back is handed to its robot,
    /// then the work each robot has due now is taken and done, to come back after the latency
    /// (the robot layer's `ModelledWork`, which a farm robot in lockstep runs too).
    fn exchange_work(&mut self, observer: &mut dyn SimObserver) {
        if self.options.skill_latency.is_none() {
            return;
        }
        let now = self.now;
        for r in &mut self.robots {
            if !r.alive() {
                continue;
            }
            if r.external {
                if let Some(d) = self.drivers.as_mut().filter(|d| d.lockstep()) {
                    d.exchange_work(&r.id, now);
                }
                continue;
            }
            let Some(work_out) = r.work_out.as_mut() else { continue };
            for work in work_out.due(now) {
                let perception = work.kind() == WorkKind::Perception;
                r.robot.finish_work(now, work);
                r.robot.deliver_recorded(observer);
                if perception && let Body::Ugv { last_scan_stamp, .. } = &mut r.body {
                    observe_scan(&r.id, &r.robot, last_scan_stamp, observer);
                }
            }
            work_out.take(&mut r.robot, now, SkillWork::run);
            r.robot.deliver_recorded(observer);
        }
    }

    fn sense(&mut self, observer: &mut dyn SimObserver) {
        let now = self.now;
        // Each UGV's own sensing and perception (odometry, panorama render, localization and
        // terrain analysis) touches only that robot and reads the world: done per robot, in
        // parallel when allowed; what observers see is reported afterwards in robot order, so
        // a run and its log are the same either way.
        // Between panoramas a UGV's sensing is an odometry sample: waking rayon's threads for
        // it cost more than it saved (0.6 s against 0.3 s serial over the bench mission).
        let panorama_due = self.robots.iter().any(|r| r.alive() && !r.external && r.panorama_due(now));
        let sensed = {
            let world = &*self.world;
            let parallel = self.options.parallel_robots && panorama_due;
            for_each_robot(parallel, &mut self.robots, |r| sense_ugv(r, world, now))
        };
        let world = &self.world;
        for (r, sensed) in self.robots.iter_mut().zip(sensed) {
            let alive = r.alive();
            match &mut r.body {
                Body::Ugv { ugv, odometry, sensor, truth_source, last_scan_stamp } => {
                    if !alive {
                        continue;
                    }
                    if let Some(s) = sensed {
                        observer.on_odometry(&r.id, &s.odometry);
                        if let Some(frame) = &s.panorama {
                            observer.on_panorama(&r.id, frame);
                        }
                        r.robot.deliver_recorded(observer);
                        if s.panorama.is_some() {
                            observe_scan(&r.id, &r.robot, last_scan_stamp, observer);
                        }
                        continue;
                    }
                    // Driven from outside: its inputs go to the process that drives it.
                    let Some(d) = self.drivers.as_mut().filter(|_| r.external) else { continue };
                    let truth = ugv.pose();
                    let odom = odometry.update(now, truth, ugv.twist());
                    observer.on_odometry(&r.id, &odom);
                    d.odometry_with_covariance(&r.id, &odom, &odometry.covariance());
                    if let Some(src) = truth_source.as_mut() {
                        d.pose(&r.id, &src.estimate(now, truth), ugv.base_elevation_m() as f64);
                    }
                    if let Some(frame) =
                        sensor.poll_among(now, world, truth, ugv.base_elevation_m(), odom.pose, &r.other_bodies)
                    {
                        observer.on_panorama(&r.id, &frame);
                        d.panorama(&r.id, &frame);
                    }
                }
                Body::Uav { uav, camera, .. } => {
                    if !alive {
                        continue;
                    }
                    let pose = uav.pose();
                    let estimate = PoseEstimate { stamp: now, pose, covariance: [0.0; 9], confidence: 1.0 };
                    if let Some(d) = self.drivers.as_mut().filter(|_| r.external) {
                        // Its position (GNSS) and what its camera mapped go to the process
                        // that drives it.
                        d.pose(&r.id, &estimate, uav.altitude_m());
                        let tiles = camera.reveal(world, pose);
                        // In lockstep every call is made, as on the simulator's own robots.
                        if !tiles.is_empty() || d.lockstep() {
                            d.camera_tiles(&r.id, now, &tiles, world.spec());
                        }
                        continue;
                    }
                    r.robot.on_external_pose(now, estimate);
                    r.robot.on_camera_tiles(now, camera.reveal(world, pose));
                    r.robot.deliver_recorded(observer);
                }
                Body::Fixed { pose } => {
                    if alive {
                        let estimate = PoseEstimate { stamp: now, pose: *pose, covariance: [0.0; 9], confidence: 1.0 };
                        if let Some(d) = self.drivers.as_mut().filter(|_| r.external) {
                            d.pose(&r.id, &estimate, 0.0);
                            continue;
                        }
                        r.robot.on_external_pose(now, estimate);
                        r.robot.deliver_recorded(observer);
                    }
                }
            }
        }
    }

    fn tick_trees(&mut self, observer: &mut dyn SimObserver) {
        let now = self.now;
        let dt = self.options.dt_s;
        // Robots in lockstep tick in their processes while the simulator's own tick here.
        let lockstep = self.drivers.as_ref().is_some_and(|d| d.lockstep());
        if let Some(d) = self.drivers.as_mut().filter(|_| lockstep) {
            for r in self.robots.iter().filter(|r| r.alive() && r.external) {
                d.tick(&r.id, now);
            }
        }
        // Upkeep and ticks touch only their robot (parallel when allowed); observers hear of
        // them afterwards, in robot order.
        let ticked = for_each_robot(self.options.parallel_robots, &mut self.robots, |r| tick_robot(r, now));
        if let Some(d) = self.drivers.as_mut().filter(|_| lockstep) {
            d.end_step(now);
        }
        for (r, ticked) in self.robots.iter_mut().zip(ticked) {
            if !r.alive() {
                continue;
            }
            if r.external {
                if let Some(d) = self.drivers.as_mut() {
                    if !lockstep {
                        r.command = d.command(&r.id, now).unwrap_or(Twist2::ZERO);
                    } else if let Some(step) = d.step_of(&r.id) {
                        if step.ticked {
                            r.command = step.command.unwrap_or(Twist2::ZERO);
                        }
                        for node in &step.transitioned {
                            if let Some(t) = r.ticked.get_mut(*node as usize) {
                                *t = true;
                            }
                        }
                        if let Some(est) = &step.estimate_after_panorama {
                            let truth = r.truth();
                            note_localization(r, est, truth, now);
                        }
                        for message in &step.problems {
                            observer.on_problem(&r.id, now, message);
                            note_problem(&mut self.problems, &r.id, message.clone(), now);
                        }
                    }
                    let id = r.id.clone();
                    let held =
                        d.goals(&id).iter().find(|g| g.visited.is_none() && g.is_held_by(&id)).map(|g| g.id.clone());
                    note_claim(r, held, now, dt, observer);
                }
                continue;
            }
            if let Some(TickedRobot { transitions }) = ticked {
                if !transitions.records.is_empty() {
                    for rec in &transitions.records {
                        if let Some(t) = r.ticked.get_mut(rec.node_id as usize) {
                            *t = true;
                        }
                    }
                    observer.on_transitions(&r.id, &transitions.records);
                }
                // After the transitions: a log cut after a tick's call holds all of that tick.
                r.robot.deliver_recorded(observer);
                let path_len = r.robot.planned_path().map_or(0, <[Point2]>::len);
                if path_len != r.last_path_len {
                    r.last_path_len = path_len;
                    observer.on_path(&r.id, now, r.robot.planned_path().unwrap_or(&[]));
                }
                for message in r.robot.take_problems() {
                    observer.on_problem(&r.id, now, &message);
                    note_problem(&mut self.problems, &r.id, message, now);
                }
            }
            // Claim bookkeeping for the "time heading to a goal" metric.
            if r.kind == RobotKind::Ugv {
                let id = r.id.clone();
                let held = r
                    .robot
                    .team()
                    .goals()
                    .iter()
                    .find(|g| g.visited.is_none() && g.is_held_by(&id))
                    .map(|g| g.id.clone());
                note_claim(r, held, now, dt, observer);
            }
        }
    }

    fn check_end(&mut self, observer: &mut dyn SimObserver) {
        let done = match self.mission.complete_when {
            CompleteWhen::AllGoalsVisited => self.all_goals_visited(),
            CompleteWhen::AllTreesDone => self.robots.iter().filter(|r| r.alive()).all(|r| match &self.drivers {
                Some(d) if r.external => d.tree_done(&r.id),
                _ => r.robot.tree().status().is_done(),
            }),
            // Such a mission runs for its whole time limit: reaching it is its completion.
            CompleteWhen::TimeLimit => self.now >= self.time_limit,
        };
        let outcome = if done {
            Some(Outcome::Complete)
        } else if self.robots.iter().all(|r| !r.alive()) {
            Some(Outcome::AllDead)
        } else if self.now >= self.time_limit {
            Some(Outcome::TimeLimit)
        } else {
            None
        };
        if let Some(o) = outcome {
            self.outcome = Some(o);
            observer.on_event(self.now, &SimEvent::MissionEnded { outcome: o });
        }
    }
}
