//! The robot runtime: one robot's state and continuous skills, and what domain nodes see of
//! the robot (their `TickContext::env`, typed).
//!
//! Adapters do not drive it directly: they drive a [`crate::Robot`], which owns the runtime and
//! the robot's tree. The runtime's state is private; inputs, outputs and what nodes may do go
//! through methods that say what they do.

mod driven;
mod localization;
mod navigation;
mod team_goals;
mod work;

use std::collections::HashMap;
use std::sync::Arc;

use rand::{RngCore, SeedableRng};
use rand_chacha::ChaCha8Rng;
use spomp_core::{
    AerialMap, ClassTable, FlightCommand, GridSpec, MapTile, Odometry, PanoramaFrame, Point2, Pose2, PoseEstimate,
    RobotId, RobotKind, Time, Twist2,
};
use spomp_mapping::{CompressedMap, CompressionParams, GoalDetectionParams, GoalDetector, MappingError, Orthomap};
use spomp_teamstate::{
    CommandId, GoalOrigin, IdentifyOutcome, OperatorMode, RobotOrders, TeamState, TeamStateError, TeamStateParams,
};

pub use driven::DrivenRuntime;
pub use localization::{Localization, LocalizationSetup, UpdateSchedule};
pub use navigation::{LocalView, NavParams, NavStack};
pub use team_goals::TeamGoalsMut;
pub use work::{FinishedWork, JoinFn, SkillWork, WorkKind};

use work::{FinishedParts, PerceptionJob, PerceptionResult};

/// How to set up one robot's runtime. Built by the one translation from a mission
/// ([`crate::RobotSetup`]) or, for a runtime without a mission (tests, tools), by
/// [`RuntimeConfig::basic`] and the `with_*` setters; read through accessors, never patched
/// field by field after the translation.
#[derive(Clone, Debug)]
pub struct RuntimeConfig {
    /// The robot.
    pub(crate) id: RobotId,
    /// Its kind.
    pub(crate) kind: RobotKind,
    /// UGV priority (lower = higher); 0 for other kinds is fine.
    pub(crate) priority: u32,
    /// Start pose in the map frame (home, and the localization prior's mean).
    pub(crate) start: Pose2,
    /// The semantic class table.
    pub(crate) classes: ClassTable,
    /// Grid of the operating area (the aerial map the team builds).
    pub(crate) map_spec: Option<GridSpec>,
    /// Team state parameters (deconfliction radius from the mission).
    pub(crate) team: TeamStateParams,
    /// Goal detection (from the mission's `goals.detect`); none for robots without it.
    pub(crate) detection: Option<GoalDetectionParams>,
    /// Where the map-frame pose comes from.
    pub(crate) localization: LocalizationSetup,
    /// Navigation parameters (UGVs).
    pub(crate) nav: Option<NavParams>,
    /// Per-goal time limit per metre of planned path (mission `goals.time_limit_per_m_s`).
    pub(crate) goal_time_per_m_s: f64,
    /// Seed of this robot's random stream (skills take randomness from it).
    pub(crate) seed: u64,
    /// How often a mapping robot (the UAV) publishes its map as a new version, seconds.
    pub(crate) map_publish_period_s: f64,
    /// PNG effort of the published map layers.
    pub(crate) map_compression: CompressionParams,
    /// An aerial map the robot starts with (surveyed before the mission); `None`: only what the
    /// team maps. Shared, not copied: robots of a team hold one prior map until they change it.
    pub(crate) prior_map: Option<Arc<AerialMap>>,
    /// The other ground robots of the team (UGVs): their bodies show in this robot's panoramas,
    /// and an edge a scan of its own finds blocked by one is marked, never removed. Empty: no
    /// robot is taken for a teammate.
    pub(crate) ground_teammates: Vec<RobotId>,
}

impl RuntimeConfig {
    /// A robot with no navigation, no goal detection and an externally supplied pose, over the
    /// default class table and no map grid (tests, basestations); set the other fields as
    /// needed.
    pub fn basic(id: RobotId, kind: RobotKind, priority: u32, start: Pose2) -> Self {
        RuntimeConfig {
            id,
            kind,
            priority,
            start,
            classes: ClassTable::default_table(),
            map_spec: None,
            team: TeamStateParams::default(),
            detection: None,
            localization: LocalizationSetup::External,
            nav: None,
            goal_time_per_m_s: 2.0,
            seed: 0,
            map_publish_period_s: 10.0,
            map_compression: CompressionParams::default(),
            prior_map: None,
            ground_teammates: Vec::new(),
        }
    }

    /// With `teammates` as the team's other ground robots (see
    /// [`NavStack::set_ground_teammates`]).
    pub fn with_ground_teammates(mut self, teammates: Vec<RobotId>) -> Self {
        self.ground_teammates = teammates;
        self
    }

    /// With the semantic class table `classes`.
    pub fn with_classes(mut self, classes: ClassTable) -> Self {
        self.classes = classes;
        self
    }

    /// Detecting goals in the aerial map with `detection`.
    pub fn with_detection(mut self, detection: GoalDetectionParams) -> Self {
        self.detection = Some(detection);
        self
    }

    /// Over the operating area's grid `spec`.
    pub fn with_map_spec(mut self, spec: GridSpec) -> Self {
        self.map_spec = Some(spec);
        self
    }

    /// With team-state parameters `team`.
    pub fn with_team(mut self, team: TeamStateParams) -> Self {
        self.team = team;
        self
    }

    /// With navigation (a UGV's) under `nav`.
    pub fn with_nav(mut self, nav: NavParams) -> Self {
        self.nav = Some(nav);
        self
    }

    /// Its random stream seeded with `seed`.
    pub fn with_seed(mut self, seed: u64) -> Self {
        self.seed = seed;
        self
    }

    /// Starting with the aerial map `map` (`None`: only what the team maps).
    pub fn with_prior_map(mut self, map: Option<Arc<AerialMap>>) -> Self {
        self.prior_map = map;
        self
    }

    /// The robot.
    pub fn id(&self) -> &RobotId {
        &self.id
    }

    /// Its kind.
    pub fn kind(&self) -> RobotKind {
        self.kind
    }

    /// Its start pose in the map frame.
    pub fn start(&self) -> Pose2 {
        self.start
    }

    /// How often a mapping robot publishes its map as a new version, seconds.
    pub fn map_publish_period_s(&self) -> f64 {
        self.map_publish_period_s
    }

    /// PNG effort of the published map layers.
    pub fn map_compression(&self) -> &CompressionParams {
        &self.map_compression
    }
}

/// Errors setting up a runtime.
#[derive(Debug, thiserror::Error)]
pub enum RuntimeError {
    /// Team state parameters rejected.
    #[error("team state: {0}")]
    Team(#[from] TeamStateError),
    /// Goal detection parameters or the prior map rejected.
    #[error("mapping: {0}")]
    Mapping(#[from] MappingError),
    /// A skill rejected its parameters.
    #[error("{skill}: {message}")]
    Skill {
        /// Which skill.
        skill: &'static str,
        /// What it said.
        message: String,
    },
}

/// How many problems [`RobotRuntime::report`] keeps waiting for the adapter; beyond, they are
/// counted and the count reported instead.
pub const MAX_REPORTED_PROBLEMS: usize = 64;
/// The longest problem text [`RobotRuntime::report`] keeps, characters.
pub const MAX_PROBLEM_CHARS: usize = 400;

/// One robot's state and skills: the environment its behaviour nodes act on.
pub struct RobotRuntime {
    id: RobotId,
    kind: RobotKind,
    /// The replicated team database.
    team: TeamState,
    /// Latest map-frame pose (from the localizer, GPS or simulator truth).
    pose: Option<PoseEstimate>,
    /// Start pose (home).
    start: Pose2,
    /// Shared with perception work (no copy per panorama).
    classes: Arc<ClassTable>,
    /// This robot's copy of the aerial map: grown from the map versions received in the team
    /// state, or (on the UAV) by its own camera.
    map: Option<Orthomap>,
    /// Goal detection as the mission's `goals.detect` configures it (none: no detection).
    detector: Option<GoalDetector>,
    /// Map version the last detection pass ran on.
    detected_version: Option<u64>,
    /// Grid of the operating area, for the map copy received maps grow.
    map_spec: Option<GridSpec>,
    odometry: Option<Odometry>,
    panorama: Option<Arc<PanoramaFrame>>,
    /// Velocity command written by a driving node this tick (UGVs); `None`: stop.
    command: Option<Twist2>,
    /// Flight command written by a flying node this tick (UAVs); `None`: hover.
    flight: Option<FlightCommand>,
    /// The path being followed, map frame.
    planned_path: Option<Vec<Point2>>,
    goal_time_per_m_s: f64,
    rng: ChaCha8Rng,
    localization: Localization,
    /// Terrain analysis, global planner and controller (UGVs with navigation).
    nav: Option<Box<NavStack>>,
    /// Problems met outside a tick (a bad map blob, a skill error), drained by the adapter.
    problems: Vec<String>,
    /// Problems [`RobotRuntime::report`] left out since the last take because
    /// [`MAX_REPORTED_PROBLEMS`] were waiting (a flood of refused messages).
    problems_left_out: u64,
    /// Newest map version applied, per publishing robot.
    applied_maps: HashMap<RobotId, u64>,
    /// Map publishing of a mapping robot: period, effort, next due time, last version sent.
    map_publish_period_s: f64,
    map_compression: CompressionParams,
    next_map_publish: Time,
    published_map_version: u64,
    /// Heavy skills as work the adapter runs elsewhere ([`Self::take_work`]), not inline.
    background_skills: bool,
    /// The newest panorama not yet taken as work (background skills).
    pending_panorama: Option<Arc<PanoramaFrame>>,
    /// A perception job is out.
    perception_out: bool,
    /// Number of the next work taken.
    next_work_id: u64,
    /// Panoramas replaced by a newer one before any work took them.
    superseded_panoramas: u64,
    /// How a panorama's localization and terrain analysis may run side by side.
    perception_join: Option<JoinFn>,
    /// The operator's orders for this robot as of this tick (issue 37).
    operator: RobotOrders,
    /// The team state's operator-records version `operator` was derived at (None: not yet):
    /// while it stands, no command or acknowledgement arrived and the tick skips the commands.
    operator_seen: Option<u64>,
}

/// What one goal-detection pass did: a plain result value handed to the node (public fields by
/// the rule in docs/ARCHITECTURE.md, "Public fields"; it holds no runtime state).
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct DetectionPass {
    /// Goals new to the team state.
    pub added: usize,
    /// What went wrong (a bad map version, a detector error), for the node to report.
    pub problems: Vec<String>,
}

impl RobotRuntime {
    /// A runtime with an empty team state, no navigation and an externally supplied pose
    /// (tests, basestations). `priority` orders UGV claims (lower = higher).
    pub fn new(
        id: RobotId,
        kind: RobotKind,
        priority: u32,
        start: Pose2,
        team: TeamStateParams,
    ) -> Result<Self, TeamStateError> {
        let team = TeamState::new(id.clone(), priority, team)?;
        Ok(RobotRuntime {
            id,
            kind,
            team,
            pose: None,
            start,
            classes: Arc::new(ClassTable::default_table()),
            map: None,
            detector: None,
            detected_version: None,
            map_spec: None,
            odometry: None,
            panorama: None,
            command: None,
            flight: None,
            planned_path: None,
            goal_time_per_m_s: 2.0,
            rng: ChaCha8Rng::seed_from_u64(0),
            localization: Localization::External,
            nav: None,
            problems: Vec::new(),
            problems_left_out: 0,
            applied_maps: HashMap::new(),
            map_publish_period_s: 10.0,
            map_compression: CompressionParams::default(),
            next_map_publish: Time::ZERO,
            published_map_version: 0,
            background_skills: false,
            pending_panorama: None,
            perception_out: false,
            next_work_id: 0,
            superseded_panoramas: 0,
            perception_join: None,
            operator: RobotOrders::default(),
            operator_seen: None,
        })
    }

    /// A runtime set up from a mission's description of the robot.
    pub fn from_config(config: RuntimeConfig) -> Result<Self, RuntimeError> {
        let mut rt = RobotRuntime::new(config.id, config.kind, config.priority, config.start, config.team)?;
        rt.classes = Arc::new(config.classes);
        rt.map_spec = config.map_spec;
        rt.goal_time_per_m_s = config.goal_time_per_m_s;
        rt.rng = ChaCha8Rng::seed_from_u64(config.seed);
        rt.map_publish_period_s = config.map_publish_period_s;
        rt.map_compression = config.map_compression;
        if let Some(det) = config.detection {
            rt.detector = Some(GoalDetector::new(det, &rt.classes)?);
        }
        rt.localization = Localization::from_setup(&config.localization, config.start)?;
        if let Some(nav) = config.nav {
            let mut stack = NavStack::new(nav, &rt.classes)?;
            stack.set_ground_teammates(config.ground_teammates);
            rt.nav = Some(Box::new(stack));
        }
        if let Some(map) = config.prior_map {
            rt.map = Some(Orthomap::from_shared(map)?);
        } else if rt.kind == RobotKind::Uav
            && let Some(spec) = rt.map_spec
        {
            // The UAV maps: its copy grows from its own camera.
            rt.map = Some(Orthomap::new(spec));
        }
        Ok(rt)
    }

    // --- identity ----------------------------------------------------------------------------

    /// The robot's id.
    pub fn id(&self) -> &RobotId {
        &self.id
    }

    /// Its kind.
    pub fn kind(&self) -> RobotKind {
        self.kind
    }

    /// Its start pose (home), map frame.
    pub fn start(&self) -> Pose2 {
        self.start
    }

    /// The semantic class table.
    pub fn classes(&self) -> &ClassTable {
        &self.classes
    }

    // --- inputs (adapters, through `Robot`) -----------------------------------------------------

    /// Clears this tick's outputs; called before the tree is ticked.
    pub(crate) fn begin_tick(&mut self) {
        self.command = None;
        self.flight = None;
    }

    /// Applies the operator's commands held in the team state (issue 37), at the start of a
    /// tick: takes this robot's hold / recall / resume in force (a recall also releases the
    /// robot's claims at once, so another robot takes its goal), and acknowledges every command
    /// that concerns it and that it has not acknowledged yet (goal commands are in force in the
    /// goal view as soon as they are held). Returns the commands acknowledged now.
    ///
    /// Orders and acknowledgements depend on the command and acknowledgement records only, so
    /// a tick in which none arrived (nearly every tick) costs one comparison and allocates
    /// nothing; a tick after one did walks the commands once.
    pub(crate) fn apply_operator(&mut self, now: Time) -> Vec<CommandId> {
        if self.operator_seen == Some(self.team.operator_records_version()) {
            return Vec::new();
        }
        let orders = self.team.operator_mode(&self.id);
        if orders.mode == OperatorMode::Recall && self.operator.mode != OperatorMode::Recall {
            self.team.release_all_claims(now);
        }
        self.operator = orders;
        let due = self.team.commands_to_acknowledge();
        for id in &due {
            if let Err(e) = self.team.acknowledge(id, now) {
                self.report(format!("operator command {id}: {e}"));
            }
        }
        // After its own acknowledgements, which move the version too.
        self.operator_seen = Some(self.team.operator_records_version());
        due
    }

    /// The safety floor of a hold (issue 37): whatever the tree commanded, a held robot stops
    /// (a UGV commands zero, a UAV hovers) in the tick that saw the hold, even if its mission
    /// has no `operator_hold` branch.
    pub(crate) fn enforce_hold(&mut self) {
        if self.operator.mode == OperatorMode::Hold {
            self.command = None;
            self.flight = None;
        }
    }

    /// The operator's orders in force for this robot (as of the last tick).
    pub fn operator_orders(&self) -> &RobotOrders {
        &self.operator
    }

    /// A pose from outside the robot's own estimation: GPS on the UAV, the basestation's
    /// surveyed position, or (where the mission asks for it) simulator ground truth plus noise.
    /// Ignored while a cross-view localizer owns the pose.
    pub(crate) fn on_external_pose(&mut self, estimate: PoseEstimate) {
        if matches!(self.localization, Localization::External) {
            self.pose = Some(estimate);
            self.publish_pose(estimate);
        }
    }

    /// New odometry: the pose between panoramas is the last filtered pose composed with the
    /// odometry since (the paper's scheme).
    pub(crate) fn on_odometry(&mut self, odom: Odometry) {
        self.odometry = Some(odom);
        if let Some(estimate) = self.localization.pose_at(&odom, &mut self.rng) {
            self.pose = Some(estimate);
            self.publish_pose(estimate);
        }
    }

    /// A new panorama: brings the map copy up to date, runs the localizer's measurement update,
    /// then terrain analysis (reachability scan shared on the team state and fed to the global
    /// planner). With background skills it is only kept, as the newest, for [`Self::take_work`].
    pub(crate) fn on_panorama(&mut self, frame: Arc<PanoramaFrame>) {
        self.panorama = Some(frame.clone());
        if self.background_skills {
            if self.pending_panorama.replace(frame).is_some() {
                self.superseded_panoramas += 1;
            }
            return;
        }
        let mut job = self.begin_perception(frame);
        let result = job.run(&mut self.rng);
        self.finish_perception(job, result);
    }

    /// Prepares a panorama's processing: the map copy brought up to date, the localizer and the
    /// terrain analyzer lent to the job.
    fn begin_perception(&mut self, frame: Arc<PanoramaFrame>) -> PerceptionJob {
        if let Err(e) = self.refresh_map() {
            self.problems.push(format!("a received map version is unusable: {e}"));
        }
        let localizer = match self.localization.take_for_update(&frame, &mut self.rng) {
            Ok(cv) => cv,
            Err(e) => {
                self.problems.push(format!("localization: {e}"));
                None
            }
        };
        let terrain = self.nav.as_deref_mut().map(|nav| nav.begin_analysis(&frame));
        PerceptionJob {
            map: self.map.as_ref().map(|m| (m.shared(), m.version())),
            classes: Arc::clone(&self.classes),
            localizer,
            terrain,
            robot: self.id.clone(),
            pose_before: self.pose,
            join: self.perception_join,
            frame,
        }
    }

    /// Takes a panorama's processing back: the localizer and analyzer return, the estimate
    /// becomes the pose, the analysis goes to the navigation stack.
    fn finish_perception(&mut self, job: PerceptionJob, result: PerceptionResult) {
        let PerceptionJob { frame, localizer, terrain, map, .. } = job;
        if let Some(cv) = localizer {
            self.localization.put_back(cv);
        }
        match result.estimate {
            Ok(Some(estimate)) => {
                // Work that ran in the background comes back after newer odometry: the pose is
                // the new estimate carried forward by it, as between panoramas.
                let newer = self.odometry.filter(|o| o.stamp > frame.stamp);
                let now = newer.and_then(|o| self.localization.pose_at(&o, &mut self.rng));
                let pose = now.unwrap_or(estimate);
                self.pose = Some(pose);
                self.publish_pose(pose);
            }
            Ok(None) => {}
            Err(e) => self.problems.push(format!("localization: {e}")),
        }
        let Some(nav) = self.nav.as_deref_mut() else { return };
        if let Some(Ok(terrain)) = terrain {
            nav.end_analysis(terrain);
        }
        let (Some(analysis), Some(pose)) = (result.analysis, result.scan_pose) else { return };
        let applied = analysis.and_then(|a| nav.apply_analysis(&frame, pose, a, map.is_some(), &mut self.team));
        if let Err(e) = applied {
            self.problems.push(format!("navigation: {e}"));
        }
    }

    /// Runs the heavy skills as work taken with [`Self::take_work`] instead of inline (an
    /// adapter with a worker thread: `spomp run`). Set before the first input.
    pub(crate) fn set_background_skills(&mut self, on: bool) {
        self.background_skills = on;
        // A robot that starts with a map plans from its first tick, as it does inline: the
        // graph of that map is built now, at setup, not in the background during the first
        // ticks (the tree would start its drives without a graph).
        if on
            && let Some(nav) = self.nav.as_deref_mut()
            && !nav.has_graph()
            && let Err(e) = nav.maintain(Time::ZERO, self.map.as_ref(), &self.team, &mut self.rng)
        {
            self.problems.push(format!("navigation: {e}"));
        }
    }

    /// Lets a panorama's localization update and terrain analysis run side by side through
    /// `join` (for example `rayon::join`), inline or as work; `None` (the default): one after the
    /// other. The results are the same either way.
    pub(crate) fn set_perception_join(&mut self, join: Option<JoinFn>) {
        self.perception_join = join;
    }

    /// Whether the heavy skills run as work taken with [`Self::take_work`].
    pub fn background_skills(&self) -> bool {
        self.background_skills
    }

    /// The work due now (background skills): the newest panorama's processing unless one is
    /// out, the global planner's upkeep when due unless it is out. Each is numbered; give each
    /// result back with [`Self::finish_work`].
    pub(crate) fn take_work(&mut self, now: Time) -> Vec<SkillWork> {
        let mut out = Vec::new();
        if !self.background_skills {
            return out;
        }
        if !self.perception_out
            && let Some(frame) = self.pending_panorama.take()
        {
            let job = self.begin_perception(frame);
            let rng = ChaCha8Rng::seed_from_u64(self.rng.next_u64());
            self.perception_out = true;
            out.push(SkillWork::perception(self.next_work_id, job, rng));
            self.next_work_id += 1;
        }
        if let Some(nav) = self.nav.as_deref_mut()
            && nav.planner_work_due(now, self.map.as_ref())
        {
            let rng = ChaCha8Rng::seed_from_u64(self.rng.next_u64());
            out.push(SkillWork::planner(self.next_work_id, nav.begin_planner_work(now, self.map.as_ref(), rng)));
            self.next_work_id += 1;
        }
        out
    }

    /// A finished work back from wherever it ran.
    pub(crate) fn finish_work(&mut self, work: FinishedWork) {
        match work.into_parts() {
            FinishedParts::Perception(job, result) => {
                self.perception_out = false;
                self.finish_perception(*job, *result);
            }
            FinishedParts::Planner(done) => {
                if let Some(nav) = self.nav.as_deref_mut()
                    && let Err(e) = nav.finish_planner_work(*done)
                {
                    self.problems.push(format!("navigation: {e}"));
                }
            }
        }
    }

    /// Panoramas replaced by a newer one before their processing began (background skills).
    pub fn superseded_panoramas(&self) -> u64 {
        self.superseded_panoramas
    }

    /// Tiles of the aerial map from the robot's own camera (the UAV): applied to its map, which
    /// is published to the team as a new version every `map_publish_period_s` while it changes
    /// (the whole map each time: the team state keeps only the newest version per publisher, so
    /// a robot that missed one still gets everything).
    pub(crate) fn on_camera_tiles(&mut self, tiles: &[MapTile], now: Time) {
        let Some(map) = self.map.as_mut() else {
            if !tiles.is_empty() {
                self.problems.push("camera tiles arrived, but this robot keeps no aerial map".into());
            }
            return;
        };
        for tile in tiles {
            if let Err(e) = map.apply_tile(tile) {
                self.problems.push(format!("camera tile rejected: {e}"));
            }
        }
        if now >= self.next_map_publish && map.version() != self.published_map_version {
            self.next_map_publish = Time::from_secs_f64(now.as_secs_f64() + self.map_publish_period_s);
            match map.encode(&self.map_compression) {
                Ok(blob) => {
                    self.published_map_version = map.version();
                    if let Err(e) = self.team.add_map_version(map.version(), now, blob.to_bytes()) {
                        self.problems.push(format!("map version rejected: {e}"));
                    }
                }
                Err(e) => self.problems.push(format!("map encoding failed: {e}")),
            }
        }
    }

    /// Background upkeep at simulated/real time `now`: the team state's clock (own claims
    /// renewed, other robots' expired claims dropped); the global planner takes in new map
    /// versions and team scans and retrains on its schedule. Call once per control period.
    pub(crate) fn maintain(&mut self, now: Time) {
        self.team.advance_clock(now);
        let Some(nav) = self.nav.as_deref_mut() else { return };
        if self.background_skills {
            nav.maintain_light(self.map.as_ref(), &self.team);
        } else if let Err(e) = nav.maintain(now, self.map.as_ref(), &self.team, &mut self.rng) {
            self.problems.push(format!("navigation: {e}"));
        }
    }

    fn publish_pose(&mut self, estimate: PoseEstimate) {
        if let Err(e) = self.team.set_pose(estimate.pose, estimate.stamp) {
            self.problems.push(format!("team state rejected the pose: {e}"));
        }
    }

    /// Applies map versions that arrived in the team state since the last call to this robot's
    /// map copy (created over the operating area's grid on first use). Returns the number of
    /// cells changed; a corrupt blob is an error and changes nothing (later versions still apply
    /// next call).
    pub fn refresh_map(&mut self) -> Result<usize, MappingError> {
        let Some(spec) = self.map.as_ref().map(|m| m.map().spec).or(self.map_spec) else { return Ok(0) };
        let fresh: Vec<(RobotId, u64, std::sync::Arc<Vec<u8>>)> = self
            .team
            .map_writers()
            .filter_map(|robot| {
                let v = self.team.latest_map(robot)?;
                let newer = self.applied_maps.get(robot).is_none_or(|&seen| v.version > seen);
                newer.then(|| (robot.clone(), v.version, v.blob.clone()))
            })
            .collect();
        let mut changed = 0;
        for (robot, version, blob) in fresh {
            let compressed = CompressedMap::from_bytes(&blob)?;
            let map = self.map.get_or_insert_with(|| Orthomap::new(spec));
            changed += map.apply_compressed(&compressed)?;
            self.applied_maps.insert(robot, version);
        }
        Ok(changed)
    }

    // --- what nodes read --------------------------------------------------------------------------

    /// Latest map-frame pose estimate.
    pub fn pose(&self) -> Option<PoseEstimate> {
        self.pose
    }

    /// Latest map-frame position, or the start position before the first estimate.
    pub fn position_or_start(&self) -> Point2 {
        self.pose.map_or_else(|| self.start.position(), |p| p.pose.position())
    }

    /// Latest odometry.
    pub fn odometry(&self) -> Option<Odometry> {
        self.odometry
    }

    /// Latest panorama.
    pub fn panorama(&self) -> Option<&Arc<PanoramaFrame>> {
        self.panorama.as_ref()
    }

    /// The replicated team database.
    pub fn team(&self) -> &TeamState {
        &self.team
    }

    /// The team database as a node changes it: claim, release and mark goals (reads through
    /// it too). The sync with teammates and what the robot publishes of itself are the robot's
    /// own ([`TeamGoalsMut`]).
    pub fn team_mut(&mut self) -> TeamGoalsMut<'_> {
        TeamGoalsMut::new(&mut self.team)
    }

    /// The whole team database, for the robot's seam and upkeep (and a harness's, through
    /// [`DrivenRuntime::team_state_mut`]).
    pub(crate) fn team_state_mut(&mut self) -> &mut TeamState {
        &mut self.team
    }

    /// This robot's copy of the aerial map.
    pub fn map(&self) -> Option<&Orthomap> {
        self.map.as_ref()
    }

    /// Where the pose comes from, and the localizer's state.
    pub fn localization(&self) -> &Localization {
        &self.localization
    }

    /// The navigation stack (UGVs with navigation).
    pub fn nav(&self) -> Option<&NavStack> {
        self.nav.as_deref()
    }

    /// The navigation stack, to plan and mark what driving taught.
    pub fn nav_mut(&mut self) -> Option<&mut NavStack> {
        self.nav.as_deref_mut()
    }

    /// The navigation stack with the robot's random stream (local-goal sampling needs both).
    pub fn nav_and_rng(&mut self) -> Option<(&mut NavStack, &mut ChaCha8Rng)> {
        Some((self.nav.as_deref_mut()?, &mut self.rng))
    }

    /// This robot's random stream (skills take randomness from it, so runs repeat).
    pub fn rng(&mut self) -> &mut ChaCha8Rng {
        &mut self.rng
    }

    /// The mission's per-goal time limit per metre of planned path, s/m.
    pub fn goal_time_per_m_s(&self) -> f64 {
        self.goal_time_per_m_s
    }

    // --- what nodes do --------------------------------------------------------------------------

    /// Brings the map copy up to date with received map versions, then, if it changed since
    /// the last pass, detects goals in it and adds the new ones to the team state.
    pub fn detect_goals(&mut self, now: Time) -> DetectionPass {
        let mut pass = DetectionPass::default();
        if let Err(e) = self.refresh_map() {
            pass.problems.push(format!("a received map version is unusable: {e}"));
        }
        let (Some(map), Some(detector)) = (self.map.as_ref(), self.detector.as_mut()) else { return pass };
        if self.detected_version == Some(map.version()) {
            return pass;
        }
        let known: Vec<Point2> = self.team.goals().iter().map(|g| g.position).collect();
        match detector.detect(map.map(), &known) {
            Ok(found) => {
                for g in found.goals {
                    match self.team.identify_goal(g.position, GoalOrigin::Detected, now) {
                        Ok(IdentifyOutcome::New(_)) => pass.added += 1,
                        Ok(IdentifyOutcome::Existing(_)) => {}
                        Err(e) => pass.problems.push(e.to_string()),
                    }
                }
                self.detected_version = Some(map.version());
            }
            Err(e) => pass.problems.push(e.to_string()),
        }
        pass
    }

    /// Commands a velocity for this tick (UGVs).
    pub fn command_velocity(&mut self, twist: Twist2) {
        self.command = Some(twist);
    }

    /// Commands a flight target for this tick (UAVs).
    pub fn command_flight(&mut self, flight: FlightCommand) {
        self.flight = Some(flight);
    }

    /// Withdraws this tick's flight command: the UAV hovers.
    pub fn hover(&mut self) {
        self.flight = None;
    }

    /// Publishes the path the robot follows (map frame) and its end on the team state, so a
    /// seeking UAV can find the robot where it is heading.
    pub fn publish_path(&mut self, points: Vec<Point2>, end: Option<Point2>) {
        self.planned_path = Some(points);
        if let Err(e) = self.team.set_path_end(end) {
            self.problems.push(format!("team state rejected the path end: {e}"));
        }
    }

    /// Withdraws the published path.
    pub fn clear_path(&mut self) {
        self.planned_path = None;
        if let Err(e) = self.team.set_path_end(None) {
            self.problems.push(format!("team state rejected clearing the path end: {e}"));
        }
    }

    /// Records a problem for the adapter to report: at most [`MAX_REPORTED_PROBLEMS`] wait at
    /// once (the rest are counted, and the count reported), each cut to
    /// [`MAX_PROBLEM_CHARS`] characters. What a peer sends can cause one per message.
    pub fn report(&mut self, problem: String) {
        if self.problems.len() >= MAX_REPORTED_PROBLEMS {
            self.problems_left_out += 1;
            return;
        }
        let problem = match problem.char_indices().nth(MAX_PROBLEM_CHARS) {
            Some((end, _)) => format!("{}…", &problem[..end]),
            None => problem,
        };
        self.problems.push(problem);
    }

    // --- outputs (adapters, through `Robot`) ------------------------------------------------------

    /// The velocity command of the last tick; `None`: stop.
    pub fn command(&self) -> Option<Twist2> {
        self.command
    }

    /// The flight command of the last tick; `None`: hover.
    pub fn flight(&self) -> Option<FlightCommand> {
        self.flight
    }

    /// The path being followed, map frame.
    pub fn planned_path(&self) -> Option<&[Point2]> {
        self.planned_path.as_deref()
    }

    /// The problems met and not taken yet.
    pub fn problems(&self) -> &[String] {
        &self.problems
    }

    /// Adds problems met outside the runtime (its setup's warnings), reported with the others.
    pub(crate) fn note_problems(&mut self, problems: impl IntoIterator<Item = String>) {
        self.problems.extend(problems);
    }

    /// Takes the problems met since the last call.
    pub fn take_problems(&mut self) -> Vec<String> {
        if self.problems_left_out > 0 {
            let n = std::mem::take(&mut self.problems_left_out);
            self.problems.push(format!("{n} more problems left out (more than {MAX_REPORTED_PROBLEMS} at once)"));
        }
        std::mem::take(&mut self.problems)
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]

    use super::*;
    use spomp_core::{Cell, GridSpec};
    use spomp_global_planner::synthetic::{class, color};

    /// A 60 × 30 m all-road map (0.5 m cells).
    fn road_map() -> AerialMap {
        let mut map = AerialMap::unknown(GridSpec::new(Point2::new(0.0, 0.0), 0.5, 120, 60));
        for row in 0..60 {
            for col in 0..120 {
                let i = map.spec.index(Cell::new(col, row));
                (map.class[i], map.rgb[i], map.elevation[i]) = (class::ROAD, color::ROAD, 0.0);
            }
        }
        map.version = 1;
        map
    }

    fn ugv(prior_map: Option<AerialMap>) -> RobotRuntime {
        let mut config = RuntimeConfig::basic(RobotId::new("ugv1"), RobotKind::Ugv, 1, Pose2::new(5.0, 5.0, 0.0));
        config.map_spec = Some(road_map().spec);
        config.nav = Some(NavParams::default());
        config.prior_map = prior_map.map(Arc::new);
        RobotRuntime::from_config(config).unwrap()
    }

    #[test]
    fn a_robot_with_a_prior_map_can_plan_at_its_first_tick_with_background_skills() {
        let mut rt = ugv(Some(road_map()));
        rt.set_background_skills(true);
        assert!(rt.nav().unwrap().has_graph(), "the prior map's graph is built at setup");
    }

    #[test]
    fn robots_set_up_over_one_prior_map_hold_it_once() {
        let prior = Arc::new(road_map());
        let robot = |id: &str| {
            let mut config = RuntimeConfig::basic(RobotId::new(id), RobotKind::Ugv, 1, Pose2::new(5.0, 5.0, 0.0));
            config.map_spec = Some(prior.spec);
            config.nav = Some(NavParams::default());
            config.prior_map = Some(Arc::clone(&prior));
            let mut rt = RobotRuntime::from_config(config).unwrap();
            rt.maintain(Time::from_secs_f64(1.0));
            rt
        };
        let (a, b) = (robot("ugv1"), robot("ugv2"));
        assert!(a.nav().unwrap().has_graph() && b.nav().unwrap().has_graph());
        for rt in [&a, &b] {
            assert!(Arc::ptr_eq(&rt.map().unwrap().shared(), &prior), "{}: the map is the prior map", rt.id());
        }
        // Each robot's map and its planner's: four holders besides the test's.
        assert_eq!(Arc::strong_count(&prior), 5, "no robot copied it");
    }

    #[test]
    fn planner_work_runs_on_a_copy_and_is_swapped_in_with_what_arrived_meanwhile() {
        let mut rt = ugv(None);
        rt.set_background_skills(true);
        assert!(!rt.nav().unwrap().has_graph());
        // A map arrives (as a received version would make it): the graph is work, not inline.
        rt.map = Some(Orthomap::from_map(road_map()).unwrap());
        rt.maintain(Time::from_secs_f64(1.0));
        assert!(!rt.nav().unwrap().has_graph(), "maintain leaves the heavy upkeep to the work");
        let work = rt.take_work(Time::from_secs_f64(1.0));
        assert_eq!(work.iter().map(SkillWork::kind).collect::<Vec<_>>(), vec![WorkKind::Planner]);
        assert!(rt.take_work(Time::from_secs_f64(1.1)).is_empty(), "one planner job at a time");
        // Run elsewhere; meanwhile the tree still plans on the planner it has (no graph yet).
        let done = std::thread::spawn(move || work.into_iter().map(SkillWork::run).collect::<Vec<_>>()).join().unwrap();
        assert!(!rt.nav().unwrap().has_graph());
        for d in done {
            rt.finish_work(d);
        }
        assert!(rt.nav().unwrap().has_graph(), "the grown graph is swapped in");
        assert!(rt.take_problems().is_empty());
        let nav = rt.nav_mut().unwrap();
        assert!(nav.plan(Point2::new(5.0, 5.0), Point2::new(50.0, 20.0)).is_ok());
    }
}
