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
//! the [`RunSummary`].

mod external;
mod pace;
mod seam;
mod setup;
mod summary;

use std::collections::BTreeMap;
use std::sync::Arc;
use std::time::Instant;

use rayon::prelude::*;
use serde::Serialize;
use spomp_behaviors::NodeRegistry;
use spomp_behaviors::mission::schema::CompleteWhen;
use spomp_behaviors::mission::{LoadedMission, MissionFile};
use spomp_behaviors::trace::{Recorder, TransitionRecord};
use spomp_core::{
    AerialMap, ClassId, GoalId, Odometry, PanoramaFrame, PanoramaGeometry, Point2, Pose2, PoseEstimate,
    ReachabilityScan, RobotId, RobotKind, Time, Twist2, normalize_angle,
};
use spomp_mapping::{CompressionParams, PngLevel};
use spomp_robot::runtime::{FinishedWork, WorkKind};
use spomp_robot::{PoseInput, Robot, RobotRuntime, RobotSetup};
use spomp_teamstate::{GoalOrigin, Tier, TierSet};

pub use external::{DrivenStep, DrivenTeamMessage, ExternalDrivers};
pub use pace::RealTimePacer;
pub use seam::{SeamInput, tier_bits};
pub use setup::{faults_for_mission, operating_area, radio_for_mission, world_for_mission};
pub use summary::{
    ClusterSummary, ErrorStats, GoalSummary, NavigationInForce, Outcome, ProblemCount, RobotSummary, RunSummary,
};

use crate::error::SimError;
use crate::panorama::{PanoramaSensor, SensorParams};
use crate::radio::{Faults, Link, LinkTier, Radio, RadioNode};
use crate::terrain::Obstacle;
use crate::uav::{OrthoCamera, Uav, UavParams};
use crate::ugv::{NoisyPoseSource, OdometryModel, OdometryNoiseParams, PoseNoiseParams, Ugv, UgvParams};
use crate::world::World;

/// Settings of a run that are not in the mission.
#[derive(Clone, Debug)]
pub struct SimOptions {
    /// Trial seed: the world (unless the mission fixes its seed), noise and every skill's RNG.
    pub seed: u64,
    /// Physics and sensor step, seconds.
    pub dt_s: f64,
    /// How often each radio link carries a sync message each way, seconds.
    pub sync_period_s: f64,
    /// How often the UAV publishes its map as a new version, seconds.
    pub map_publish_period_s: f64,
    /// PNG effort for the published map layers.
    pub map_compression: CompressionParams,
    /// Overrides the mission's time limit, seconds.
    pub time_limit_s: Option<f64>,
    /// Faults on top of the mission's.
    pub faults: Faults,
    /// Panoramic sensor of the UGVs.
    pub sensor: SensorParams,
    /// UGV body.
    pub ugv: UgvParams,
    /// UAV flight and camera.
    pub uav: UavParams,
    /// Odometry noise.
    pub odometry_noise: OdometryNoiseParams,
    /// Run the robots' heavy skills as background work that takes this long, as `spomp run`
    /// does on its worker threads; `None`: inline, within the step (the default).
    pub skill_latency: Option<SkillLatency>,
    /// Step the robots' sensing, perception and ticks on rayon's threads (when it has more than
    /// one). Results are the same either way: each robot's work touches only that robot, and
    /// observers are told in robot order after it.
    pub parallel_robots: bool,
}

/// Modelled compute time of the heavy skills when they run in the background
/// ([`SimOptions::skill_latency`]): each job is taken between steps, done at once, and handed
/// back to its robot at the first step this long after — deterministic, unlike threads, so a
/// run repeats bit for bit and its log replays.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct SkillLatency {
    /// A panorama's localization and terrain analysis, seconds.
    pub perception_s: f64,
    /// The global planner's graph growth and training, seconds.
    pub planner_s: f64,
}

impl SkillLatency {
    /// Figures of the order `spomp run` measures on a 2-core machine (a panorama in tens of
    /// milliseconds, a graph rebuild in most of a second).
    pub const TYPICAL: SkillLatency = SkillLatency { perception_s: 0.05, planner_s: 0.8 };

    fn of(&self, kind: WorkKind) -> f64 {
        match kind {
            WorkKind::Perception => self.perception_s,
            WorkKind::Planner => self.planner_s,
        }
    }
}

impl Default for SimOptions {
    fn default() -> Self {
        SimOptions {
            seed: 1,
            dt_s: 0.1,
            sync_period_s: 0.5,
            map_publish_period_s: 10.0,
            // The whole map is re-encoded on every publish: favour speed over the last bytes.
            map_compression: CompressionParams { level: PngLevel::Fast },
            time_limit_s: None,
            faults: Faults::default(),
            sensor: SensorParams::default(),
            ugv: UgvParams::default(),
            uav: UavParams::default(),
            odometry_noise: OdometryNoiseParams::default(),
            skill_latency: None,
            parallel_robots: true,
        }
    }
}

/// What happened, for logs (team-level changes and faults).
#[derive(Clone, Debug, PartialEq, Serialize)]
#[serde(tag = "event", rename_all = "snake_case")]
pub enum SimEvent {
    /// A goal became known to the team.
    GoalIdentified {
        /// Goal id.
        goal: String,
        /// Who identified it.
        by: String,
        /// Where, metres.
        position: [f64; 2],
    },
    /// A robot took a claim on a goal (as seen in its own team state).
    GoalClaimed {
        /// Goal id.
        goal: String,
        /// Claimant.
        by: String,
    },
    /// A robot gave up its claim.
    GoalReleased {
        /// Goal id.
        goal: String,
        /// Former claimant.
        by: String,
    },
    /// A goal was visited.
    GoalVisited {
        /// Goal id.
        goal: String,
        /// Visitor.
        by: String,
    },
    /// The simulator refused a UGV's commanded motion for [`STUCK_AFTER_S`] on end (wedged: every
    /// move collides); counted in its summary's `stuck_events` and reported as a problem.
    RobotStuck {
        /// Robot id.
        robot: String,
        /// Where (ground truth), metres.
        position: [f64; 2],
    },
    /// A robot was killed (fault injection).
    RobotKilled {
        /// Robot id.
        robot: String,
    },
    /// The mission ended.
    MissionEnded {
        /// How.
        outcome: Outcome,
    },
}

/// A robot's state at a step, for observers.
#[derive(Clone, Copy, Debug)]
pub struct RobotSnapshot {
    /// What the robot is.
    pub kind: RobotKind,
    /// Ground-truth pose.
    pub truth: Pose2,
    /// Height of the body above the datum (UAV altitude, UGV ground elevation), metres.
    pub z_m: f64,
    /// The robot's own estimate.
    pub estimate: Option<PoseEstimate>,
    /// Velocity command in force (UGVs).
    pub command: Twist2,
}

/// Receives everything a run produces. Every method has an empty default.
pub trait SimObserver {
    /// Each robot's state, every `record_period_s` (see [`SimObserver::record_period_s`]).
    fn on_state(&mut self, _robot: &RobotId, _now: Time, _state: &RobotSnapshot) {}
    /// Odometry as the robot received it (every step).
    fn on_odometry(&mut self, _robot: &RobotId, _odom: &Odometry) {}
    /// A panorama as the robot received it.
    fn on_panorama(&mut self, _robot: &RobotId, _frame: &PanoramaFrame) {}
    /// The obstacle mask of the terrain analysis of a panorama (row-major in its geometry).
    fn on_terrain(&mut self, _robot: &RobotId, _stamp: Time, _geometry: PanoramaGeometry, _obstacle: &[bool]) {}
    /// A reachability scan the robot computed.
    fn on_scan(&mut self, _scan: &ReachabilityScan) {}
    /// A planned path (when it changes).
    fn on_path(&mut self, _robot: &RobotId, _now: Time, _path: &[Point2]) {}
    /// Node transitions of one tick.
    fn on_transitions(&mut self, _robot: &RobotId, _records: &[TransitionRecord]) {}
    /// A team-level event.
    fn on_event(&mut self, _now: Time, _event: &SimEvent) {}
    /// A problem a node or skill reported.
    fn on_problem(&mut self, _robot: &RobotId, _now: Time, _message: &str) {}
    /// A call the simulator made on a robot's seam, in the order made (what a replay needs).
    fn on_seam(&mut self, _robot: &RobotId, _now: Time, _call: SeamInput<'_>) {}
    /// The aerial map as it grows: a robot's copy of the map when it publishes a new version
    /// to the team (the mapping UAV, every `map_publish_period_s` while the map changes), and
    /// once at the start when the robots begin with a prior map. Checked once a simulated
    /// second.
    fn on_map(&mut self, _robot: &RobotId, _now: Time, _map: &AerialMap) {}
    /// How often `on_state` is called, seconds.
    fn record_period_s(&self) -> f64 {
        0.1
    }
}

/// An observer that keeps nothing.
pub struct NoObserver;

impl SimObserver for NoObserver {}

enum Body {
    Ugv {
        ugv: Box<Ugv>,
        odometry: Box<OdometryModel>,
        sensor: Box<PanoramaSensor>,
        truth_source: Option<Box<NoisyPoseSource>>,
        last_scan_stamp: Option<Time>,
    },
    Uav {
        uav: Box<Uav>,
        camera: Box<OrthoCamera>,
        flying_to: Option<Point2>,
    },
    Fixed {
        pose: Pose2,
    },
}

/// Reports a UGV's newest reachability scan and terrain obstacles once each.
fn observe_scan(id: &RobotId, robot: &Robot, last_scan_stamp: &mut Option<Time>, observer: &mut dyn SimObserver) {
    if let Some(nav) = robot.nav()
        && let Some(scan) = nav.latest_scan.as_ref()
        && *last_scan_stamp != Some(scan.stamp)
    {
        *last_scan_stamp = Some(scan.stamp);
        observer.on_scan(scan);
        if let Some((geometry, obstacle)) = nav.terrain_obstacles() {
            observer.on_terrain(id, scan.stamp, geometry, obstacle);
        }
    }
}

struct SimRobot {
    id: RobotId,
    kind: RobotKind,
    pose_input: PoseInput,
    robot: Robot,
    body: Body,
    tick_period_ns: i64,
    next_tick: Time,
    kill_at: Option<Time>,
    killed_s: Option<f64>,
    command: Twist2,
    /// Node ids (depth-first) that ever changed status.
    ticked: Vec<bool>,
    node_paths: Vec<String>,
    /// Seconds holding a claim, per goal.
    claim_time_s: BTreeMap<GoalId, f64>,
    held: Option<GoalId>,
    localization_errors: Vec<f64>,
    /// (simulated time s, position error m) of the robot's own estimate, at most once a second
    /// (sampled at panoramas).
    localization_error_series: Vec<(f64, f64)>,
    last_path_len: usize,
    trajectory: Vec<Point2>,
    /// Driven from outside (see [`ExternalDrivers`]): its own `robot` is not ticked.
    external: bool,
    /// Background work done and waiting for the step it is due back (skill latency).
    work_out: Vec<(Time, FinishedWork)>,
    /// The last map version this robot published that observers were shown.
    map_shown: Option<u64>,
    /// The other UGVs' bodies this step, as obstacles for this one (a UGV's; reused).
    other_bodies: Vec<Obstacle>,
    /// Since when every commanded motion of this UGV was refused (none moved it), and whether
    /// that stretch was counted as a stuck event yet.
    refused_since: Option<Time>,
    refusal_counted: bool,
    /// Times the simulator refused its commanded motion for [`STUCK_AFTER_S`] on end.
    stuck_events: u64,
    /// Where and since when it has stood still (within [`MOTIONLESS_RADIUS_M`]) while its tree
    /// drove it (sampled once a second), and the longest such stretch, seconds.
    still_since: Option<(Point2, Time)>,
    longest_still_driving_s: f64,
}

impl SimRobot {
    fn truth(&self) -> Pose2 {
        match &self.body {
            Body::Ugv { ugv, .. } => ugv.pose(),
            Body::Uav { uav, .. } => uav.pose(),
            Body::Fixed { pose } => *pose,
        }
    }

    fn z_m(&self) -> f64 {
        match &self.body {
            Body::Ugv { ugv, .. } => ugv.base_elevation_m() as f64,
            Body::Uav { uav, .. } => uav.altitude_m(),
            Body::Fixed { .. } => 0.0,
        }
    }

    /// Whether this robot is a UGV whose panorama is due at `now`.
    fn panorama_due(&self, now: Time) -> bool {
        matches!(&self.body, Body::Ugv { sensor, .. } if sensor.due(now))
    }

    fn alive(&self) -> bool {
        self.killed_s.is_none()
    }
}

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
    /// Bytes each directed link may still carry (row-major, sender × receiver).
    link_credit: Vec<u64>,
    /// When the radio last carried sync messages.
    last_sync: Time,
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
}

/// Claim bookkeeping for the "time heading to a goal" metric: events when the held goal
/// changes, time accumulated on the one held.
fn note_claim(r: &mut SimRobot, held: Option<GoalId>, now: Time, dt: f64, observer: &mut dyn SimObserver) {
    let id = r.id.clone();
    if held != r.held {
        if let Some(old) = &r.held {
            observer.on_event(now, &SimEvent::GoalReleased { goal: old.to_string(), by: id.to_string() });
        }
        if let Some(new) = &held {
            observer.on_event(now, &SimEvent::GoalClaimed { goal: new.to_string(), by: id.to_string() });
        }
        r.held = held.clone();
    }
    if let Some(g) = held {
        *r.claim_time_s.entry(g).or_insert(0.0) += dt;
    }
}

/// Every UGV body but the `own`-th, into `out` (reused across steps).
fn others_than(all: &[Obstacle], own: usize, out: &mut Vec<Obstacle>) {
    out.clear();
    out.extend(all.iter().enumerate().filter(|(k, _)| *k != own).map(|(_, o)| *o));
}

/// What a UGV's sensors gave its robot in one step, for the observers.
struct SensedUgv {
    odometry: Odometry,
    /// The pose given as an external input (GPS or noisy truth), if the mission asks for one.
    external_pose: Option<PoseEstimate>,
    /// The panorama, when one was due.
    panorama: Option<Arc<PanoramaFrame>>,
}

/// A live UGV's sensing of one step, fed to its own robot (nothing for other robots, dead ones
/// and those driven from outside). Touches only `r`: robots may be sensed in parallel.
fn sense_ugv(r: &mut SimRobot, world: &World, now: Time) -> Option<SensedUgv> {
    if !r.alive() || r.external {
        return None;
    }
    let truth = r.truth();
    let Body::Ugv { ugv, odometry, sensor, truth_source, .. } = &mut r.body else { return None };
    let odom = odometry.update(now, truth, ugv.twist());
    r.robot.on_odometry(odom);
    let external_pose = truth_source.as_mut().map(|src| src.estimate(now, truth));
    if let Some(estimate) = external_pose {
        r.robot.on_external_pose(estimate);
    }
    let panorama =
        sensor.poll_among(now, world, truth, ugv.base_elevation_m(), odom.pose, &r.other_bodies).map(Arc::new);
    if let Some(frame) = &panorama {
        r.robot.on_panorama(Arc::clone(frame));
        if let Some(est) = r.robot.pose() {
            note_localization(r, &est, truth, now);
        }
    }
    Some(SensedUgv { odometry: odom, external_pose, panorama })
}

/// A UGV's estimate right after a panorama, against the truth: its localization error.
fn note_localization(r: &mut SimRobot, est: &PoseEstimate, truth: Pose2, now: Time) {
    let error = est.pose.position().distance(truth.position());
    r.localization_errors.push(error);
    let t = now.as_secs_f64();
    if r.localization_error_series.last().is_none_or(|&(last, _)| t - last >= 1.0 - 1e-9) {
        r.localization_error_series.push((t, error));
    }
}

/// Counts a problem a robot reported (the first `MAX_PROBLEMS` distinct ones are kept).
fn note_problem(problems: &mut BTreeMap<(String, String), ProblemCount>, robot: &RobotId, message: String, now: Time) {
    let key = (robot.to_string(), message);
    if let Some(p) = problems.get_mut(&key) {
        p.count += 1;
    } else if problems.len() < MAX_PROBLEMS {
        let p = ProblemCount { robot: key.0.clone(), message: key.1.clone(), count: 1, first_s: now.as_secs_f64() };
        problems.insert(key, p);
    }
}

/// Seconds from the first to the last second of a once-a-second trajectory in which the robot
/// moved at least 5 cm (see [`RobotSummary::travel_time_s`]).
fn travel_time_s(trajectory: &[Point2]) -> Option<f64> {
    const STILL_M: f64 = 0.05;
    let moved = |k: &usize| trajectory[*k].distance(trajectory[*k - 1]) >= STILL_M;
    let first = (1..trajectory.len()).find(moved)?;
    let last = (1..trajectory.len()).rev().find(moved)?;
    Some((last - first + 1) as f64)
}

/// What a robot's tick of one step left for the observers.
struct TickedRobot {
    transitions: Recorder,
}

/// Runs the robot's upkeep and tree tick if due (not for dead robots or those driven from
/// outside). Touches only `r`: robots may be ticked in parallel.
fn tick_robot(r: &mut SimRobot, now: Time) -> Option<TickedRobot> {
    if !r.alive() || r.external || now < r.next_tick {
        return None;
    }
    r.next_tick = Time::from_nanos(now.nanos + r.tick_period_ns - 1);
    let mut transitions = Recorder::default();
    r.robot.maintain(now);
    r.robot.tick(now, Some(&mut transitions));
    r.command = r.robot.command().unwrap_or(Twist2::ZERO);
    Some(TickedRobot { transitions })
}

/// `work` applied to every robot, in parallel (rayon's pool) when `parallel`, else in order;
/// the results in robot order. `work` must touch nothing but its robot, so that both ways give
/// the same robots and results.
fn for_each_robot<T, F>(parallel: bool, robots: &mut [SimRobot], work: F) -> Vec<T>
where
    T: Send,
    F: Fn(&mut SimRobot) -> T + Sync + Send,
{
    if parallel && robots.len() > 1 && rayon::current_num_threads() > 1 {
        robots.par_iter_mut().map(work).collect()
    } else {
        robots.iter_mut().map(work).collect()
    }
}

/// A robot's localization update and terrain analysis side by side, when its perception already
/// runs on one of rayon's threads (robots stepped in parallel): a thread left idle while the
/// last robot's panorama is processed takes half of it. From any other thread, one after the
/// other.
fn join_on_rayon(a: &mut (dyn FnMut() + Send), b: &mut (dyn FnMut() + Send)) {
    if rayon::current_thread_index().is_some() {
        rayon::join(a, b);
    } else {
        a();
        b();
    }
}

/// Most bytes a link can bank for later (a few full map versions).
const MAX_LINK_CREDIT_BYTES: u64 = 32 * 1024 * 1024;

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
        let faults = faults_for_mission(&mission, &options.faults);
        let radio = Radio::new(radio_for_mission(&mission), &faults)?;
        let area = operating_area(&mission, &world);
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
            let mut setup =
                RobotSetup::from_mission(&mission, &spec.id, &area, options.seed).map_err(|e| robot_error(&e))?;
            setup.config.map_publish_period_s = options.map_publish_period_s;
            setup.config.map_compression = options.map_compression.clone();
            let start = setup.config.start;
            let id = setup.config.id.clone();
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
                work_out: Vec::new(),
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
        Ok(Simulation {
            ugv_to_ugv: mission.comms.ugv_to_ugv.unwrap_or(true),
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
            link_credit: vec![0; n_robots * n_robots],
            last_sync: Time::from_nanos(-1),
            problems: BTreeMap::new(),
            outcome: None,
            obstacles: Vec::new(),
            ugv_body_class,
            drivers: None,
            driven_outbox: Vec::new(),
            pacer: None,
            map_shown: false,
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

    /// A robot (tests and tools).
    pub fn robot(&self, id: &str) -> Option<&Robot> {
        self.robots.iter().find(|r| r.id.as_str() == id).map(|r| &r.robot)
    }

    /// A robot's runtime (tests and tools).
    pub fn runtime(&self, id: &str) -> Option<&RobotRuntime> {
        self.robot(id).map(Robot::runtime)
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
            if let Some(map) = r.robot.runtime().map().filter(|m| fresh || m.map().known_cells() > 0) {
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
                r.robot.halt(now, None);
                if let Some(d) = self.drivers.as_mut().filter(|_| r.external) {
                    d.halt(&r.id, now);
                }
                observer.on_seam(&r.id, now, SeamInput::Halt);
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
    /// then the work each robot has due now is taken and done, to come back after the latency.
    fn exchange_work(&mut self, observer: &mut dyn SimObserver) {
        let Some(latency) = self.options.skill_latency else { return };
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
            let mut k = 0;
            while k < r.work_out.len() {
                if r.work_out[k].0 > now {
                    k += 1;
                    continue;
                }
                let (_, work) = r.work_out.remove(k);
                observer.on_seam(&r.id, now, SeamInput::FinishWork(work.id()));
                let perception = work.kind() == WorkKind::Perception;
                r.robot.finish_work(work);
                if perception && let Body::Ugv { last_scan_stamp, .. } = &mut r.body {
                    observe_scan(&r.id, &r.robot, last_scan_stamp, observer);
                }
            }
            let work = r.robot.take_work(now);
            if work.is_empty() {
                continue;
            }
            let ids: Vec<u64> = work.iter().map(|w| w.id()).collect();
            observer.on_seam(&r.id, now, SeamInput::TakeWork(&ids));
            for w in work {
                let due = Time::from_nanos(now.nanos + Time::from_secs_f64(latency.of(w.kind())).nanos);
                r.work_out.push((due, w.run()));
            }
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
                        observer.on_seam(&r.id, now, SeamInput::Odometry(&s.odometry));
                        if let Some(estimate) = &s.external_pose {
                            observer.on_seam(&r.id, now, SeamInput::ExternalPose(estimate));
                        }
                        if let Some(frame) = &s.panorama {
                            observer.on_panorama(&r.id, frame);
                            observer.on_seam(&r.id, now, SeamInput::Panorama(frame));
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
                    observer.on_seam(&r.id, now, SeamInput::ExternalPose(&estimate));
                    r.robot.on_external_pose(estimate);
                    let tiles = camera.reveal(world, pose);
                    observer.on_seam(&r.id, now, SeamInput::CameraTiles(&tiles));
                    r.robot.on_camera_tiles(&tiles, now);
                }
                Body::Fixed { pose } => {
                    if alive {
                        let estimate = PoseEstimate { stamp: now, pose: *pose, covariance: [0.0; 9], confidence: 1.0 };
                        if let Some(d) = self.drivers.as_mut().filter(|_| r.external) {
                            d.pose(&r.id, &estimate, 0.0);
                            continue;
                        }
                        observer.on_seam(&r.id, now, SeamInput::ExternalPose(&estimate));
                        r.robot.on_external_pose(estimate);
                    }
                }
            }
        }
    }

    fn sync_radio(&mut self, observer: &mut dyn SimObserver) {
        let nodes: Vec<RadioNode> =
            self.robots.iter().map(|r| RadioNode { position: r.truth().position(), alive: r.alive() }).collect();
        let mut links = std::mem::take(&mut self.links);
        self.radio.links_into(self.now, &nodes, self.options.sync_period_s, &mut links);
        if !self.ugv_to_ugv {
            let robots = &self.robots;
            links.retain(|(i, j, _)| !(robots[*i].kind == RobotKind::Ugv && robots[*j].kind == RobotKind::Ugv));
        }
        let n = self.robots.len();
        // Unused bytes of a link carry over while it stays up, so an item larger than one
        // period's budget (a map version) goes through after enough periods, as on a real
        // link; the credit is lost when the link drops.
        let mut credit = vec![0u64; n * n];
        for &(i, j, link) in &links {
            let tiers = match link.tier {
                LinkTier::All => TierSet::ALL,
                LinkTier::Small => TierSet::only(Tier::Coordination),
            };
            for (a, b) in [(i, j), (j, i)] {
                let k = a * n + b;
                let was_up = self.last_link.get(k).copied().flatten() == Some(self.last_sync);
                let carried = if was_up { self.link_credit.get(k).copied().unwrap_or(0) } else { 0 };
                if let Some(c) = credit.get_mut(k) {
                    *c = carried.saturating_add(link.budget_bytes).min(MAX_LINK_CREDIT_BYTES);
                }
                if let Some(slot) = self.last_link.get_mut(k) {
                    *slot = Some(self.now);
                }
            }
            for (a, b) in [(i, j), (j, i)] {
                let k = a * n + b;
                let budget = credit.get(k).copied().unwrap_or(0);
                let from = self.robots[a].id.clone();
                let to = self.robots[b].id.clone();
                // Over the wire: encoded, decoded and checked by the receiver. A driven robot's
                // messages were sent already; the link carries those it has room for (a small
                // link, coordination only, cannot tell tiers apart in them: it carries none).
                let lockstep = self.drivers.as_ref().is_some_and(|d| d.lockstep());
                let messages: Vec<Vec<u8>> = if self.robots[a].external && lockstep {
                    let budget_bytes = usize::try_from(budget).unwrap_or(usize::MAX);
                    match self.drivers.as_mut() {
                        Some(d) => d.team_message_for(&from, &to, tiers, budget_bytes).into_iter().collect(),
                        None => Vec::new(),
                    }
                } else if self.robots[a].external {
                    let mut budget = if link.tier == LinkTier::All { budget } else { 0 };
                    let mut out = Vec::new();
                    self.driven_outbox.retain(|m| {
                        if m.from != from || m.to != to {
                            return true;
                        }
                        if (m.bytes.len() as u64) <= budget {
                            budget -= m.bytes.len() as u64;
                            out.push(m.bytes.clone());
                        }
                        false
                    });
                    out
                } else {
                    let budget_bytes = usize::try_from(budget).unwrap_or(usize::MAX);
                    let sent = self.robots[a].robot.team_message_for(&to, tiers, budget_bytes);
                    let call = SeamInput::TeamOut { to: &to, tiers, budget_bytes, sent: sent.as_deref() };
                    observer.on_seam(&from, self.now, call);
                    sent.into_iter().collect()
                };
                for bytes in messages {
                    if let Some(c) = credit.get_mut(k) {
                        *c = c.saturating_sub(bytes.len() as u64);
                    }
                    match self.drivers.as_mut().filter(|_| self.robots[b].external) {
                        Some(d) => d.deliver_team_message(&to, &from, &bytes),
                        None => {
                            observer.on_seam(&to, self.now, SeamInput::TeamIn { from: &from, bytes: &bytes });
                            let _ = self.robots[b].robot.on_team_message(&from, &bytes);
                        }
                    }
                }
            }
        }
        // What driven robots sent over links that are down is lost, as on a radio.
        self.driven_outbox.clear();
        self.link_credit = credit;
        self.last_sync = self.now;
        self.links = links;
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
                let tick = SeamInput::Tick { command: r.robot.command(), flight: r.robot.flight() };
                observer.on_seam(&r.id, now, tick);
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

    /// Team-level goal bookkeeping (earliest identification, claim and visit over all robots).
    fn track_goals(&mut self, observer: &mut dyn SimObserver) {
        let now = self.now;
        let mut own_visits = Vec::new();
        for (ri, r) in self.robots.iter().enumerate() {
            let goals = match self.drivers.as_ref().filter(|_| r.external) {
                Some(d) => d.goals(&r.id),
                None => r.robot.team().goals(),
            };
            for g in goals {
                for a in &g.aliases {
                    self.aliases.insert(a.clone(), g.id.clone());
                }
                let entry = match self.goals.get_mut(&g.id) {
                    Some(e) => e,
                    None => {
                        let summary = GoalSummary {
                            id: g.id.to_string(),
                            position: [g.position.x, g.position.y],
                            origin: match g.origin {
                                GoalOrigin::Detected => "detected",
                                GoalOrigin::Mission => "mission",
                                GoalOrigin::Basestation => "basestation",
                            }
                            .to_string(),
                            identified_s: g.identified_at.as_secs_f64(),
                            identified_by: g.identified_by.to_string(),
                            claimed_s: None,
                            claimed_by: None,
                            visited_s: None,
                            visited_by: None,
                            revisits_in_contact: 0,
                        };
                        observer.on_event(
                            now,
                            &SimEvent::GoalIdentified {
                                goal: summary.id.clone(),
                                by: summary.identified_by.clone(),
                                position: summary.position,
                            },
                        );
                        self.goal_order.push(g.id.clone());
                        self.goals.entry(g.id.clone()).or_insert(summary)
                    }
                };
                for c in &g.claims {
                    let t = c.stamp.as_secs_f64();
                    if entry.claimed_s.is_none_or(|s| t < s) {
                        entry.claimed_s = Some(t);
                        entry.claimed_by = Some(c.robot.to_string());
                    }
                }
                if let Some((t, by)) = &g.visited
                    && by == &r.id
                {
                    own_visits.push((g.id.clone(), ri, *t));
                }
                if let Some((t, by)) = &g.visited {
                    let t = t.as_secs_f64();
                    if entry.visited_s.is_none() {
                        observer.on_event(now, &SimEvent::GoalVisited { goal: entry.id.clone(), by: by.to_string() });
                    }
                    if entry.visited_s.is_none_or(|s| t < s) {
                        entry.visited_s = Some(t);
                        entry.visited_by = Some(by.to_string());
                    }
                }
            }
        }
        self.record_own_visits(own_visits);
    }

    /// Records visits robots made themselves; a visit to a goal another robot visited earlier
    /// counts as a revisit in contact when the two had a direct link after the first visit
    /// (the team state should have told the second robot in time).
    fn record_own_visits(&mut self, visits: Vec<(GoalId, usize, Time)>) {
        let n = self.robots.len();
        for (goal, robot, t2) in visits {
            let canonical = self.aliases.get(&goal).cloned().unwrap_or_else(|| goal.clone());
            if self.own_visits.contains_key(&(canonical.clone(), robot)) {
                continue;
            }
            let in_contact = self.own_visits.iter().any(|((g, other), t1)| {
                *g == canonical
                    && *other != robot
                    && *t1 < t2
                    && self.last_link.get(*other * n + robot).copied().flatten().is_some_and(|l| l > *t1)
            });
            self.own_visits.insert((canonical, robot), t2);
            if in_contact && let Some(entry) = self.goals.get_mut(&goal) {
                entry.revisits_in_contact += 1;
            }
        }
    }

    /// The goals with the ids robots merged (identified twice within the deconfliction radius)
    /// folded into their canonical goal: earliest identification, claim and visit win.
    fn merged_goals(&self) -> Vec<GoalSummary> {
        let canonical = |id: &GoalId| {
            let mut c = id;
            // Alias chains are short; the bound guards against a cycle in bad data.
            for _ in 0..8 {
                match self.aliases.get(c) {
                    Some(next) if next != c => c = next,
                    _ => break,
                }
            }
            c.clone()
        };
        let mut merged: BTreeMap<GoalId, GoalSummary> = BTreeMap::new();
        let mut order = Vec::new();
        for id in &self.goal_order {
            let Some(g) = self.goals.get(id) else { continue };
            let c = canonical(id);
            match merged.get_mut(&c) {
                None => {
                    let mut first = g.clone();
                    if let Some(cg) = self.goals.get(&c) {
                        first.id = cg.id.clone();
                        first.position = cg.position;
                    }
                    merged.insert(c.clone(), first);
                    order.push(c);
                }
                Some(m) => {
                    m.revisits_in_contact += g.revisits_in_contact;
                    if g.identified_s < m.identified_s {
                        m.identified_s = g.identified_s;
                        m.identified_by = g.identified_by.clone();
                    }
                    if let Some(t) = g.claimed_s
                        && m.claimed_s.is_none_or(|s| t < s)
                    {
                        m.claimed_s = Some(t);
                        m.claimed_by = g.claimed_by.clone();
                    }
                    if let Some(t) = g.visited_s
                        && m.visited_s.is_none_or(|s| t < s)
                    {
                        m.visited_s = Some(t);
                        m.visited_by = g.visited_by.clone();
                    }
                }
            }
        }
        order.into_iter().filter_map(|c| merged.remove(&c)).collect()
    }

    fn all_goals_visited(&self) -> bool {
        let goals = self.merged_goals();
        if goals.is_empty() || goals.iter().any(|g| g.visited_s.is_none()) {
            return false;
        }
        // With detection in a generated world, every vehicle cluster must have been found too.
        match self.cluster_summary(&goals) {
            Some(c) => c.visited >= c.total,
            None => true,
        }
    }

    fn cluster_summary(&self, goals: &[GoalSummary]) -> Option<ClusterSummary> {
        let detect = self.mission.goals.as_ref()?.detect.as_ref()?;
        let clusters = &self.world.meta.vehicle_clusters;
        if clusters.is_empty() {
            return None;
        }
        // The detector's own defaults for what the mission leaves unset.
        let defaults = spomp_mapping::GoalDetectionParams::default();
        let match_radius_m = detect.merge_distance_m.unwrap_or(defaults.merge_distance_m)
            + detect.placement_region_m.unwrap_or(defaults.placement_region_m);
        let near =
            |c: &Point2, g: &GoalSummary| Point2::new(g.position[0], g.position[1]).distance(*c) <= match_radius_m;
        let found = clusters.iter().filter(|c| goals.iter().any(|g| near(c, g))).count();
        let visited = clusters.iter().filter(|c| goals.iter().any(|g| g.visited_s.is_some() && near(c, g))).count();
        Some(ClusterSummary { total: clusters.len(), found, visited, match_radius_m })
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

    fn finish(mut self, _observer: &mut dyn SimObserver, wall_s: f64) -> RunResult {
        let end_s = self.now.as_secs_f64();
        // Each tree's status at the end of the run, before the halt that stops it.
        let final_status: Vec<String> = self
            .robots
            .iter()
            .map(|r| match self.drivers.as_ref().filter(|_| r.external).and_then(|d| d.tree_status(&r.id)) {
                Some(status) => status,
                None => format!("{:?}", r.robot.tree().status()).to_lowercase(),
            })
            .collect();
        if let Some(d) = self.drivers.as_mut() {
            d.end_run();
        }
        for r in &mut self.robots {
            if r.alive() {
                r.robot.halt(self.now, None);
            }
        }
        let goals = self.merged_goals();
        let robots = self
            .robots
            .iter()
            .enumerate()
            .map(|(i, r)| {
                let visited_goals: Vec<&GoalSummary> =
                    goals.iter().filter(|g| g.visited_by.as_deref() == Some(r.id.as_str())).collect();
                let heading: f64 = r
                    .claim_time_s
                    .iter()
                    .filter(|(g, _)| visited_goals.iter().any(|v| v.id == g.to_string()))
                    .fold(0.0, |acc, (_, t)| acc + t);
                let (distance_m, collisions) = match &r.body {
                    Body::Ugv { ugv, .. } => (ugv.distance_m(), ugv.collisions()),
                    Body::Uav { uav, .. } => (uav.distance_m(), 0),
                    Body::Fixed { .. } => (0.0, 0),
                };
                RobotSummary {
                    id: r.id.to_string(),
                    kind: r.kind.to_string(),
                    distance_m,
                    heading_to_goal_fraction: if end_s > 0.0 { heading / end_s } else { 0.0 },
                    travel_time_s: travel_time_s(&r.trajectory),
                    collisions,
                    stuck_events: r.stuck_events,
                    longest_motionless_driving_s: r.longest_still_driving_s,
                    localization: match r.kind {
                        RobotKind::Ugv => r.pose_input.name().to_string(),
                        RobotKind::Uav => "gps".to_string(),
                        RobotKind::Basestation => "surveyed".to_string(),
                    },
                    localization_error_m: ErrorStats::of(&r.localization_errors),
                    goals_visited: visited_goals.len() as u32,
                    killed_s: r.killed_s,
                    tree_status: final_status.get(i).cloned().unwrap_or_default(),
                    navigation: r.robot.nav().map(|n| {
                        let p = &n.params;
                        NavigationInForce {
                            learning: p.global.learning.enabled,
                            graph_updates: p.global.experience.graph_updates,
                            sharing: match p.global.sharing.mode {
                                spomp_global_planner::SharingMode::None => "none",
                                spomp_global_planner::SharingMode::Downsampled => "downsampled",
                                spomp_global_planner::SharingMode::All => "all",
                            }
                            .to_string(),
                            slope_threshold: p.local.terrain.slope_threshold,
                            inflation_m: p.local.terrain.inflation_m,
                            max_speed_mps: p.local.dwa.max_speed_mps,
                            stuck_timeout_s: p.watchdog.stuck_timeout_s,
                        }
                    }),
                }
            })
            .collect();
        let nodes_total = self.robots.iter().map(|r| r.ticked.len()).sum();
        let nodes_exercised = self.robots.iter().map(|r| r.ticked.iter().filter(|t| **t).count()).sum();
        let nodes_never_ticked = self
            .robots
            .iter()
            .flat_map(|r| {
                r.ticked.iter().zip(&r.node_paths).filter(|(t, _)| !**t).map(move |(_, p)| format!("{}: {p}", r.id))
            })
            .collect();
        let summary = RunSummary {
            mission: self.mission.mission.clone(),
            seed: self.options.seed,
            outcome: self.outcome.unwrap_or(Outcome::TimeLimit),
            end_s,
            time_limit_s: self.time_limit.as_secs_f64(),
            navigation: "skills (global planner graph + panorama local planner)".to_string(),
            goals_visited: goals.iter().filter(|g| g.visited_s.is_some()).count(),
            clusters: self.cluster_summary(&goals),
            goals,
            robots,
            wall_s,
            speedup: if wall_s > 0.0 { end_s / wall_s } else { 0.0 },
            nodes_exercised,
            nodes_total,
            nodes_never_ticked,
            problems: self.problems.into_values().collect(),
        };
        let localization_errors = self
            .robots
            .iter()
            .filter(|r| r.kind == RobotKind::Ugv)
            .map(|r| (r.id.clone(), r.localization_error_series.clone()))
            .collect();
        let trajectories = self.robots.into_iter().map(|r| (r.id, r.kind, r.trajectory)).collect();
        RunResult { summary, world: self.world, trajectories, localization_errors }
    }
}
