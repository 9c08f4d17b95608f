//! The seam between a robot and the world: one [`Robot`] per robot, driven the same way by
//! every adapter.
//!
//! Per control period an adapter:
//! 1. pushes what arrived: odometry, panoramas, an external pose (GPS, a surveyed position,
//!    simulator truth where the mission asks), camera tiles (the UAV), team-state messages with
//!    the peer they came from;
//! 2. calls [`Robot::maintain`] and [`Robot::tick`] at the robot's tick rate — and, when the
//!    heavy skills run in the background ([`Robot::set_background_skills`]), hands the work
//!    [`Robot::take_work`] gives to another thread and each result back with
//!    [`Robot::finish_work`] between ticks;
//! 3. pulls what the robot wants done: [`Robot::command`] (UGV velocity) or [`Robot::flight`]
//!    (UAV target) — `None` is stop / hover, so a command never outlives the node that issued
//!    it — the team-state message for each peer it can reach ([`Robot::team_message_for`]),
//!    and the problems met ([`Robot::take_problems`]).

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
                    .team_mut()
                    .add_mission_goal(k as u32, Point2::new(g.x_m, g.y_m))
                    .map_err(|e| RobotError::MissionGoal(e.to_string()))?;
            }
        }
        let build = BuildOptions { base_dir: Some(loaded.base_dir()), map_origin: setup.map_origin };
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

    // --- inputs -----------------------------------------------------------------------------------

    /// New odometry (robot frame).
    pub fn on_odometry(&mut self, odom: Odometry) {
        self.runtime.on_odometry(odom);
    }

    /// A new depth + semantic panorama.
    pub fn on_panorama(&mut self, frame: Arc<PanoramaFrame>) {
        self.runtime.on_panorama(frame);
    }

    /// A map-frame pose from outside (see [`Robot::pose_input`]).
    pub fn on_external_pose(&mut self, estimate: PoseEstimate) {
        self.runtime.on_external_pose(estimate);
    }

    /// Aerial-map tiles from the robot's own camera (the UAV).
    pub fn on_camera_tiles(&mut self, tiles: &[MapTile], now: Time) {
        self.runtime.on_camera_tiles(tiles, now);
    }

    /// A team-state sync message from peer `from`, as bytes off the link. A message that does
    /// not decode or check is rejected whole, reported, and changes nothing; the error says why.
    pub fn on_team_message(&mut self, from: &RobotId, bytes: &[u8]) -> Result<ApplyReport, SyncError> {
        let result = self.runtime.team_mut().apply_bytes(from, bytes);
        if let Err(e) = &result {
            self.runtime.report(format!("sync from {from} rejected: {e}"));
        }
        result
    }

    // --- the team link on robots ------------------------------------------------------------------

    /// Signs this robot's team-state records and messages and checks its peers' (a secured
    /// team; see `spomp_teamstate::auth`).
    pub fn secure_team(&mut self, security: Arc<TeamSecurity>) -> Result<(), TeamStateError> {
        self.runtime.team_mut().set_security(security)
    }

    /// Which boot of this robot this is (larger at every boot): peers forget what they knew of
    /// its earlier messages.
    pub fn set_team_session(&mut self, session: u64) {
        self.runtime.team_mut().set_session(session);
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
    pub fn resume(&mut self, bytes: &[u8]) -> Result<RestoreSummary, ResumeError> {
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
        *self.runtime.team_mut() = team_state;
        for (name, value) in values {
            self.tree.blackboard_mut().set_by_name(&name, value);
        }
        Ok(summary)
    }

    // --- stepping ---------------------------------------------------------------------------------

    /// Background upkeep at `now` (team-state clock, global planner upkeep); once per tick.
    pub fn maintain(&mut self, now: Time) {
        self.runtime.maintain(now);
    }

    /// Ticks the tree once at `now`; transitions go to `observer`. A tree that has finished
    /// (success or failure) stays finished: it is not ticked again and the robot commands
    /// nothing, so a mission's `all_trees_done` sees every robot done together. A role that
    /// should run again says so with `repeat`. Upkeep ([`Self::maintain`]) goes on.
    ///
    /// The tree does not start before the robot's first inputs ([`Self::has_first_inputs`]): on
    /// a robot the processes and topics come up in any order, and a tree ticked first would see
    /// no pose, fail its first node and, finished, stay failed. Until then the tree stays idle,
    /// the robot commands nothing, and a wait longer than [`FIRST_INPUTS_REPORT_S`] is reported
    /// once.
    pub fn tick(&mut self, now: Time, observer: Option<&mut dyn TreeObserver>) -> Status {
        self.runtime.begin_tick();
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

    /// Halts the tree (mission end, robot killed): running nodes stop and clean up.
    pub fn halt(&mut self, now: Time, observer: Option<&mut dyn TreeObserver>) {
        self.tree.halt(now, &mut self.runtime, observer);
    }

    // --- heavy skills off the tick thread -----------------------------------------------------------

    /// Runs the heavy skills (panorama processing, the global planner's upkeep) as work the
    /// adapter takes with [`Self::take_work`] and runs elsewhere, instead of inside
    /// [`Self::on_panorama`] and [`Self::maintain`]. Set before the first input.
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
        self.runtime.take_work(now)
    }

    /// A finished work, back from wherever it ran.
    pub fn finish_work(&mut self, work: FinishedWork) {
        self.runtime.finish_work(work);
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
    pub fn team_message_for(&mut self, to: &RobotId, tiers: TierSet, budget_bytes: usize) -> Option<Vec<u8>> {
        self.runtime.team_mut().make_sync(to, tiers, budget_bytes).map(|m| m.encode())
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
        self.runtime.nav().and_then(|n| n.latest_scan.as_ref())
    }

    /// The runtime, read-only (tests and tools).
    pub fn runtime(&self) -> &RobotRuntime {
        &self.runtime
    }

    /// The tree's executor (node paths, blackboard, status).
    pub fn tree(&self) -> &TreeExecutor<RobotRuntime> {
        &self.tree
    }

    /// The tree's executor, mutable (adapters inject blackboard entries and events).
    pub fn tree_mut(&mut self) -> &mut TreeExecutor<RobotRuntime> {
        &mut self.tree
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
        let area = OperatingArea {
            classes: ClassTable::default_table(),
            grid: GridSpec::new(Point2::new(0.0, 0.0), 0.5, 40, 40),
            prior_map: None,
            map_origin: None,
        };
        Robot::from_mission(&loaded, "ugv1", &area, 1, &crate::registry()).unwrap()
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
        r.on_odometry(Odometry { stamp: t(12.0), ..Default::default() });
        assert!(!r.tick(t(12.0), None).is_done());
        r.on_external_pose(PoseEstimate {
            stamp: t(12.1),
            pose: Pose2::new(5.0, 5.0, 0.0),
            confidence: 1.0,
            ..Default::default()
        });
        assert!(r.has_first_inputs());
        assert_eq!(r.tick(t(12.1), None), Status::Failure, "the tree runs once the inputs are in");
    }
}
