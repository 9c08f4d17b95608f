//! The robot runtime: what domain nodes reach through `TickContext::env`.
//!
//! An adapter (the simulator, the ROS 2 node, MCAP replay) owns one `RobotRuntime` per robot and
//! drives it the same way everywhere:
//! 1. feed the platform inputs: [`RobotRuntime::on_odometry`], [`RobotRuntime::on_panorama`],
//!    [`RobotRuntime::on_external_pose`] (GPS, or simulator ground truth where the mission asks);
//!    these run the robot's continuous skills (localization, terrain analysis, the global
//!    planner's experience) so every adapter gets the same robot;
//! 2. [`RobotRuntime::begin_tick`], then tick the executor with the runtime as `env`;
//! 3. read the outputs the nodes wrote this tick: [`RobotRuntime::command`] (UGV velocity) or
//!    [`RobotRuntime::flight`] (UAV waypoint); `None` means stop / hover, so a stale command never
//!    outlives the node that issued it.
//!
//! Nodes downcast `env` with [`runtime`]; a node ticked without it fails and says so, rather than
//! guessing.

mod localization;
mod navigation;

use std::collections::HashMap;
use std::sync::Arc;

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use spomp_core::{
    ClassTable, FlightCommand, GridSpec, Odometry, PanoramaFrame, Point2, Pose2, PoseEstimate, RobotId, RobotKind,
    Time, Twist2,
};
use spomp_mapping::{CompressedMap, GoalDetectionParams, GoalDetector, MappingError, Orthomap};
use spomp_teamstate::{TeamState, TeamStateError, TeamStateParams};

pub use localization::{Localization, LocalizationSetup, UpdateSchedule};
pub use navigation::{NavParams, NavStack};

use crate::node::TickContext;

/// How to set up one robot's runtime (from the mission and the adapter).
#[derive(Clone, Debug)]
pub struct RuntimeConfig {
    /// The robot.
    pub id: RobotId,
    /// Its kind.
    pub kind: RobotKind,
    /// UGV priority (lower = higher); 0 for other kinds is fine.
    pub priority: u32,
    /// Start pose in the map frame (home, and the localization prior's mean).
    pub start: Pose2,
    /// The semantic class table.
    pub classes: ClassTable,
    /// Grid of the operating area (the aerial map the team builds).
    pub map_spec: Option<GridSpec>,
    /// Team state parameters (deconfliction radius from the mission).
    pub team: TeamStateParams,
    /// Goal detection (from the mission's `goals.detect`); none for robots without it.
    pub detection: Option<GoalDetectionParams>,
    /// Where the map-frame pose comes from.
    pub localization: LocalizationSetup,
    /// Navigation parameters (UGVs).
    pub nav: Option<NavParams>,
    /// Per-goal time limit per metre of planned path (mission `goals.time_limit_per_m_s`).
    pub goal_time_per_m_s: f64,
    /// Seed of this robot's random stream (skills take randomness from it).
    pub seed: u64,
}

/// Errors setting up a runtime.
#[derive(Debug, thiserror::Error)]
pub enum RuntimeError {
    /// Team state parameters rejected.
    #[error("team state: {0}")]
    Team(#[from] TeamStateError),
    /// Goal detection parameters rejected.
    #[error("goal detection: {0}")]
    Detection(#[from] MappingError),
    /// A skill rejected its parameters.
    #[error("{skill}: {message}")]
    Skill {
        /// Which skill.
        skill: &'static str,
        /// What it said.
        message: String,
    },
}

/// One robot's state and skills as the behaviour nodes see them.
pub struct RobotRuntime {
    /// The robot.
    pub id: RobotId,
    /// Its kind.
    pub kind: RobotKind,
    /// The replicated team database.
    pub team: TeamState,
    /// Latest map-frame pose (from the localizer, GPS or simulator truth), kept current by the
    /// platform inputs.
    pub pose: Option<PoseEstimate>,
    /// Start pose (home).
    pub start: Pose2,
    /// The semantic class table.
    pub classes: ClassTable,
    /// This robot's copy of the aerial map, grown from map versions received in the team state.
    pub map: Option<Orthomap>,
    /// Goal detection as the mission's `goals.detect` configures it (none: no detection).
    pub detector: Option<GoalDetector>,
    /// Map version the last detection pass ran on.
    pub detected_version: Option<u64>,
    /// Grid of the operating area, for the map copy received maps grow.
    pub map_spec: Option<GridSpec>,
    /// Latest odometry.
    pub odometry: Option<Odometry>,
    /// Latest panorama.
    pub panorama: Option<Arc<PanoramaFrame>>,
    /// Velocity command written by a driving node this tick (UGVs); `None`: stop.
    pub command: Option<Twist2>,
    /// Flight command written by a flying node this tick (UAVs); `None`: hover.
    pub flight: Option<FlightCommand>,
    /// The path being followed, map frame (for logs and the team state's path end).
    pub planned_path: Option<Vec<Point2>>,
    /// Per-goal time limit per metre of planned path.
    pub goal_time_per_m_s: f64,
    /// This robot's random stream.
    pub rng: ChaCha8Rng,
    /// Where the pose comes from, and the localizer's state.
    pub localization: Localization,
    /// Terrain analysis, global planner and controller (UGVs with navigation).
    pub nav: Option<Box<NavStack>>,
    /// Problems met outside a tick (a bad map blob, a skill error), drained by the adapter.
    pub problems: Vec<String>,
    /// Newest map version applied, per publishing robot.
    applied_maps: HashMap<RobotId, u64>,
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
            classes: ClassTable::default_table(),
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
            applied_maps: HashMap::new(),
        })
    }

    /// A runtime set up from a mission's description of the robot.
    pub fn from_config(config: RuntimeConfig) -> Result<Self, RuntimeError> {
        let mut rt = RobotRuntime::new(config.id, config.kind, config.priority, config.start, config.team)?;
        rt.classes = config.classes;
        rt.map_spec = config.map_spec;
        rt.goal_time_per_m_s = config.goal_time_per_m_s;
        rt.rng = ChaCha8Rng::seed_from_u64(config.seed);
        if let Some(det) = config.detection {
            rt.detector = Some(GoalDetector::new(det, &rt.classes)?);
        }
        rt.localization = Localization::from_setup(&config.localization, config.start)?;
        if let Some(nav) = config.nav {
            rt.nav = Some(Box::new(NavStack::new(nav, &rt.classes)?));
        }
        Ok(rt)
    }

    /// Clears this tick's outputs; call before ticking the executor.
    pub fn begin_tick(&mut self) {
        self.command = None;
        self.flight = None;
    }

    /// A pose from outside the robot's own estimation: GPS on the UAV, the basestation's
    /// surveyed position, or (where the mission asks for it) simulator ground truth plus noise.
    /// Ignored while a cross-view localizer owns the pose.
    pub fn on_external_pose(&mut self, estimate: PoseEstimate) {
        if matches!(self.localization, Localization::External) {
            self.pose = Some(estimate);
            self.publish_pose(estimate);
        }
    }

    /// New odometry: the pose between panoramas is the last filtered pose composed with the
    /// odometry since (the paper's scheme).
    pub fn on_odometry(&mut self, odom: Odometry) {
        self.odometry = Some(odom);
        if let Some(estimate) = self.localization.pose_at(&odom, &mut self.rng) {
            self.pose = Some(estimate);
            self.publish_pose(estimate);
        }
    }

    /// A new panorama: brings the map copy up to date, runs the localizer's measurement update,
    /// then terrain analysis (reachability scan shared on the team state and fed to the global
    /// planner).
    pub fn on_panorama(&mut self, frame: Arc<PanoramaFrame>) {
        self.panorama = Some(frame.clone());
        if let Some(spec) = self.map.as_ref().map(|m| m.map().spec).or(self.map_spec)
            && let Err(e) = self.ingest_team_maps(spec)
        {
            self.problems.push(format!("a received map version is unusable: {e}"));
        }
        let map = self.map.as_ref().map(|m| (m.map(), m.version()));
        match self.localization.on_panorama(&frame, map, &self.classes, &mut self.rng) {
            Ok(Some(estimate)) => {
                self.pose = Some(estimate);
                self.publish_pose(estimate);
            }
            Ok(None) => {}
            Err(e) => self.problems.push(format!("localization: {e}")),
        }
        if let (Some(nav), Some(pose)) = (self.nav.as_deref_mut(), self.pose) {
            let map = self.map.as_ref();
            match nav.on_panorama(&self.id, &frame, pose, map, &mut self.team, &mut self.rng) {
                Ok(()) => {}
                Err(e) => self.problems.push(format!("navigation: {e}")),
            }
        }
    }

    /// Background upkeep at simulated/real time `now`: the team state's clock (own claims
    /// renewed, other robots' expired claims dropped); the global planner takes in new map
    /// versions and team scans and retrains on its schedule. Call once per control period.
    pub fn maintain(&mut self, now: Time) {
        self.team.advance_clock(now);
        if let Some(nav) = self.nav.as_deref_mut()
            && let Err(e) = nav.maintain(now, self.map.as_ref(), &self.team, &mut self.rng)
        {
            self.problems.push(format!("navigation: {e}"));
        }
    }

    fn publish_pose(&mut self, estimate: PoseEstimate) {
        if let Err(e) = self.team.set_pose(estimate.pose, estimate.stamp) {
            self.problems.push(format!("team state rejected the pose: {e}"));
        }
    }

    /// Applies map versions that arrived in the team state since the last call to this robot's
    /// map copy (created over `spec` on first use). Returns the number of cells changed; a
    /// corrupt blob is an error and changes nothing (later versions still apply next call).
    pub fn ingest_team_maps(&mut self, spec: GridSpec) -> Result<usize, MappingError> {
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
}

/// The runtime in `ctx.env`, or a report naming the node that needed it.
pub fn runtime<'c>(ctx: &'c mut TickContext<'_>, node: &str) -> Option<&'c mut RobotRuntime> {
    if ctx.env.is::<RobotRuntime>() {
        ctx.env.downcast_mut::<RobotRuntime>()
    } else {
        ctx.blackboard.report(format!(
            "node `{node}` needs a robot runtime; run the mission through an adapter (spomp sim / run)"
        ));
        None
    }
}
