//! A UGV's navigation stack inside its runtime: terrain analysis on every panorama (the safe
//! region for the controller, the reachability scan for the team and the global planner), the
//! global planner kept current with the map copy, the team's scans and its training schedule.
//! The driving nodes (`navigate_to`, `navigate_local`, `return_home`) use it.

use std::collections::VecDeque;
use std::sync::{Arc, Mutex, PoisonError};

use rand_chacha::ChaCha8Rng;
use spomp_core::{
    AerialMap, ClassTable, DepthPanorama, PanoramaFrame, PanoramaGeometry, Point2, Pose2, PoseEstimate,
    ReachabilityScan, RobotId, Time,
};
use spomp_global_planner::{
    GlobalPath, GlobalPlanner, GlobalPlannerParams, NodeId, PlanError, ScanSharer, TrainOutcome,
};
use spomp_local_planner::{Dwa, LocalPlannerParams, SafeRegion, TerrainAnalyzer, TerrainParams};
use spomp_mapping::Orthomap;
use spomp_teamstate::TeamState;

use super::RuntimeError;
use crate::settings::WatchdogParams;

/// Spacing of the robot's trail points, metres.
const TRAIL_SPACING_M: f64 = 2.0;

/// Trail points kept (400 m of driving at the spacing).
const TRAIL_POINTS: usize = 200;

/// A backtracking plan aims at least this far back along the trail (and this far from any place
/// the robot got stuck), metres.
const BACKTRACK_MIN_M: f64 = 6.0;

/// Graph nodes along the trail tried as the start of a backtracking plan.
const MAX_BACKTRACK_ATTEMPTS: usize = 12;

/// Graph nodes nearest a goal in unmapped territory tried as the end of the graph part of the
/// path ([`NavStack::plan`]).
const MAX_UNMAPPED_GOAL_ATTEMPTS: usize = 8;

/// Terrain analyzers not lent to a job, for any robot of the process. An analyzer is scratch
/// (tables and ≈ 26 bytes of buffers per panorama pixel: 6.8 MB at 256 × 1024) whose result
/// depends on the panorama alone, so robots stepped one after another — a simulated team —
/// share a few instead of each holding one between panoramas; robots on their own threads take
/// one each.
// Boxed as the jobs carry them: taking one out or giving it back moves a pointer.
#[allow(clippy::vec_box)]
static IDLE_ANALYZERS: Mutex<Vec<Box<TerrainAnalyzer>>> = Mutex::new(Vec::new());

/// Idle analyzers kept for reuse (more are dropped when given back): enough for the robots of
/// a process analysing panoramas at the same time on a many-core machine.
const MAX_IDLE_ANALYZERS: usize = 16;

/// An idle analyzer for this geometry and these parameters, or a new one.
fn take_analyzer(geometry: PanoramaGeometry, params: &TerrainParams) -> Result<Box<TerrainAnalyzer>, String> {
    {
        let mut idle = IDLE_ANALYZERS.lock().unwrap_or_else(PoisonError::into_inner);
        if let Some(k) = idle.iter().position(|a| a.geometry() == geometry && a.params() == params) {
            return Ok(idle.swap_remove(k));
        }
    }
    TerrainAnalyzer::new(geometry, params.clone()).map(Box::new).map_err(|e| e.to_string())
}

/// Gives an analyzer back for any robot to use.
fn give_back_analyzer(analyzer: Box<TerrainAnalyzer>) {
    let mut idle = IDLE_ANALYZERS.lock().unwrap_or_else(PoisonError::into_inner);
    if idle.len() < MAX_IDLE_ANALYZERS {
        idle.push(analyzer);
    }
}

/// Navigation parameters of a UGV: a plain value of parameters (public fields, each the
/// skill's own params type; the rule in docs/ARCHITECTURE.md, "Public fields"), resolved once
/// by `RobotSetup` and read by the runtime.
#[derive(Clone, Debug, Default)]
pub struct NavParams {
    /// Local planner (terrain analysis, local goal, DWA).
    pub local: LocalPlannerParams,
    /// Global planner (graph, learning, experience, sharing, search).
    pub global: GlobalPlannerParams,
    /// When driving nodes give up as stuck.
    pub watchdog: WatchdogParams,
}

/// The latest terrain analysis, with where the robot was when the panorama was taken.
#[derive(Clone, Debug)]
pub struct LocalView {
    /// Safe region in the robot frame at the panorama.
    pub(crate) region: SafeRegion,
    /// Map-frame pose estimate at the panorama.
    pub(crate) pose: PoseEstimate,
    /// Odometry-frame pose at the panorama (compose with later odometry to express the region
    /// in the current robot frame).
    pub(crate) odom_pose: Pose2,
    /// When the panorama was taken.
    pub(crate) stamp: Time,
}

impl LocalView {
    /// Safe region in the robot frame at the panorama.
    pub fn region(&self) -> &SafeRegion {
        &self.region
    }

    /// Map-frame pose estimate at the panorama.
    pub fn pose(&self) -> PoseEstimate {
        self.pose
    }

    /// Odometry-frame pose at the panorama.
    pub fn odom_pose(&self) -> Pose2 {
        self.odom_pose
    }

    /// When the panorama was taken.
    pub fn stamp(&self) -> Time {
        self.stamp
    }
}

/// Navigation state of one UGV.
pub struct NavStack {
    /// Parameters.
    params: NavParams,
    /// The latest safe region.
    view: Option<LocalView>,
    /// The latest reachability scan (map frame).
    latest_scan: Option<Arc<ReachabilityScan>>,
    /// The depth image the latest analysis ran on.
    analyzed_depth: Option<Arc<DepthPanorama>>,
    /// The obstacle mask of the latest analysis (row-major in its geometry), kept for
    /// observers: the analyzer itself goes back to the process's idle ones.
    latest_obstacles: Option<(PanoramaGeometry, Vec<bool>)>,
    /// The global planner.
    global: GlobalPlanner,
    /// The DWA controller.
    dwa: Dwa,
    /// Which scans go to the team (the paper's communication modes).
    sharer: ScanSharer,
    /// Graph edges (node pairs) this robot failed to get across while driving them: the
    /// driving nodes' experience of a blockage the scans could not judge (see [`NavStack::plan`]).
    blocked_edges: Vec<(NodeId, NodeId)>,
    /// Where the robot has been (map frame, every [`TRAIL_SPACING_M`], newest last): ground it
    /// drove, the way back when the graph has no path from where it stands.
    trail: VecDeque<Point2>,
    /// Where the robot got stuck ([`NavStack::note_stuck_at`]).
    stuck_spots: Vec<Point2>,
    /// Ground teammates: an edge a scan finds blocked by one is marked, never removed.
    ground_teammates: Vec<RobotId>,
    /// Scratch for their positions (no allocation per panorama).
    teammate_positions: Vec<Point2>,
    map_version_seen: Option<u64>,
    team_scan_cursor: usize,
    /// A [`PlannerJob`] holds a copy of the planner.
    planner_in_flight: bool,
    /// Scans given to the planner since its copy left, for the copy when it is back.
    scans_since_planner_left: Vec<(Arc<ReachabilityScan>, ScanOrigin)>,
    /// No training-only planner job before this time (the last one found too few labels).
    retry_training_at: Option<Time>,
}

/// Terrain analysis of one panorama, as a job: see [`NavStack::begin_analysis`].
pub(crate) enum TerrainJob {
    /// Run the analyzer.
    Analyze {
        /// The stack's analyzer, lent.
        analyzer: Box<TerrainAnalyzer>,
        /// The terrain parameters (for the safe region).
        params: TerrainParams,
    },
    /// The depth image was analysed last time: this is that analysis.
    Reuse {
        /// The safe region.
        region: SafeRegion,
        /// The scan (stamp and pose replaced).
        scan: ReachabilityScan,
    },
}

impl TerrainJob {
    /// The safe region and the scan of `frame`, stamped with the frame's time; the scan's pose
    /// is left for the caller to set (the localization of the same frame gives it).
    pub(crate) fn analyze(
        &mut self,
        robot: &RobotId,
        frame: &PanoramaFrame,
    ) -> Result<(SafeRegion, ReachabilityScan), String> {
        match self {
            TerrainJob::Analyze { analyzer, params } => {
                let output = analyzer.analyze(&frame.depth).map_err(|e| e.to_string())?;
                let region = SafeRegion::from_terrain(output, params).map_err(|e| e.to_string())?;
                Ok((region, output.to_scan(robot.clone(), frame.stamp, Pose2::default())))
            }
            TerrainJob::Reuse { region, scan } => {
                Ok((region.clone(), ReachabilityScan { stamp: frame.stamp, ..scan.clone() }))
            }
        }
    }
}

/// Whose a scan given to the planner is, so the planner's copy gets it the same way.
#[derive(Debug)]
enum ScanOrigin {
    /// This robot's, taken with its ground teammates at these positions.
    Own { teammates: Vec<Point2> },
    /// Another robot's (never removes an edge).
    Peer,
}

/// The global planner's heavy upkeep on a copy of it: [`NavStack::begin_planner_work`].
pub(crate) struct PlannerJob {
    planner: Box<GlobalPlanner>,
    new_map: Option<(Arc<AerialMap>, u64)>,
    now: Time,
    rng: ChaCha8Rng,
}

/// A finished [`PlannerJob`].
pub(crate) struct PlannerDone {
    planner: Box<GlobalPlanner>,
    map_version: Option<u64>,
    /// Whether a training round ran; the error that stopped the job.
    result: Result<bool, String>,
    now: Time,
}

impl PlannerJob {
    /// Grows the graph on the new map version, then trains if due.
    pub(crate) fn run(mut self) -> PlannerDone {
        let map_version = self.new_map.as_ref().map(|(_, v)| *v);
        let mut result = Ok(false);
        if let Some((map, _)) = &self.new_map
            && let Err(e) = self.planner.update_map_shared(Arc::clone(map))
        {
            result = Err(e.to_string());
        }
        if result.is_ok() {
            let outcome = self.planner.train(self.now, &mut self.rng);
            result = Ok(matches!(outcome, TrainOutcome::Trained { .. }));
        }
        PlannerDone { planner: self.planner, map_version, result, now: self.now }
    }
}

impl NavStack {
    /// The parameters in force.
    pub fn params(&self) -> &NavParams {
        &self.params
    }

    /// The latest safe region (from the latest panorama).
    pub fn view(&self) -> Option<&LocalView> {
        self.view.as_ref()
    }

    /// The latest reachability scan (map frame).
    pub fn latest_scan(&self) -> Option<&Arc<ReachabilityScan>> {
        self.latest_scan.as_ref()
    }

    /// The global planner.
    pub fn global(&self) -> &GlobalPlanner {
        &self.global
    }

    /// The global planner, for a tool or test that queries it (its queries keep caches).
    pub fn global_mut(&mut self) -> &mut GlobalPlanner {
        &mut self.global
    }

    /// The DWA controller.
    pub fn dwa(&self) -> &Dwa {
        &self.dwa
    }

    /// Which scans go to the team.
    pub fn sharer(&self) -> &ScanSharer {
        &self.sharer
    }

    /// Graph edges this robot failed to get across while driving them.
    pub fn blocked_edges(&self) -> &[(NodeId, NodeId)] {
        &self.blocked_edges
    }

    /// A stack with no map and no experience.
    pub fn new(params: NavParams, classes: &ClassTable) -> Result<Self, RuntimeError> {
        let skill = |skill: &'static str| {
            move |e: &dyn std::fmt::Display| RuntimeError::Skill { skill, message: e.to_string() }
        };
        params.local.validate().map_err(|e| skill("local_planner")(&e))?;
        let global =
            GlobalPlanner::new(params.global.clone(), classes.clone()).map_err(|e| skill("global_planner")(&e))?;
        let dwa = Dwa::new(params.local.dwa.clone()).map_err(|e| skill("local_planner")(&e))?;
        let sharer = ScanSharer::new(params.global.sharing.clone());
        Ok(NavStack {
            params,
            view: None,
            latest_scan: None,
            analyzed_depth: None,
            latest_obstacles: None,
            global,
            dwa,
            sharer,
            blocked_edges: Vec::new(),
            trail: VecDeque::new(),
            stuck_spots: Vec::new(),
            ground_teammates: Vec::new(),
            teammate_positions: Vec::new(),
            map_version_seen: None,
            team_scan_cursor: 0,
            planner_in_flight: false,
            scans_since_planner_left: Vec::new(),
            retry_training_at: None,
        })
    }

    /// Prepares terrain analysis of `frame`: an analyzer for the frame's geometry (an idle one
    /// of the process, else a new one) is lent to the job, or, when the depth image is the one
    /// analysed last (a sensor that re-sends its last frame, the simulator's still robot), the
    /// job reuses that analysis and only the stamp and pose are new.
    pub(crate) fn begin_analysis(&mut self, frame: &PanoramaFrame) -> Result<TerrainJob, String> {
        if let (Some(last), Some(view), Some(scan)) = (&self.analyzed_depth, &self.view, &self.latest_scan)
            && Arc::ptr_eq(last, &frame.depth)
        {
            return Ok(TerrainJob::Reuse { region: view.region.clone(), scan: (**scan).clone() });
        }
        let analyzer = take_analyzer(frame.depth.geometry, &self.params.local.terrain)?;
        Ok(TerrainJob::Analyze { analyzer, params: self.params.local.terrain.clone() })
    }

    /// Takes back what [`Self::begin_analysis`] lent the job (the analyzer goes back to the
    /// process's idle ones).
    pub(crate) fn end_analysis(&mut self, job: TerrainJob) {
        if let TerrainJob::Analyze { analyzer, .. } = job {
            let (geometry, mask) = self.latest_obstacles.get_or_insert_with(|| (analyzer.geometry(), Vec::new()));
            *geometry = analyzer.geometry();
            mask.clear();
            mask.extend_from_slice(analyzer.output().obstacle());
            give_back_analyzer(analyzer);
        }
    }

    /// The obstacle mask of the latest terrain analysis (row-major in its panorama geometry).
    pub fn terrain_obstacles(&self) -> Option<(PanoramaGeometry, &[bool])> {
        self.latest_obstacles.as_ref().map(|(g, mask)| (*g, mask.as_slice()))
    }

    /// The result of terrain analysis of `frame` taken at `pose`: updates the safe region,
    /// gives the scan to the global planner as the robot's own experience (when it has a map),
    /// and shares it on the team state when the sharing filter lets it through.
    pub(crate) fn apply_analysis(
        &mut self,
        frame: &PanoramaFrame,
        pose: PoseEstimate,
        (region, scan): (SafeRegion, ReachabilityScan),
        has_map: bool,
        team: &mut TeamState,
    ) -> Result<(), String> {
        self.analyzed_depth = Some(frame.depth.clone());
        self.record_trail(pose.pose.position());
        let scan = Arc::new(scan);
        self.view = Some(LocalView { region, pose, odom_pose: frame.odom_pose, stamp: frame.stamp });
        if has_map {
            // An edge a teammate blocks is marked, never removed (see
            // `GlobalPlanner::add_own_scan_among`).
            self.gather_teammate_positions(scan.stamp, team);
            self.global.add_own_scan_among(&scan, &self.teammate_positions).map_err(|e| e.to_string())?;
            if self.planner_in_flight {
                let teammates = self.teammate_positions.clone();
                self.scans_since_planner_left.push((scan.clone(), ScanOrigin::Own { teammates }));
            }
        }
        if self.sharer.should_share(&scan) {
            team.add_scan((*scan).clone()).map_err(|e| e.to_string())?;
        }
        self.latest_scan = Some(scan);
        Ok(())
    }

    /// The ground teammates whose bodies show in this robot's panoramas
    /// ([`Self::gather_teammate_positions`]).
    pub fn set_ground_teammates(&mut self, teammates: Vec<RobotId>) {
        self.ground_teammates = teammates;
    }

    /// The ground teammates' last known positions (map frame) in `team`, no older than
    /// `experience.teammate_max_age_s` at `stamp`, into `teammate_positions`; none when the
    /// teammate rule is off (`experience.teammate_clearance_m` 0).
    fn gather_teammate_positions(&mut self, stamp: Time, team: &TeamState) {
        self.teammate_positions.clear();
        let x = &self.params.global.experience;
        if x.teammate_clearance_m <= 0.0 {
            return;
        }
        let now = stamp.as_secs_f64();
        for id in &self.ground_teammates {
            if let Some((pose, seen)) = team.robot_pose(id)
                && now - seen.as_secs_f64() <= x.teammate_max_age_s
            {
                self.teammate_positions.push(pose.position());
            }
        }
    }

    /// Keeps the global planner current: a new map version grows the graph; scans other robots
    /// shared since the last call update the model and the edges (never removing one); a
    /// training round runs when due.
    pub fn maintain(
        &mut self,
        now: Time,
        map: Option<&Orthomap>,
        team: &TeamState,
        rng: &mut ChaCha8Rng,
    ) -> Result<(), String> {
        let Some(map) = map else { return Ok(()) };
        if self.map_version_seen != Some(map.version()) {
            self.global.update_map_shared(map.shared()).map_err(|e| e.to_string())?;
            self.map_version_seen = Some(map.version());
        }
        self.take_team_scans(team);
        self.global.train(now, rng);
        Ok(())
    }

    /// [`Self::maintain`] with the heavy part (growing the graph, training) left to
    /// [`Self::begin_planner_work`]: only the team's new scans are taken in here.
    pub(crate) fn maintain_light(&mut self, map: Option<&Orthomap>, team: &TeamState) {
        if map.is_some() {
            self.take_team_scans(team);
        }
    }

    /// Scans other robots shared since the last call, into the planner. A malformed scan from
    /// a peer is skipped; it must not stop the robot.
    fn take_team_scans(&mut self, team: &TeamState) {
        let (scans, cursor) = team.scans_since(self.team_scan_cursor);
        let own = team.self_id().clone();
        for scan in scans.iter().filter(|s| s.robot != own) {
            let _ = self.global.add_scan(scan, false);
            if self.planner_in_flight {
                self.scans_since_planner_left.push((Arc::clone(scan), ScanOrigin::Peer));
            }
        }
        self.team_scan_cursor = cursor;
    }

    /// Whether the global planner has heavy upkeep due ([`Self::begin_planner_work`]): a new
    /// map version to grow the graph on, or a training round; never while a job is out.
    pub(crate) fn planner_work_due(&self, now: Time, map: Option<&Orthomap>) -> bool {
        let Some(map) = map else { return false };
        !self.planner_in_flight
            && (self.map_version_seen != Some(map.version())
                || (self.map_version_seen.is_some()
                    && self.global.training_due(now)
                    && self.retry_training_at.is_none_or(|t| now >= t)))
    }

    /// The global planner's heavy upkeep as a job for another thread (call when
    /// [`Self::planner_work_due`]): the graph grown on a new map version, a training round when
    /// due. The job works on a copy; the planner here keeps answering the driving nodes until
    /// [`Self::finish_planner_work`] swaps the copy in.
    pub(crate) fn begin_planner_work(&mut self, now: Time, map: Option<&Orthomap>, rng: ChaCha8Rng) -> PlannerJob {
        let new_map = map.filter(|m| self.map_version_seen != Some(m.version())).map(|m| (m.shared(), m.version()));
        self.planner_in_flight = true;
        PlannerJob { planner: Box::new(self.global.clone()), new_map, now, rng }
    }

    /// Swaps in the planner a [`PlannerJob`] brought up to date, after giving it the scans
    /// taken in here since it left.
    pub(crate) fn finish_planner_work(&mut self, done: PlannerDone) -> Result<(), String> {
        self.planner_in_flight = false;
        let PlannerDone { mut planner, map_version, result, now } = done;
        match result {
            Ok(trained) => {
                for (scan, origin) in self.scans_since_planner_left.drain(..) {
                    let _ = match origin {
                        ScanOrigin::Own { teammates } => planner.add_own_scan_among(&scan, &teammates),
                        ScanOrigin::Peer => planner.add_scan(&scan, false),
                    };
                }
                // Edges failed while the copy was out (no-ops for those it already knew).
                for &(a, b) in &self.blocked_edges {
                    planner.mark_failed_edge(a, b);
                }
                self.global = *planner;
                if let Some(v) = map_version {
                    self.map_version_seen = Some(v);
                }
                // Too few labels yet: a copy of the planner every tick would be waste.
                self.retry_training_at = (!trained).then(|| Time::from_secs_f64(now.as_secs_f64() + 1.0));
                Ok(())
            }
            Err(e) => {
                self.scans_since_planner_left.clear();
                Err(e)
            }
        }
    }

    /// Whether the global planner has a graph yet (an aerial map arrived).
    pub fn has_graph(&self) -> bool {
        self.global.nodes().next().is_some()
    }

    /// Records that the robot could not get across the edge between `a` and `b`: the global
    /// planner marks the edge failed from experience (`GlobalPlanner::mark_failed_edge`: removed
    /// for good, its own observation locks it), so no later plan of any node sends the robot
    /// back the same way. The record is kept here as well, to be given again to a planner copy
    /// that was out for upkeep ([`NavStack::begin_planner_work`]) when it comes back.
    pub fn block_edge(&mut self, a: NodeId, b: NodeId) {
        let key = if a.0 <= b.0 { (a, b) } else { (b, a) };
        if !self.blocked_edges.contains(&key) {
            self.blocked_edges.push(key);
        }
        self.global.mark_failed_edge(a, b);
    }

    /// Plans from `from` to `to` on the global planner, avoiding the edges the robot recorded as
    /// blocked ([`NavStack::block_edge`]). That record is experience too: with graph updates off
    /// (`global.experience.graph_updates: false`, the paper's ablation) it is not used.
    ///
    /// When the graph has no path from where the robot stands (the edges of the node covering
    /// it were all seen blocked, say inside a parking lot whose straight edges cross parked
    /// vehicles), the robot backtracks: the path starts with its own trail back to the newest
    /// trail point from which the graph has one ([`GlobalPath::lead_in`] counts those points).
    ///
    /// When the goal lies where this robot's map has no data yet (a goal another robot found in
    /// a map version that has not reached this one over the radio), the path runs over the
    /// graph to the node nearest the goal that it can reach and then straight on to the goal,
    /// a last stretch the local planner drives alone; a replan after the map arrives finds the
    /// whole way on the graph.
    pub fn plan(&mut self, from: Point2, to: Point2) -> Result<GlobalPath, PlanError> {
        match self.plan_on_graph(from, to) {
            Err(unmapped @ PlanError::Unmapped { which: "goal", .. }) => {
                self.plan_into_unmapped(from, to).ok_or(unmapped)
            }
            other => other,
        }
    }

    /// [`NavStack::plan`] without the unmapped-goal fallback.
    fn plan_on_graph(&mut self, from: Point2, to: Point2) -> Result<GlobalPath, PlanError> {
        let avoid: &[(NodeId, NodeId)] =
            if self.params.global.experience.graph_updates { &self.blocked_edges } else { &[] };
        match self.global.plan_avoiding(from, to, avoid) {
            Err(PlanError::NoPath) => self.plan_backtracking(from, to),
            other => other,
        }
    }

    /// A path to the reachable graph node nearest `to` (of the [`MAX_UNMAPPED_GOAL_ATTEMPTS`]
    /// nearest), extended straight to `to`.
    fn plan_into_unmapped(&mut self, from: Point2, to: Point2) -> Option<GlobalPath> {
        let mut nearest: Vec<(f64, Point2)> = self.global.nodes().map(|(_, p, _)| (p.distance(to), p)).collect();
        nearest.sort_by(|a, b| a.0.total_cmp(&b.0));
        nearest.truncate(MAX_UNMAPPED_GOAL_ATTEMPTS);
        nearest.into_iter().find_map(|(tail_m, node)| {
            let mut path = self.plan_on_graph(from, node).ok()?;
            path.waypoints.push(to);
            path.length_m += tail_m;
            Some(path)
        })
    }

    /// A path that backs out along the robot's trail to the newest trail point (at least
    /// 6 m (`BACKTRACK_MIN_M`) away, not near a place the robot got stuck) from which the graph has
    /// a path to `to`, then follows that path; [`PlanError::NoPath`] when no trail point has one.
    pub fn plan_backtracking(&mut self, from: Point2, to: Point2) -> Result<GlobalPath, PlanError> {
        let avoid: &[(NodeId, NodeId)] =
            if self.params.global.experience.graph_updates { &self.blocked_edges } else { &[] };
        let mut tried = Vec::new();
        tried.extend(self.global.covering_node(from));
        for k in (0..self.trail.len()).rev() {
            let back = self.trail[k];
            if back.distance(from) < BACKTRACK_MIN_M
                || self.stuck_spots.iter().any(|s| s.distance(back) < BACKTRACK_MIN_M)
            {
                continue;
            }
            // One attempt per graph node: trail points covered by a node already tried would
            // attach the same way.
            let Some(node) = self.global.covering_node(back) else { continue };
            if tried.contains(&node) {
                continue;
            }
            if tried.len() > MAX_BACKTRACK_ATTEMPTS {
                break;
            }
            tried.push(node);
            if let Ok(mut path) = self.global.plan_avoiding(back, to, avoid) {
                let mut waypoints = Vec::with_capacity(self.trail.len() - k + path.waypoints.len());
                waypoints.push(from);
                waypoints.extend(self.trail.range(k + 1..).rev().copied());
                path.lead_in = waypoints.len();
                for k in &mut path.node_waypoints {
                    *k += path.lead_in;
                }
                waypoints.append(&mut path.waypoints);
                path.length_m = waypoints.windows(2).map(|w| w[0].distance(w[1])).sum();
                path.waypoints = waypoints;
                return Ok(path);
            }
        }
        Err(PlanError::NoPath)
    }

    /// Records a place where the robot got stuck: backtracking never aims back at it.
    pub fn note_stuck_at(&mut self, p: Point2) {
        if self.stuck_spots.len() >= TRAIL_POINTS {
            self.stuck_spots.remove(0);
        }
        self.stuck_spots.push(p);
    }

    /// Adds `p` to the trail when it is [`TRAIL_SPACING_M`] from the newest point; the trail
    /// keeps the last [`TRAIL_POINTS`].
    fn record_trail(&mut self, p: Point2) {
        if !(p.x.is_finite() && p.y.is_finite()) || self.trail.back().is_some_and(|q| q.distance(p) < TRAIL_SPACING_M) {
            return;
        }
        if self.trail.len() >= TRAIL_POINTS {
            self.trail.pop_front();
        }
        self.trail.push_back(p);
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]

    use super::*;
    use spomp_core::{AerialMap, Cell, GridSpec, UNKNOWN_CLASS};
    use spomp_global_planner::synthetic::{class, color};

    /// A 100 × 50 m map (0.5 m cells) of which only `roads` (columns × rows of cells) are
    /// mapped, as road; the rest is unknown.
    fn partly_mapped(roads: &[(std::ops::Range<u32>, std::ops::Range<u32>)]) -> AerialMap {
        let mut map = AerialMap::unknown(GridSpec::new(Point2::new(0.0, 0.0), 0.5, 200, 100));
        for (cols, rows) in roads {
            for row in rows.clone() {
                for col in cols.clone() {
                    let i = map.spec.index(Cell::new(col, row));
                    (map.class[i], map.rgb[i], map.elevation[i]) = (class::ROAD, color::ROAD, 0.0);
                }
            }
        }
        map.version = 1;
        map
    }

    fn stack(map: &AerialMap) -> NavStack {
        let mut nav = NavStack::new(NavParams::default(), &ClassTable::default_table()).unwrap();
        nav.global.update_map(map).unwrap();
        nav
    }

    #[test]
    fn a_goal_in_unmapped_territory_is_approached_over_the_graph_then_straight_on() {
        // A road along the south edge, x 0–100 m, y 0–8 m; the goal 30 m north of its east half.
        let map = partly_mapped(&[(0..200, 0..16)]);
        assert_eq!(map.class[map.spec.index(Cell::new(140, 76))], UNKNOWN_CLASS);
        let mut nav = stack(&map);
        let (start, goal) = (Point2::new(4.0, 4.0), Point2::new(70.0, 38.0));
        assert!(matches!(nav.global.plan(start, goal), Err(PlanError::Unmapped { .. })));
        let path = nav.plan(start, goal).unwrap();
        let (last, before) = (path.waypoints[path.waypoints.len() - 1], path.waypoints[path.waypoints.len() - 2]);
        assert_eq!(last, goal);
        // The graph part ends on the road, below the goal.
        assert!(before.y <= 8.0 && (before.x - goal.x).abs() < 10.0, "graph part ends at {before:?}");
        let length: f64 = path.waypoints.windows(2).map(|w| w[0].distance(w[1])).sum();
        assert!((path.length_m - length).abs() < 1e-6, "{} against {length}", path.length_m);
        // Nodes index the graph part only.
        assert!(path.node_waypoints.iter().all(|&k| k + 1 < path.waypoints.len()));
    }

    #[test]
    fn an_unmapped_goal_with_no_reachable_node_near_it_is_still_an_error() {
        // The robot's patch of road in the south-west corner, 10 × 8 m; a large mapped lot in the
        // east half that no edge joins to it. The goal lies between them, nearer the lot, whose
        // nodes are all nearer than the robot's.
        let map = partly_mapped(&[(0..20, 0..16), (100..200, 0..100)]);
        let mut nav = stack(&map);
        let (start, goal) = (Point2::new(4.0, 4.0), Point2::new(42.0, 25.0));
        let patch_m = nav
            .global
            .nodes()
            .filter(|(_, p, _)| p.x < 10.0)
            .map(|(_, p, _)| p.distance(goal))
            .fold(f64::MAX, f64::min);
        let lot_nearer = nav.global.nodes().filter(|(_, p, _)| p.x >= 50.0 && p.distance(goal) < patch_m).count();
        assert!(lot_nearer >= MAX_UNMAPPED_GOAL_ATTEMPTS, "{lot_nearer} lot nodes nearer than {patch_m} m");
        let err = nav.plan(start, goal).unwrap_err();
        assert!(matches!(err, PlanError::Unmapped { which: "goal", .. }), "{err:?}");
    }
}
