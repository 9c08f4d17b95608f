//! The seam between a robot and the world: one [`Robot`] per robot, driven the same way by
//! every adapter.
//!
//! Per control period an adapter:
//! 1. pushes what arrived: odometry, panoramas, an external pose (GPS, a surveyed position,
//!    simulator truth where the mission asks), camera tiles (the UAV), team-state messages with
//!    the peer they came from;
//! 2. calls [`Robot::tick`] (upkeep, then the tree) at the robot's tick rate — and, when the
//!    heavy skills run in the background ([`Robot::set_background_skills`]), hands the work
//!    [`Robot::take_work`] gives to another thread and each result back with
//!    [`Robot::finish_work`] between ticks;
//! 3. pulls what the robot wants done: [`Robot::command`] (UGV velocity) or [`Robot::flight`]
//!    (UAV target) — `None` is stop / hover, so a command never outlives the node that issued
//!    it — the team-state message for each peer it can reach ([`Robot::team_message_for`]),
//!    and the problems met ([`Robot::take_problems`]).
//!
//! Each of these calls is one [`SeamCall`] made through [`Robot::call`]; a robot told to
//! record ([`Robot::record_seam`]) keeps them, with their answers, for its observers
//! ([`Robot::deliver_recorded`]).

use std::sync::Arc;

use spomp_behaviors::mission::{BuildError, BuildOptions, LoadedMission, build_executor};
use spomp_behaviors::{NodeRegistry, Status, TreeExecutor, TreeObserver};
use spomp_core::{
    FlightCommand, MapTile, Odometry, PanoramaFrame, Point2, PoseEstimate, ReachabilityScan, RobotId, RobotKind, Time,
    Twist2,
};
use std::collections::BTreeMap;

use spomp_behaviors::blackboard::BbValue;
use spomp_teamstate::{ApplyReport, RestoreSummary, SyncError, TeamSecurity, TeamState, TeamStateError, TierSet};

use crate::runtime::{FinishedWork, NavStack, RobotRuntime, RuntimeError, SkillWork};
use crate::seam::{RobotObserver, SeamCall, SeamReply, TickOutput, UnknownWork};
use crate::setup::{OperatingArea, PoseInput, RobotSetup, SetupError};

/// Why a robot could not be built.
#[derive(Debug, thiserror::Error)]
pub enum RobotError {
    /// The mission did not load cleanly.
    #[error("the mission is not valid; run `spomp validate` on it")]
    InvalidMission,
    /// The robot's settings.
    #[error(transparent)]
    Setup(#[from] SetupError),
    /// A skill refused its parameters.
    #[error(transparent)]
    Runtime(#[from] RuntimeError),
    /// Its role did not compile.
    #[error("role `{0}` did not compile")]
    Role(String),
    /// Its tree could not be built.
    #[error(transparent)]
    Build(#[from] BuildError),
    /// A goal of the mission was refused by the team state.
    #[error("goals.manual: {0}")]
    MissionGoal(String),
}

/// One robot: its runtime (state and continuous skills) and its behaviour tree.
pub struct Robot {
    runtime: RobotRuntime,
    tree: TreeExecutor<RobotRuntime>,
    pose_input: PoseInput,
    tick_hz: f64,
    /// Blackboard entries kept across reboots (the role's `persist`).
    persist: Vec<String>,
    /// The first tick that found the robot's first inputs missing ([`Robot::tick`]), and
    /// whether that wait was reported.
    waiting_since: Option<Time>,
    wait_reported: bool,
    /// The calls made on the seam not yet delivered to observers, when recording.
    seam_log: Option<Vec<(Time, SeamCall)>>,
    /// Finished work handed over and not yet applied ([`Robot::deliver_work`]).
    delivered: Vec<FinishedWork>,
    /// The team-state bytes it sent and received ([`Robot::team_traffic`]).
    traffic: TeamTraffic,
}

/// The team-state traffic of a robot since it was built: what it sent (each answer of a
/// [`SeamCall::TeamOut`]) and what it received, kept by the robot so that counting bytes needs
/// no seam recording.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize)]
pub struct TeamTraffic {
    /// Messages sent.
    pub sent_messages: u64,
    /// Bytes sent in messages a link allowed every tier.
    pub sent_bytes_all_tiers: u64,
    /// Bytes sent in messages limited to fewer tiers (a coordination-only link, a channel per
    /// tier).
    pub sent_bytes_fewer_tiers: u64,
    /// Bytes sent, by the tier they carried (coordination, scans, maps); a message's header
    /// counts as coordination.
    pub sent_bytes_by_tier: [u64; 3],
    /// Messages received (taken or refused).
    pub received_messages: u64,
    /// Bytes received.
    pub received_bytes: u64,
}

impl TeamTraffic {
    /// Every byte sent.
    pub fn sent_bytes(&self) -> u64 {
        self.sent_bytes_all_tiers + self.sent_bytes_fewer_tiers
    }

    fn count_sent(&mut self, tiers: TierSet, message: &spomp_teamstate::SyncMessage, len: usize) {
        self.sent_messages += 1;
        if tiers == TierSet::ALL {
            self.sent_bytes_all_tiers += len as u64;
        } else {
            self.sent_bytes_fewer_tiers += len as u64;
        }
        for (total, b) in self.sent_bytes_by_tier.iter_mut().zip(message.bytes_by_tier(len)) {
            *total += b;
        }
    }
}

/// Where a named seam method's call answered with another call's reply (never: each call
/// gives its own); the fallback keeps production code free of panics.
#[cold]
fn mismatched_reply() {
    debug_assert!(false, "a seam call answered with another call's reply");
}

/// A robot still without its first inputs this long after its first tick reports it once,
/// seconds.
pub const FIRST_INPUTS_REPORT_S: f64 = 10.0;

/// Why a robot's saved state was not taken. Nothing of it was.
#[derive(Debug, thiserror::Error)]
pub enum ResumeError {
    /// The bytes are not a robot state.
    #[error("not a robot state: {0}")]
    Malformed(String),
    /// The team state in it was refused.
    #[error(transparent)]
    Team(#[from] spomp_teamstate::SnapshotError),
    /// A kept blackboard entry does not fit the tree.
    #[error("kept entry `{0}`: {1}")]
    Entry(String, String),
}

impl Robot {
    /// Robot `id` of a validated mission, over `area`, with `run_seed` seeding its random
    /// stream; its tree is built from `registry` (the robot layer's [`crate::registry`], or a
    /// lab's own with more node types).
    pub fn from_mission(
        loaded: &LoadedMission,
        id: &str,
        area: &OperatingArea,
        run_seed: u64,
        registry: &NodeRegistry<RobotRuntime>,
    ) -> Result<Self, RobotError> {
        let mission = loaded.mission.as_ref().filter(|_| loaded.is_valid()).ok_or(RobotError::InvalidMission)?;
        let setup = RobotSetup::from_mission(mission, id, area, run_seed)?;
        Self::from_setup(loaded, setup, registry)
    }

    /// A robot from its setup (an adapter may adjust the setup first: the simulator's map
    /// publishing rate, say).
    pub fn from_setup(
        loaded: &LoadedMission,
        setup: RobotSetup,
        registry: &NodeRegistry<RobotRuntime>,
    ) -> Result<Self, RobotError> {
        let mission = loaded.mission.as_ref().filter(|_| loaded.is_valid()).ok_or(RobotError::InvalidMission)?;
        let role = loaded.roles.get(&setup.role).ok_or_else(|| RobotError::Role(setup.role.clone()))?;
        let start = setup.config.start;
        let robot_id = setup.config.id.clone();
        let mut runtime = RobotRuntime::from_config(setup.config)?;
        runtime.note_problems(setup.warnings);
        if let Some(goals) = &mission.goals {
            for (k, g) in goals.manual.iter().enumerate() {
                runtime
                    .team_state_mut()
                    .add_mission_goal(k as u32, Point2::new(g.x_m, g.y_m))
                    .map_err(|e| RobotError::MissionGoal(e.to_string()))?;
            }
        }
        // The area's georeference, else one the robot's own sections give it (its ROS 2
        // section's `gps_origin`, through that section's registered owner).
        let map_origin = setup.map_origin.or_else(|| {
            let spec = mission.team.get(setup.index).filter(|r| r.id == robot_id.as_str())?;
            registry.catalog().robot_geo_reference(spec)
        });
        let build = BuildOptions { base_dir: Some(loaded.base_dir()), map_origin };
        let tree = build_executor(role, registry, &robot_id, start, build)?;
        let tick_hz = if setup.tick_hz.is_finite() && setup.tick_hz > 0.0 {
            setup.tick_hz
        } else {
            spomp_behaviors::mission::schema::DEFAULT_TICK_HZ
        };
        Ok(Robot {
            runtime,
            tree,
            pose_input: setup.pose_input,
            tick_hz,
            persist: role.persist.clone(),
            waiting_since: None,
            wait_reported: false,
            seam_log: None,
            delivered: Vec::new(),
            traffic: TeamTraffic::default(),
        })
    }

    // --- identity -------------------------------------------------------------------------------

    /// The robot's id.
    pub fn id(&self) -> &RobotId {
        self.runtime.id()
    }

    /// Its kind.
    pub fn kind(&self) -> RobotKind {
        self.runtime.kind()
    }

    /// Where its map-frame pose must come from.
    pub fn pose_input(&self) -> PoseInput {
        self.pose_input
    }

    /// Its tree's tick rate, per second.
    pub fn tick_hz(&self) -> f64 {
        self.tick_hz
    }

    // --- the seam ------------------------------------------------------------------------------

    /// Makes one call on the seam at `now` and returns it with its answers filled in, and what
    /// else it gives its caller. Every named input, [`Self::tick`], [`Self::halt`],
    /// [`Self::team_message_for`], [`Self::take_work`], [`Self::finish_work`] and
    /// [`Self::resume`] is this call; a robot recording ([`Self::record_seam`]) keeps each call
    /// made for its observers.
    pub fn call(&mut self, now: Time, call: SeamCall) -> (SeamCall, SeamReply) {
        self.call_observed(now, call, None)
    }

    /// [`Self::call`], a tick's node transitions going to `tree` as they happen.
    pub fn call_observed(
        &mut self,
        now: Time,
        call: SeamCall,
        tree: Option<&mut dyn TreeObserver>,
    ) -> (SeamCall, SeamReply) {
        let (call, reply) = self.dispatch(now, call, tree);
        if let Some(log) = self.seam_log.as_mut() {
            log.push((now, call.clone()));
        }
        (call, reply)
    }

    fn dispatch(
        &mut self,
        now: Time,
        mut call: SeamCall,
        tree: Option<&mut dyn TreeObserver>,
    ) -> (SeamCall, SeamReply) {
        let reply = match &mut call {
            SeamCall::Odometry(odom) => {
                self.runtime.on_odometry(*odom);
                SeamReply::Done
            }
            SeamCall::Panorama(frame) => {
                self.runtime.on_panorama(Arc::clone(frame));
                SeamReply::Done
            }
            SeamCall::ExternalPose(estimate) => {
                self.runtime.on_external_pose(*estimate);
                SeamReply::Done
            }
            SeamCall::CameraTiles(tiles) => {
                self.runtime.on_camera_tiles(tiles, now);
                SeamReply::Done
            }
            SeamCall::TeamIn { from, bytes } => {
                self.traffic.received_messages += 1;
                self.traffic.received_bytes += bytes.len() as u64;
                let result = self.runtime.team_state_mut().apply_bytes(from, bytes);
                if let Err(e) = &result {
                    self.runtime.report(format!("sync from {from} rejected: {e}"));
                }
                SeamReply::TeamIn(result)
            }
            SeamCall::TeamOut { to, tiers, budget_bytes, sent } => {
                *sent = self.runtime.team_state_mut().make_sync(to, *tiers, *budget_bytes).map(|m| {
                    let bytes = m.encode();
                    self.traffic.count_sent(*tiers, &m, bytes.len());
                    bytes
                });
                SeamReply::Done
            }
            SeamCall::Tick(out) => {
                self.runtime.maintain(now);
                let status = self.tick_tree(now, tree);
                *out = TickOutput { command: self.runtime.command(), flight: self.runtime.flight() };
                SeamReply::Tick(status)
            }
            SeamCall::Halt => {
                self.tree.halt(now, &mut self.runtime, tree);
                SeamReply::Done
            }
            SeamCall::TakeWork(ids) => {
                let work = self.runtime.take_work(now);
                *ids = work.iter().map(SkillWork::id).collect();
                SeamReply::TakeWork(work)
            }
            SeamCall::FinishWork(id) => match self.delivered.iter().position(|w| w.id() == *id) {
                Some(k) => {
                    let work = self.delivered.swap_remove(k);
                    self.runtime.finish_work(work);
                    SeamReply::FinishWork(Ok(()))
                }
                None => SeamReply::FinishWork(Err(UnknownWork(*id))),
            },
            SeamCall::Resume(bytes) => SeamReply::Resume(self.resume_from(bytes)),
        };
        (call, reply)
    }

    /// Whether the robot keeps every call made on its seam for its observers (a recorder that
    /// logs them, a replay check): off by default, as it costs a copy of each call's data.
    /// Turning it on again keeps what is recorded.
    pub fn record_seam(&mut self, on: bool) {
        match (on, self.seam_log.is_some()) {
            (true, false) => self.seam_log = Some(Vec::new()),
            (false, true) => self.seam_log = None,
            _ => {}
        }
    }

    /// Hands `observer` the calls made on the seam since the last delivery, in the order made
    /// (none unless recording, [`Self::record_seam`]). Adapters that step several robots on
    /// several threads deliver each robot's calls afterwards, in robot order: the log is the
    /// same however the robots were stepped.
    pub fn deliver_recorded(&mut self, observer: &mut dyn RobotObserver) {
        let Some(log) = self.seam_log.as_mut() else { return };
        if log.is_empty() {
            return;
        }
        let calls = std::mem::take(log);
        let id = self.runtime.id();
        for (now, call) in &calls {
            observer.on_seam(id, *now, call);
        }
        // Keeps the buffer's capacity for the next step.
        let mut calls = calls;
        calls.clear();
        if let Some(log) = self.seam_log.as_mut() {
            *log = calls;
        }
    }

    // --- inputs -----------------------------------------------------------------------------------

    /// New odometry (robot frame) at `now`.
    pub fn on_odometry(&mut self, now: Time, odom: Odometry) {
        self.call(now, SeamCall::Odometry(odom));
    }

    /// A new depth + semantic panorama at `now`.
    pub fn on_panorama(&mut self, now: Time, frame: Arc<PanoramaFrame>) {
        self.call(now, SeamCall::Panorama(frame));
    }

    /// A map-frame pose from outside at `now` (see [`Robot::pose_input`]).
    pub fn on_external_pose(&mut self, now: Time, estimate: PoseEstimate) {
        self.call(now, SeamCall::ExternalPose(estimate));
    }

    /// Aerial-map tiles from the robot's own camera (the UAV) at `now`.
    pub fn on_camera_tiles(&mut self, now: Time, tiles: Vec<MapTile>) {
        self.call(now, SeamCall::CameraTiles(tiles));
    }

    /// A team-state sync message from peer `from`, as bytes off the link. A message that does
    /// not decode or check is rejected whole, reported, and changes nothing; the error says why.
    pub fn on_team_message(&mut self, now: Time, from: &RobotId, bytes: Vec<u8>) -> Result<ApplyReport, SyncError> {
        match self.call(now, SeamCall::TeamIn { from: from.clone(), bytes }).1 {
            SeamReply::TeamIn(result) => result,
            _ => {
                mismatched_reply();
                Ok(ApplyReport::default())
            }
        }
    }

    // --- the team link on robots ------------------------------------------------------------------

    /// Signs this robot's team-state records and messages and checks its peers' (a secured
    /// team; see `spomp_teamstate::auth`).
    pub fn secure_team(&mut self, security: Arc<TeamSecurity>) -> Result<(), TeamStateError> {
        self.runtime.team_state_mut().set_security(security)
    }

    /// Which boot of this robot this is (larger at every boot): peers forget what they knew of
    /// its earlier messages.
    pub fn set_team_session(&mut self, session: u64) {
        self.runtime.team_state_mut().set_session(session);
    }

    /// What a reboot resumes from: the team state and the role's kept blackboard entries.
    pub fn resume_state(&self) -> Vec<u8> {
        let bb = self.tree.blackboard();
        let entries: BTreeMap<&str, serde_json::Value> =
            self.persist.iter().filter_map(|name| Some((name.as_str(), bb.get_by_name(name)?.to_json()?))).collect();
        let entries = serde_json::to_vec(&entries).unwrap_or_else(|_| b"{}".to_vec());
        let mut out = Vec::with_capacity(entries.len() + 1024);
        out.extend_from_slice(&(entries.len() as u32).to_le_bytes());
        out.extend_from_slice(&entries);
        out.extend_from_slice(&self.runtime.team().snapshot());
        out
    }

    /// Takes a state made by [`Robot::resume_state`] before a reboot: its team state (checked
    /// as a peer's would be) and kept entries. Call it before the first tick, after
    /// [`Robot::secure_team`]. Refused whole if any part does not check.
    pub fn resume(&mut self, now: Time, bytes: Vec<u8>) -> Result<RestoreSummary, ResumeError> {
        match self.call(now, SeamCall::Resume(bytes)).1 {
            SeamReply::Resume(result) => result,
            _ => {
                mismatched_reply();
                Err(ResumeError::Malformed("no answer".into()))
            }
        }
    }

    fn resume_from(&mut self, bytes: &[u8]) -> Result<RestoreSummary, ResumeError> {
        let (len, rest) = bytes.split_first_chunk::<4>().ok_or_else(|| ResumeError::Malformed("cut short".into()))?;
        let (entries, team) = rest
            .split_at_checked(u32::from_le_bytes(*len) as usize)
            .ok_or_else(|| ResumeError::Malformed("cut short".into()))?;
        let entries: BTreeMap<String, serde_json::Value> =
            serde_json::from_slice(entries).map_err(|e| ResumeError::Malformed(e.to_string()))?;
        let mut values = Vec::new();
        for (name, json) in &entries {
            if !self.persist.contains(name) {
                return Err(ResumeError::Entry(name.clone(), "the role does not keep it (`persist`)".into()));
            }
            let ty = self
                .tree
                .blackboard()
                .get_by_name(name)
                .map(|v| v.port_type())
                .ok_or_else(|| ResumeError::Entry(name.clone(), "not on the blackboard".into()))?;
            values.push((name.clone(), BbValue::from_json(ty, json).map_err(|e| ResumeError::Entry(name.clone(), e))?));
        }
        let mut team_state = self.runtime.team().clone();
        let summary = team_state.restore(team)?;
        *self.runtime.team_state_mut() = team_state;
        for (name, value) in values {
            self.tree.blackboard_mut().set_by_name(&name, value);
        }
        Ok(summary)
    }

    // --- stepping ---------------------------------------------------------------------------------

    /// Background upkeep at `now` (team-state clock, global planner upkeep), then one tick of the
    /// tree; transitions go to `observer`. A tree that has finished
    /// (success or failure) stays finished: it is not ticked again and the robot commands
    /// nothing, so a mission's `all_trees_done` sees every robot done together. A role that
    /// should run again says so with `repeat`. Upkeep goes on.
    ///
    /// The tree does not start before the robot's first inputs ([`Self::has_first_inputs`]): on
    /// a robot the processes and topics come up in any order, and a tree ticked first would see
    /// no pose, fail its first node and, finished, stay failed. Until then the tree stays idle,
    /// the robot commands nothing, and a wait longer than [`FIRST_INPUTS_REPORT_S`] is reported
    /// once.
    pub fn tick(&mut self, now: Time, observer: Option<&mut dyn TreeObserver>) -> Status {
        match self.call_observed(now, SeamCall::Tick(TickOutput::default()), observer).1 {
            SeamReply::Tick(status) => status,
            _ => {
                mismatched_reply();
                self.tree.status()
            }
        }
    }

    fn tick_tree(&mut self, now: Time, observer: Option<&mut dyn TreeObserver>) -> Status {
        self.runtime.begin_tick();
        self.runtime.apply_operator(now);
        let status = self.tick_tree_inner(now, observer);
        self.runtime.enforce_hold();
        status
    }

    fn tick_tree_inner(&mut self, now: Time, observer: Option<&mut dyn TreeObserver>) -> Status {
        let last = self.tree.status();
        if last.is_done() {
            return last;
        }
        if !self.has_first_inputs() {
            let since = *self.waiting_since.get_or_insert(now);
            if !self.wait_reported && now.secs_since(since) >= FIRST_INPUTS_REPORT_S {
                self.wait_reported = true;
                let missing = match self.kind() {
                    RobotKind::Ugv => "odometry and a pose estimate",
                    _ => "a pose",
                };
                self.runtime.report(format!(
                    "tree not started: no {missing} after {FIRST_INPUTS_REPORT_S:.0} s (it starts when they arrive)"
                ));
            }
            return last;
        }
        self.tree.tick(now, &mut self.runtime, observer)
    }

    /// Whether the inputs the tree needs to start have arrived: a UGV's odometry and pose
    /// estimate, a UAV's pose (GPS); a basestation has none to wait for (its position is
    /// surveyed).
    pub fn has_first_inputs(&self) -> bool {
        match self.kind() {
            RobotKind::Ugv => self.runtime.odometry().is_some() && self.runtime.pose().is_some(),
            RobotKind::Uav => self.runtime.pose().is_some(),
            RobotKind::Basestation => true,
        }
    }

    /// Halts the tree (mission end, robot killed): running nodes stop and clean up. Unobserved:
    /// a halt's transitions are not logged (a replay makes the same halt).
    pub fn halt(&mut self, now: Time) {
        self.call(now, SeamCall::Halt);
    }

    // --- heavy skills off the tick thread -----------------------------------------------------------

    /// Runs the heavy skills (panorama processing, the global planner's upkeep) as work the
    /// adapter takes with [`Self::take_work`] and runs elsewhere, instead of inside
    /// [`Self::on_panorama`] and [`Self::tick`]. Set before the first input.
    pub fn set_background_skills(&mut self, on: bool) {
        self.runtime.set_background_skills(on);
    }

    /// Lets a panorama's localization update and terrain analysis run side by side through
    /// `join` (e.g. on rayon's threads); `None` (the default): one after the other. Same results.
    pub fn set_perception_join(&mut self, join: Option<crate::JoinFn>) {
        self.runtime.set_perception_join(join);
    }

    /// The work due now (background skills; none otherwise): run each, then give it back with
    /// [`Self::finish_work`]. See `spomp_robot::runtime::SkillWork`.
    pub fn take_work(&mut self, now: Time) -> Vec<SkillWork> {
        match self.call(now, SeamCall::TakeWork(Vec::new())).1 {
            SeamReply::TakeWork(work) => work,
            _ => {
                mismatched_reply();
                Vec::new()
            }
        }
    }

    /// A finished work, back from wherever it ran, applied at `now`.
    pub fn finish_work(&mut self, now: Time, work: FinishedWork) {
        let id = work.id();
        self.deliver_work(work);
        self.call(now, SeamCall::FinishWork(id));
    }

    /// Hands over a finished work without applying it: the seam call
    /// [`SeamCall::FinishWork`] with its number applies it (a replay delivers the work it ran
    /// and makes the recorded call).
    pub fn deliver_work(&mut self, work: FinishedWork) {
        self.delivered.push(work);
    }

    // --- outputs ----------------------------------------------------------------------------------

    /// The velocity command of the last tick (UGVs); `None`: stop.
    pub fn command(&self) -> Option<Twist2> {
        self.runtime.command()
    }

    /// The flight command of the last tick (UAVs); `None`: hover.
    pub fn flight(&self) -> Option<FlightCommand> {
        self.runtime.flight()
    }

    /// The sync message for peer `to`, limited to `tiers` and `budget_bytes`, encoded for the
    /// link; `None` when there is nothing to send.
    pub fn team_message_for(
        &mut self,
        now: Time,
        to: &RobotId,
        tiers: TierSet,
        budget_bytes: usize,
    ) -> Option<Vec<u8>> {
        match self.call(now, SeamCall::TeamOut { to: to.clone(), tiers, budget_bytes, sent: None }).0 {
            SeamCall::TeamOut { sent, .. } => sent,
            _ => None,
        }
    }

    /// Problems met since the last call: the nodes' reports, then the runtime's.
    pub fn take_problems(&mut self) -> Vec<String> {
        let mut out = self.tree.blackboard_mut().take_reports();
        out.append(&mut self.runtime.take_problems());
        out
    }

    // --- what observers may read --------------------------------------------------------------------

    /// The latest map-frame pose estimate.
    pub fn pose(&self) -> Option<PoseEstimate> {
        self.runtime.pose()
    }

    /// The robot's team state.
    pub fn team(&self) -> &TeamState {
        self.runtime.team()
    }

    /// The path being followed, map frame.
    pub fn planned_path(&self) -> Option<&[Point2]> {
        self.runtime.planned_path()
    }

    /// The navigation stack (UGVs), for its latest scan and terrain analysis.
    pub fn nav(&self) -> Option<&NavStack> {
        self.runtime.nav()
    }

    /// The latest reachability scan (UGVs).
    pub fn latest_scan(&self) -> Option<&Arc<ReachabilityScan>> {
        self.runtime.nav().and_then(NavStack::latest_scan)
    }

    /// The latest terrain analysis's obstacle mask (UGVs), row-major in its panorama geometry.
    pub fn terrain_obstacles(&self) -> Option<(spomp_core::PanoramaGeometry, &[bool])> {
        self.runtime.nav().and_then(NavStack::terrain_obstacles)
    }

    /// The navigation settings in force (UGVs).
    pub fn nav_params(&self) -> Option<&crate::runtime::NavParams> {
        self.runtime.nav().map(NavStack::params)
    }

    /// The robot's copy of the aerial map, if it keeps one.
    pub fn aerial_map(&self) -> Option<&spomp_mapping::Orthomap> {
        self.runtime.map()
    }

    /// The class table its skills use.
    pub fn classes(&self) -> &spomp_core::ClassTable {
        self.runtime.classes()
    }

    /// Panoramas replaced by a newer one before they were processed (background skills).
    pub fn superseded_panoramas(&self) -> u64 {
        self.runtime.superseded_panoramas()
    }

    /// The team-state traffic since it was built.
    pub fn team_traffic(&self) -> TeamTraffic {
        self.traffic
    }

    /// The tree's executor (node paths, blackboard, status).
    pub fn tree(&self) -> &TreeExecutor<RobotRuntime> {
        &self.tree
    }

    /// What observers and tools may read of the robot.
    pub fn view(&self) -> RobotView<'_> {
        RobotView(self)
    }
}

/// A robot, read-only: what observers, live views and tools may read of it (its estimates,
/// team state, plans, the latest perception, its tree's status), never its runtime.
#[derive(Clone, Copy)]
pub struct RobotView<'a>(&'a Robot);

impl<'a> RobotView<'a> {
    /// The robot's id.
    pub fn id(&self) -> &'a RobotId {
        self.0.id()
    }

    /// Its kind.
    pub fn kind(&self) -> RobotKind {
        self.0.kind()
    }

    /// The latest map-frame pose estimate.
    pub fn pose(&self) -> Option<PoseEstimate> {
        self.0.pose()
    }

    /// The velocity command of the last tick (UGVs); `None`: stop.
    pub fn command(&self) -> Option<Twist2> {
        self.0.command()
    }

    /// The flight command of the last tick (UAVs); `None`: hover.
    pub fn flight(&self) -> Option<FlightCommand> {
        self.0.flight()
    }

    /// Its team state.
    pub fn team(&self) -> &'a TeamState {
        self.0.team()
    }

    /// Its team-state traffic since it was built.
    pub fn team_traffic(&self) -> TeamTraffic {
        self.0.team_traffic()
    }

    /// The path being followed, map frame.
    pub fn planned_path(&self) -> Option<&'a [Point2]> {
        self.0.planned_path()
    }

    /// The latest reachability scan (UGVs).
    pub fn latest_scan(&self) -> Option<&'a Arc<ReachabilityScan>> {
        self.0.latest_scan()
    }

    /// The latest terrain analysis's obstacle mask (UGVs), row-major in its panorama geometry.
    pub fn terrain_obstacles(&self) -> Option<(spomp_core::PanoramaGeometry, &'a [bool])> {
        self.0.terrain_obstacles()
    }

    /// The navigation stack (UGVs): its planner's graph, blocked edges, latest safe region.
    pub fn nav(&self) -> Option<&'a NavStack> {
        self.0.nav()
    }

    /// The navigation settings in force (UGVs).
    pub fn nav_params(&self) -> Option<&'a crate::runtime::NavParams> {
        self.0.nav_params()
    }

    /// The robot's copy of the aerial map, if it keeps one.
    pub fn aerial_map(&self) -> Option<&'a spomp_mapping::Orthomap> {
        self.0.aerial_map()
    }

    /// The class table its skills use.
    pub fn classes(&self) -> &'a spomp_core::ClassTable {
        self.0.classes()
    }

    /// Panoramas replaced by a newer one before they were processed (background skills).
    pub fn superseded_panoramas(&self) -> u64 {
        self.0.superseded_panoramas()
    }

    /// Its tree's status.
    pub fn tree_status(&self) -> Status {
        self.0.tree.status()
    }

    /// Its tree's executor, read-only (node paths, blackboard).
    pub fn tree(&self) -> &'a TreeExecutor<RobotRuntime> {
        self.0.tree()
    }

    /// Its localization (UGVs: the filter's state and counts).
    pub fn localization(&self) -> &'a crate::runtime::Localization {
        self.0.runtime.localization()
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]

    use spomp_behaviors::mission::load_mission_str;
    use spomp_core::{ClassTable, GridSpec, Odometry, Pose2};

    use super::*;

    /// A UGV whose role fails at its first tick (as a drive does that finds no pose).
    fn robot_failing_at_once() -> Robot {
        let text = "mission: first-inputs\n\
             team:\n  - { id: ugv1, kind: ugv, role: r, priority: 1, start: { x_m: 5, y_m: 5 }, localization: { mode: ground_truth } }\n\
             roles:\n  r: { tree: { fail: } }\n\
             complete_when: time_limit\ntime_limit_s: 100\n";
        let loaded =
            load_mission_str(text, std::path::Path::new("first.yaml"), &crate::registry(), &Default::default());
        assert!(loaded.is_valid(), "{:#?}", loaded.diagnostics);
        let area = OperatingArea::new(ClassTable::default_table(), GridSpec::new(Point2::new(0.0, 0.0), 0.5, 40, 40));
        Robot::from_mission(&loaded, "ugv1", &area, 1, &crate::registry()).unwrap()
    }

    /// Keeps every seam call it is handed.
    #[derive(Default)]
    struct SeamLog(Vec<(RobotId, Time, SeamCall)>);

    impl RobotObserver for SeamLog {
        fn wants_seam(&self) -> bool {
            true
        }
        fn on_seam(&mut self, robot: &RobotId, now: Time, call: &SeamCall) {
            self.0.push((robot.clone(), now, call.clone()));
        }
    }

    /// Issue 35: the robot records itself. Every named method is a call on the seam, kept with
    /// its answers in the order made, and a fresh robot made the same calls answers them alike
    /// (what a replay checks) — no adapter has to report a call for it to be logged.
    #[test]
    fn a_recording_robot_keeps_every_call_with_its_answers_and_a_fresh_robot_answers_alike() {
        let t = |s: f64| Time::from_secs_f64(s);
        let drive = |r: &mut Robot| {
            r.on_odometry(t(1.0), Odometry { stamp: t(1.0), ..Default::default() });
            r.on_external_pose(
                t(1.0),
                PoseEstimate { stamp: t(1.0), pose: Pose2::new(5.0, 5.0, 0.0), confidence: 1.0, ..Default::default() },
            );
            let sent = r.team_message_for(t(1.0), &RobotId::new("ugv2"), TierSet::ALL, 1 << 20);
            let rejected = r.on_team_message(t(1.05), &RobotId::new("ugv2"), vec![1, 2, 3]).is_err();
            let status = r.tick(t(1.1), None);
            let work = r.take_work(t(1.1));
            r.halt(t(1.2));
            (sent, rejected, status, work.len())
        };
        let mut r = robot_failing_at_once();
        let mut quiet = robot_failing_at_once();
        r.record_seam(true);
        let (sent, rejected, status, work) = drive(&mut r);
        assert_eq!((sent.clone(), rejected, status, work), drive(&mut quiet), "recording changes nothing");
        assert!(sent.is_some() && rejected && status == Status::Failure && work == 0);
        // The robot counted its traffic itself, recording or not.
        let len = sent.as_ref().map_or(0, |b| b.len() as u64);
        for robot in [&r, &quiet] {
            let t = robot.team_traffic();
            assert_eq!((t.sent_messages, t.sent_bytes_all_tiers, t.sent_bytes_fewer_tiers), (1, len, 0));
            assert_eq!(t.sent_bytes_by_tier.iter().sum::<u64>(), len);
            assert_eq!((t.received_messages, t.received_bytes), (1, 3));
        }
        let mut log = SeamLog::default();
        r.deliver_recorded(&mut log);
        let names: Vec<&str> = log.0.iter().map(|(_, _, c)| c.name()).collect();
        assert_eq!(names, ["odometry", "external_pose", "team_out", "team_in", "tick", "take_work", "halt"]);
        assert!(log.0.iter().all(|(id, _, _)| id.as_str() == "ugv1"));
        assert_eq!(log.0[2].1, t(1.0));
        assert!(matches!(&log.0[2].2, SeamCall::TeamOut { sent: s, .. } if *s == sent), "the answer is kept");
        assert!(matches!(log.0[4].2, SeamCall::Tick(TickOutput { command: None, flight: None })));
        // Delivered once.
        let mut again = SeamLog::default();
        r.deliver_recorded(&mut again);
        assert!(again.0.is_empty());
        // A robot not told to record keeps nothing.
        quiet.deliver_recorded(&mut again);
        assert!(again.0.is_empty());
        // Replayed on a fresh robot, every call answers as recorded.
        let mut fresh = robot_failing_at_once();
        for (_, now, call) in &log.0 {
            let (answered, _) = fresh.call(*now, call.clone());
            assert!(call.same_answers(&answered), "{} answered differently", call.name());
        }
        // A changed answer is told apart, with where it differs.
        let SeamCall::TeamOut { to, tiers, budget_bytes, sent: Some(mut bytes) } = log.0[2].2.clone() else {
            panic!("{:?}", log.0[2].2)
        };
        bytes[0] ^= 1;
        let changed = SeamCall::TeamOut { to, tiers, budget_bytes, sent: Some(bytes) };
        assert!(!log.0[2].2.same_answers(&changed));
        assert!(changed.describe_answer(Some(&log.0[2].2)).contains("first difference at byte 0"));
    }

    /// A work result is applied only when handed over first; a finish naming another work is
    /// refused, not applied.
    #[test]
    fn finishing_work_never_handed_over_is_refused() {
        let mut r = robot_failing_at_once();
        let (call, reply) = r.call(Time::from_secs_f64(1.0), SeamCall::FinishWork(7));
        assert_eq!(call, SeamCall::FinishWork(7));
        assert!(matches!(reply, SeamReply::FinishWork(Err(UnknownWork(7)))), "{reply:?}");
    }

    /// Issue 32: on a robot the processes come up in any order; a tree ticked before the first
    /// odometry and pose failed at once and, finished, stayed failed for the whole mission.
    #[test]
    fn the_tree_does_not_start_before_the_robots_first_inputs() {
        let mut r = robot_failing_at_once();
        let t = |s: f64| Time::from_secs_f64(s);
        assert!(!r.has_first_inputs());
        assert!(!r.tick(t(0.0), None).is_done(), "not started without inputs");
        assert!(r.take_problems().iter().all(|p| !p.contains("tree not started")));
        // A long wait is reported once.
        assert!(!r.tick(t(FIRST_INPUTS_REPORT_S + 1.0), None).is_done());
        assert!(!r.tick(t(FIRST_INPUTS_REPORT_S + 2.0), None).is_done());
        let waits: Vec<String> = r.take_problems().into_iter().filter(|p| p.contains("tree not started")).collect();
        assert_eq!(waits.len(), 1, "{waits:?}");
        assert!(r.command().is_none_or(|c| c == Twist2::ZERO));
        // Odometry alone is not enough for a UGV: its pose too.
        r.on_odometry(t(12.0), Odometry { stamp: t(12.0), ..Default::default() });
        assert!(!r.tick(t(12.0), None).is_done());
        r.on_external_pose(
            t(12.1),
            PoseEstimate { stamp: t(12.1), pose: Pose2::new(5.0, 5.0, 0.0), confidence: 1.0, ..Default::default() },
        );
        assert!(r.has_first_inputs());
        assert_eq!(r.tick(t(12.1), None), Status::Failure, "the tree runs once the inputs are in");
    }
}
