//! Driving nodes for UGVs: `navigate_to` (global graph + local planner), `navigate_local`
//! (panoramas and odometry only) and `return_home`, over the runtime's navigation stack.
//!
//! One implementation serves all three (paper §Local Ground Planner and §Global Ground Planner):
//! - [`Driver`] is the local machinery. On every new panorama (the runtime's `nav.view` changes)
//!   it picks a local goal in the known-safe region with `select_local_goal` — the global goal
//!   (the target, or a look-ahead point on the global path) expressed in the robot frame at the
//!   panorama, the previous local goal carried over for the consistency term, randomness from
//!   `rt.rng`. On every tick it runs DWA with the robot's pose relative to the panorama taken
//!   from odometry (`view.odom_pose⁻¹ ⊕ odometry`), and writes `rt.command`. It also keeps the
//!   progress watchdog (no reduction of the remaining distance by [`PROGRESS_MARGIN_M`] within
//!   the stuck timeout → stuck).
//! - [`Navigator`] adds the global path: plans on the robot's `GlobalPlanner` (through
//!   `NavStack::plan`), feeds the driver a pure-pursuit waypoint on the path (the farthest point
//!   within the look-ahead, never moving back), replans when the path's edges are removed or
//!   their cost rises (checked at each new panorama, i.e. after each scan updated the graph) and
//!   every [`REPLAN_PERIOD_S`], and enforces the time limit. Replans start from the node the
//!   robot is heading to, so the edge being driven is kept and a re-attachment cannot jump past
//!   an obstacle. The global planner judges the edge under the robot from the robot's position
//!   (`experience.on_edge_radius_m`), so a block mid-edge is normally seen by the scans; should
//!   the robot still get stuck on an edge the scans could not judge, it records the edge as
//!   blocked on its `NavStack` (planned around with `GlobalPlanner::plan_avoiding`) and
//!   replans from the node behind. A target in territory the robot's map does not cover yet
//!   is approached over the graph to the reachable node nearest it, the rest driven locally
//!   (`NavStack::plan`). `navigate_to` and `return_home` are thin nodes over it;
//!   `navigate_local` is a thin node over the driver.
//!
//! Per tick the nodes allocate nothing: they read the runtime, run one DWA step (and a local
//! goal selection once per panorama); the global search runs only at start and on a replan.
//!
//! Node-level parameter blocks: `local_planner` may override `local_goal` and `dwa` (applied
//! over the robot's own local-planner parameters, to a copy the node owns); `terrain` is refused
//! because terrain analysis runs once per panorama for the whole robot (set it in the robot's
//! navigation parameters). `global_planner` may set `search` only (`replan_cost_rise_ratio`, used
//! by this node's replanning test); the graph, learning, experience and sharing belong to the
//! robot's one planner, shared by every node and fed by every scan, so they are refused too.

use serde_json::{Value, json};
use spomp_core::{Point2, Pose2, RobotKind, Time, Twist2};
use spomp_global_planner::{GlobalPath, NodeId, SearchParams};
use spomp_local_planner::{Dwa, LocalGoalParams, LocalPlannerParams, select_local_goal};

use super::Ctx;
use crate::runtime::{NavStack, RobotRuntime};
use crate::settings::WatchdogParams;
use spomp_behaviors::Status;
use spomp_behaviors::blackboard::{BbValue, Binding, PortType};
use spomp_behaviors::node::Behavior;
use spomp_behaviors::registry::{Category, NodeRegistry, NodeTypeSpec, PortBindings, PortSpec};

/// The remaining distance must drop by this much within the stuck timeout, metres.
pub const PROGRESS_MARGIN_M: f64 = 1.0;
/// `navigate_to` replans at least this often even when the path looks valid, seconds.
pub const REPLAN_PERIOD_S: f64 = 10.0;

/// A robot that stays within this distance of one point ...
pub const PINNED_RADIUS_M: f64 = 2.0;

/// ... for this many stuck timeouts is stuck, and backs out along its own trail.
pub const PINNED_TIMEOUTS: f64 = 2.0;
/// When stuck, the blocked edge is taken this far ahead of the robot along the path, metres.
const BLOCKAGE_PROBE_M: f64 = 2.0;
/// A robot this close to its look-ahead point may take one whose line is not clear of curbs.
const LOOKAHEAD_STALL_M: f64 = 2.0;
/// Half the width of the band along the look-ahead line that must be free of curbs, metres.
const CLEARANCE_HALF_WIDTH_M: f64 = 1.0;
/// How far beyond the last look-ahead point (plus the look-ahead) the path is searched, metres.
const PROJECTION_WINDOW_M: f64 = 20.0;

/// Registers the navigation nodes.
pub fn register_navigation(r: &mut NodeRegistry<RobotRuntime>) {
    use Category::Action;
    use PortType::{Float, Params, Point, String as Str};
    use RobotKind::Ugv;

    r.register(
        NodeTypeSpec::leaf(
            "navigate_to",
            Action,
            "Plans a path on the robot's traversability graph from its pose to `target`, follows it by giving the local planner the farthest path point within `lookahead_m` that the path reaches without leaving that circle and whose straight line (widened to 1 m either side at the point) crosses no curb the aerial map shows unless the path does (a path up a curb ramp is followed, not cut across the curb) (local goal per panorama, DWA at every tick), and replans when an edge of the path is removed or the path's cost rises after a reachability scan (checked at every panorama), and every 10 s; replans keep the edge being driven (they search from the node ahead, keeping the rest of an edge routed around a curb). When the remaining path length has not shrunk by 1 m for `stuck_timeout_s` on a graph edge, the robot marks that edge blocked for itself and replans from the node behind (a blockage the scans could not judge). A robot that stays within 2 m of one point for twice `stuck_timeout_s` is stuck too: it backs out along its own trail to the newest trail point from which the graph has a path (so does any plan from a place the graph has no path from, such as a node whose edges were all removed). Success within `tolerance_m`; Failure (reason in `failure_reason`) when there is no path (`no_path`, also when a blocked path has no alternative), when stuck with no edge to give up (`stuck`), or past the time limit (`time_limit`): `time_limit_s` if given, else `time_per_m_s` (unset: the mission's `goals.time_limit_per_m_s`) × the planned path length, counted from the start and extended by a replan forced by a blocked or costlier path to now + `time_per_m_s` × the new length. With no aerial map yet (empty graph) it drives toward the target with the local planner alone (time limit from the straight-line distance) and plans as soon as a graph exists. A target where the robot's map has no data yet (a goal another robot found in a map version that has not reached this one) is approached over the graph to the reachable node nearest it, then straight on with the local planner alone. Writes the robot's planned path and publishes its end on the team state; finishing or halting stops the robot and clears both.",
            vec![
                PortSpec::input("target", Point, "Where to go (map frame)."),
                PortSpec::input("tolerance_m", Float, "Arrival radius, metres.").with_default(json!(2.0)),
                PortSpec::optional("time_limit_s", Float, "Fixed time limit, seconds; overrides `time_per_m_s`."),
                PortSpec::optional("time_per_m_s", Float, "Time limit per metre of planned path, s/m; unset: the mission's `goals.time_limit_per_m_s`."),
                PortSpec::optional("stuck_timeout_s", Float, "Fail as stuck after this long without 1 m of progress along the path, seconds; unset: the robot's `navigation.watchdog.stuck_timeout_s` (30 s unless the mission says otherwise)."),
                PortSpec::input("lookahead_m", Float, "Distance ahead along the global path of the waypoint given to the local planner, metres.").with_default(json!(8.0)),
                PortSpec::optional("global_planner", Params, "Only `search: { replan_cost_rise_ratio }` (the robot's graph, learning and experience are shared by all nodes and set in its navigation parameters)."),
                PortSpec::optional("local_planner", Params, "Overrides of `local_goal` and `dwa` (spomp-local-planner) over the robot's parameters, for this node; `terrain` is the robot's."),
                PortSpec::output("failure_reason", Str, "Why it failed: no_path, stuck or time_limit (no_navigation: the robot has no navigation stack)."),
            ],
            |p| Ok(Box::new(NavigateTo::new(p)?)),
        )
        .for_kinds(&[Ugv])
        .using_skills(&["global_planner", "local_planner", "localization"]),
    );
    r.register(
        NodeTypeSpec::leaf(
            "navigate_local",
            Action,
            "Drives to `target` using only panoramas and odometry: on each panorama a local goal in the known-safe region closest to the target (with the consistency term), at every tick a DWA command toward it. The target is in the map frame, or with `frame: robot` relative to the robot's pose estimate when the node starts (x ahead, y to the left; fixed on the ground from then on, so \"10 m ahead\" stays where it was when the robot turns). Success within `tolerance_m`; Failure when the distance to the target did not shrink by 1 m for `stuck_timeout_s` (a blocked road, an empty safe region, no panoramas); halting stops the robot.",
            vec![
                PortSpec::input("target", Point, "Where to go, in `frame`."),
                PortSpec::input("frame", Str, "Frame of `target`: `map`, or `robot` (the robot's pose when the node starts).").with_default(json!("map")),
                PortSpec::input("tolerance_m", Float, "Arrival radius, metres.").with_default(json!(1.0)),
                PortSpec::optional("stuck_timeout_s", Float, "Give up after this long without progress, seconds; unset: the robot's `navigation.watchdog.stuck_timeout_s`."),
                PortSpec::optional("local_planner", Params, "Overrides of `local_goal` and `dwa` (spomp-local-planner) over the robot's parameters, for this node; `terrain` is the robot's."),
            ],
            |p| Ok(Box::new(NavigateLocal::new(p)?)),
        )
        .for_kinds(&[Ugv])
        .using_skills(&["local_planner"]),
    );
    r.register(
        NodeTypeSpec::leaf(
            "return_home",
            Action,
            "Drives back to the robot's start position like `navigate_to` (global path when there is a map, local planner alone otherwise; time limit from the mission's `goals.time_limit_per_m_s`) if it is farther than `min_distance_m`; succeeds there, or at once if already close.",
            vec![
                PortSpec::input("min_distance_m", Float, "Only move if farther than this from home, metres.").with_default(json!(5.0)),
                PortSpec::input("tolerance_m", Float, "Arrival radius, metres.").with_default(json!(2.0)),
                PortSpec::optional("stuck_timeout_s", Float, "Fail as stuck after this long without 1 m of progress, seconds; unset: the robot's `navigation.watchdog.stuck_timeout_s`."),
                PortSpec::output("failure_reason", Str, "Why it failed: no_path, stuck or time_limit."),
            ],
            |p| Ok(Box::new(ReturnHome::new(p)?)),
        )
        .for_kinds(&[Ugv])
        .using_skills(&["global_planner", "local_planner", "localization"]),
    );
}

// ---------------------------------------------------------------------------------------------
// Parameters

/// Node-level parameter overrides, checked when the node is built.
#[derive(Clone, Debug, Default)]
struct Overrides {
    /// `local_planner` block (object with `local_goal` and/or `dwa`).
    local: Option<Value>,
    /// `search` of the `global_planner` block.
    search: Option<SearchParams>,
}

impl Overrides {
    fn from_ports(p: &PortBindings, global: bool) -> Result<Self, String> {
        let mut o = Overrides::default();
        if let Some(v) = params_literal(p, "local_planner")? {
            let Some(obj) = v.as_object() else { return Err("`local_planner` must be a mapping".into()) };
            if obj.contains_key("terrain") {
                return Err("`local_planner.terrain` cannot be set per node: terrain analysis runs once per panorama for the whole robot; set it in the robot's navigation parameters".into());
            }
            serde_json::from_value::<LocalPlannerParams>(v.clone())
                .map_err(|e| format!("`local_planner`: {e}"))?
                .validate()
                .map_err(|e| format!("`local_planner`: {e}"))?;
            o.local = Some(v);
        }
        if global && let Some(v) = params_literal(p, "global_planner")? {
            let Some(obj) = v.as_object() else { return Err("`global_planner` must be a mapping".into()) };
            if let Some(k) = obj.keys().find(|k| k.as_str() != "search") {
                return Err(format!(
                    "`global_planner.{k}` cannot be set per node: the robot has one traversability graph, fed by every scan and shared by every node; set it in the robot's navigation parameters (only `search` is per node)"
                ));
            }
            if let Some(s) = obj.get("search") {
                let search: SearchParams =
                    serde_json::from_value(s.clone()).map_err(|e| format!("`global_planner.search`: {e}"))?;
                if !(search.replan_cost_rise_ratio.is_finite() && search.replan_cost_rise_ratio >= 0.0) {
                    return Err("`global_planner.search.replan_cost_rise_ratio` must be finite and >= 0".into());
                }
                o.search = Some(search);
            }
        }
        Ok(o)
    }
}

fn params_literal(p: &PortBindings, name: &str) -> Result<Option<Value>, String> {
    match p.literal(name) {
        None => match p.get(name) {
            Binding::Unset => Ok(None),
            _ => Err(format!("`{name}` must be written in the mission (a literal parameter block)")),
        },
        Some(BbValue::Params(v)) => Ok(Some((**v).clone())),
        Some(other) => Err(format!("`{name}` must be a mapping of parameters, not {:?}", other.port_type())),
    }
}

/// Merges `over` into `base` (objects field by field, anything else replaced).
fn merge(base: &mut Value, over: &Value) {
    match (base, over) {
        (Value::Object(b), Value::Object(o)) => {
            for (k, v) in o {
                match b.get_mut(k) {
                    Some(slot) => merge(slot, v),
                    None => {
                        b.insert(k.clone(), v.clone());
                    }
                }
            }
        }
        (b, o) => *b = o.clone(),
    }
}

/// What a driving node runs with: the robot's local-planner parameters with the node's
/// overrides, built once at the node's first start.
#[derive(Clone, Debug)]
struct Tuning {
    goal: LocalGoalParams,
    dwa: Dwa,
    replan_ratio: f64,
}

impl Tuning {
    fn build(nav: &NavStack, overrides: &Overrides) -> Result<Self, String> {
        let mut local = nav.params.local.clone();
        if let Some(over) = &overrides.local {
            let mut base = serde_json::to_value(&local).map_err(|e| e.to_string())?;
            merge(&mut base, over);
            local = serde_json::from_value(base).map_err(|e| format!("local_planner: {e}"))?;
            local.validate().map_err(|e| format!("local_planner: {e}"))?;
        }
        let dwa = Dwa::new(local.dwa.clone()).map_err(|e| format!("local_planner: {e}"))?;
        let replan_ratio = overrides
            .search
            .as_ref()
            .map_or(nav.params.global.search.replan_cost_rise_ratio, |s| s.replan_cost_rise_ratio)
            .max(0.0);
        Ok(Tuning { goal: local.local_goal, dwa, replan_ratio })
    }
}

// ---------------------------------------------------------------------------------------------
// The driving core

/// Why a drive ended badly.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Reason {
    NoPath,
    Stuck,
    TimeLimit,
    NoNavigation,
}

impl Reason {
    fn as_str(self) -> &'static str {
        match self {
            Reason::NoPath => "no_path",
            Reason::Stuck => "stuck",
            Reason::TimeLimit => "time_limit",
            Reason::NoNavigation => "no_navigation",
        }
    }
}

/// Outcome of one tick of a drive.
enum Step {
    Running,
    Arrived,
    Failed(Reason, String),
}

/// The local machinery shared by every driving node: local goal per panorama, DWA per tick,
/// progress watchdog.
struct Driver {
    overrides: Overrides,
    tuning: Option<Tuning>,
    /// Stamp of the panorama the local goal was chosen in.
    view_stamp: Option<Time>,
    /// Map-frame pose of that panorama.
    view_pose: Pose2,
    /// The local goal, in the robot frame at that panorama.
    local_goal: Option<Point2>,
    /// Smallest remaining distance seen, and when it last dropped by the margin.
    best_remaining: f64,
    best_at: Time,
    /// Where the robot was when it last got [`PINNED_RADIUS_M`] away from the previous such
    /// point, and when: a robot that stays near one point is stuck, whatever its route says.
    pinned_at: Option<Point2>,
    pinned_since: Time,
}

impl Driver {
    fn new(overrides: Overrides) -> Self {
        Driver {
            overrides,
            tuning: None,
            view_stamp: None,
            view_pose: Pose2::default(),
            local_goal: None,
            best_remaining: f64::INFINITY,
            best_at: Time::ZERO,
            pinned_at: None,
            pinned_since: Time::ZERO,
        }
    }

    /// Starts a drive: builds the tuning on first use, forgets the last drive.
    fn start(&mut self, rt: &RobotRuntime, now: Time) -> Result<(), String> {
        let Some(nav) = rt.nav() else {
            return Err("the robot has no navigation stack (not a UGV, or its runtime was set up without `nav`)".into());
        };
        if self.tuning.is_none() {
            self.tuning = Some(Tuning::build(nav, &self.overrides)?);
        }
        self.view_stamp = None;
        self.local_goal = None;
        self.best_remaining = f64::INFINITY;
        self.best_at = now;
        self.pinned_at = None;
        self.pinned_since = now;
        Ok(())
    }

    /// Feeds the watchdog the remaining distance and the robot's position; true when no
    /// progress was made for `timeout_s`, or the robot stayed within [`PINNED_RADIUS_M`] of one
    /// point for [`PINNED_TIMEOUTS`] of them (wiggling in a corner while replans keep changing
    /// the route, so that the remaining distance alone would not tell).
    fn stuck(&mut self, now: Time, here: Option<Point2>, remaining: f64, timeout_s: f64) -> bool {
        if remaining.is_finite()
            && (remaining < self.best_remaining - PROGRESS_MARGIN_M || !self.best_remaining.is_finite())
        {
            self.best_remaining = remaining;
            self.best_at = now;
        }
        now.secs_since(self.best_at) > timeout_s || self.pinned(now, here, timeout_s)
    }

    /// Whether the robot stayed near one point for [`PINNED_TIMEOUTS`] × `timeout_s`.
    fn pinned(&mut self, now: Time, here: Option<Point2>, timeout_s: f64) -> bool {
        if let Some(p) = here
            && self.pinned_at.is_none_or(|a| a.distance(p) > PINNED_RADIUS_M)
        {
            self.pinned_at = Some(p);
            self.pinned_since = now;
        }
        now.secs_since(self.pinned_since) > PINNED_TIMEOUTS * timeout_s
    }

    /// A fresh stuck window from now, measured against `remaining` (a new route after being
    /// stuck on the old one).
    fn restart_watchdog(&mut self, now: Time, remaining: f64) {
        self.best_remaining = if remaining.is_finite() { remaining } else { f64::INFINITY };
        self.best_at = now;
        self.pinned_since = now;
    }

    /// Lets the watchdog measure against a new remaining distance (after a replan changed the
    /// route) without granting extra time.
    fn rebase(&mut self, remaining: f64) {
        if remaining.is_finite() {
            self.best_remaining = remaining;
        }
    }

    /// One control step toward `goal` (map frame): a new local goal if a new panorama arrived,
    /// then DWA. Writes `rt.command` (zero without a view or a local goal).
    fn drive(&mut self, rt: &mut RobotRuntime, goal: Point2) {
        let Some(tuning) = self.tuning.as_mut() else {
            rt.command_velocity(Twist2::ZERO);
            return;
        };
        let odometry = rt.odometry();
        let Some((view, rng)) = rt.nav_and_rng().and_then(|(n, rng)| Some((n.view.as_ref()?, rng))) else {
            rt.command_velocity(Twist2::ZERO);
            return;
        };
        if self.view_stamp != Some(view.stamp) {
            let at = view.pose.pose;
            let target = at.inverse_transform_point(goal);
            let previous = self.local_goal.map(|g| at.inverse_transform_point(self.view_pose.transform_point(g)));
            self.local_goal = select_local_goal(&view.region, target, previous, &tuning.goal, rng);
            self.view_stamp = Some(view.stamp);
            self.view_pose = at;
        }
        let Some(local_goal) = self.local_goal else {
            rt.command_velocity(Twist2::ZERO);
            return;
        };
        let (robot, current) = match odometry {
            Some(odom) => (view.odom_pose.between(odom.pose), odom.twist),
            None => (Pose2::default(), Twist2::ZERO),
        };
        let cmd = tuning.dwa.step_in_region(current, robot, local_goal, &view.region);
        rt.command_velocity(cmd);
    }
}

/// A global path prepared for following: cumulative lengths and the robot's progress on it.
struct Route {
    /// The planner's path (`None`: local-only, the straight line to the target).
    path: Option<GlobalPath>,
    points: Vec<Point2>,
    cumulative: Vec<f64>,
    /// Segment of the last look-ahead point.
    segment: usize,
    /// Arc length of the last look-ahead point.
    reached: f64,
}

impl Route {
    fn new(path: Option<GlobalPath>, from: Point2, target: Point2) -> Self {
        let mut points = match &path {
            Some(p) => p.waypoints.clone(),
            None => vec![from, target],
        };
        if points.is_empty() {
            points = vec![from, target];
        }
        let mut cumulative = Vec::with_capacity(points.len());
        let mut total = 0.0;
        cumulative.push(0.0);
        for w in points.windows(2) {
            total += w[0].distance(w[1]);
            cumulative.push(total);
        }
        Route { path, points, cumulative, segment: 0, reached: 0.0 }
    }

    fn length(&self) -> f64 {
        self.cumulative.last().copied().unwrap_or(0.0)
    }

    /// Pure pursuit: the farthest point along the path (never behind the last one, searched
    /// within [`PROJECTION_WINDOW_M`] beyond it) that lies within `lookahead_m` of `p` without
    /// the path leaving that circle on the way there, and that the straight line from `p`
    /// reaches across no step unless the path to it crosses one too (`steps(a, b, half_width)`:
    /// the aerial map shows a curb within `half_width` of the line a–b; the line from `p` must
    /// be clear to [`CLEARANCE_HALF_WIDTH_M`] either side of the point; with none such, the
    /// last look-ahead point again, or when the robot is within [`LOOKAHEAD_STALL_M`] of it, a
    /// point clear along the centre line, failing that the farthest). So a path that folds back from a curb
    /// ramp is not cut short across the curb beside it, and the robot meets the ramp head-on
    /// rather than past the curb's corner. Returns that point and the
    /// remaining distance through it (path left after it plus the straight line to it). When no
    /// point of the path is that close (the robot strayed), the last look-ahead point again.
    fn pursue(&mut self, p: Point2, lookahead_m: f64, steps: impl Fn(Point2, Point2, f64) -> bool) -> (Point2, f64) {
        let n = self.points.len();
        if n < 2 {
            let q = self.points.first().copied().unwrap_or(p);
            return (q, q.distance(p));
        }
        let l2 = lookahead_m * lookahead_m;
        let horizon = self.reached + lookahead_m + PROJECTION_WINDOW_M;
        let mut best: Option<(usize, f64)> = None;
        // The farthest point whose line from `p` is only clear along its centre, and the
        // farthest at all: used when no point has a clear wedge (a robot squeezed beside a curb).
        let mut fallback: [Option<(usize, f64)>; 2] = [None, None];
        // Whether the path itself crosses a step up to the segment being looked at (then a
        // line across it is no worse than the plan, such as a roadblock's the scans must judge).
        let mut path_steps = false;
        for i in self.segment.min(n - 2)..n - 1 {
            if self.cumulative[i] > horizon {
                break;
            }
            let (a, b) = (self.points[i], self.points[i + 1]);
            let d = b - a;
            let f = a - p;
            let dd = d.dot(d);
            let t = if dd <= 1e-12 {
                if f.dot(f) <= l2 { Some(1.0) } else { None }
            } else {
                let fd = f.dot(d);
                let disc = fd * fd - dd * (f.dot(f) - l2);
                if disc < 0.0 {
                    None
                } else {
                    let root = disc.sqrt();
                    let (near, far) = ((-fd - root) / dd, (-fd + root) / dd);
                    (near.max(0.0) <= far.min(1.0)).then_some(far.min(1.0))
                }
            };
            match t {
                Some(t) => {
                    let s = self.cumulative[i] + t * (self.cumulative[i + 1] - self.cumulative[i]);
                    let (a, b) = (self.points[i], self.points[i + 1]);
                    let q = a + (b - a) * t;
                    let planned_step = path_steps || steps(a, q, 0.0);
                    if s >= self.reached {
                        fallback[1] = Some((i, s));
                        if planned_step || !steps(p, q, 0.0) {
                            fallback[0] = Some((i, s));
                        }
                        if planned_step || !steps(p, q, CLEARANCE_HALF_WIDTH_M) {
                            best = Some((i, s));
                        }
                    }
                    path_steps |= t >= 1.0 && planned_step;
                    // The path leaves the circle here: where it comes back in later (a path
                    // that folds back, to a curb ramp and back along the sidewalk) is beyond a
                    // stretch the robot has not driven, so the look-ahead never jumps there.
                    if t < 1.0 && fallback[1].is_some() {
                        break;
                    }
                }
                None if fallback[1].is_some() => break,
                None => {}
            }
        }
        // Without a point whose wedge is clear, the look-ahead stays where it was while the
        // robot still has a way to go to it (it is heading for the foot of a ramp); only a robot
        // that reached it takes a point clear along the centre line, then any point, rather
        // than stall (squeezed beside a wall).
        let stalled = self.point_at(self.reached).distance(p) < LOOKAHEAD_STALL_M;
        let chosen = best.or(if stalled { fallback[0].or(fallback[1]) } else { None });
        if let Some((i, s)) = chosen {
            self.segment = i;
            self.reached = s;
        }
        let q = self.point_at(self.reached);
        (q, (self.length() - self.reached).max(0.0) + q.distance(p))
    }

    /// The graph nodes at the two ends of the path segment at arc length `s`: the node behind
    /// (`None` on the first segment, which starts at the robot) and ahead (`None` on the last,
    /// which ends at the target), both `None` without a graph path and on the lead-in (the
    /// robot's own trail back to where the graph path starts).
    fn nodes_around(&self, s: f64) -> (Option<NodeId>, Option<NodeId>) {
        let Some(path) = self.path.as_ref() else { return (None, None) };
        let last = self.points.len().saturating_sub(2);
        let i = self.cumulative.partition_point(|&c| c <= s).saturating_sub(1).min(last);
        if i < path.lead_in {
            return (None, None);
        }
        // Segment i joins waypoints i and i + 1: the nodes around it are the last node at or
        // before waypoint i and the first at or after waypoint i + 1 (an edge routed around a
        // curb has waypoints of its own between its nodes).
        let k = path.node_waypoints.partition_point(|&w| w <= i);
        let behind = k.checked_sub(1).and_then(|k| path.nodes.get(k).copied());
        (behind, path.nodes.get(k).copied())
    }

    /// The look-ahead point and the waypoints after it up to (not including) the first
    /// waypoint of `node` from there on: the rest of the way to that node, which a replan from
    /// the node keeps. Empty when `node` is not ahead on the path or is the next waypoint.
    fn points_before(&self, node: Option<NodeId>) -> Vec<Point2> {
        let (Some(node), Some(path)) = (node, self.path.as_ref()) else { return Vec::new() };
        let first_ahead = self.segment + 1;
        let Some(w) = path
            .nodes
            .iter()
            .zip(&path.node_waypoints)
            .find(|&(&n, &w)| n == node && w >= first_ahead)
            .map(|(_, &w)| w)
        else {
            return Vec::new();
        };
        if w <= first_ahead {
            // A straight edge: the node is the next waypoint anyway.
            return Vec::new();
        }
        let mut lead = vec![self.point_at(self.reached)];
        lead.extend_from_slice(&self.points[first_ahead..w.min(self.points.len())]);
        lead
    }

    /// The point at arc length `s` (clamped to the path), from the current segment on.
    fn point_at(&self, s: f64) -> Point2 {
        let n = self.points.len();
        if n < 2 {
            return self.points.first().copied().unwrap_or_default();
        }
        let mut i = self.segment.min(n - 2);
        while i + 2 < n && self.cumulative[i + 1] < s {
            i += 1;
        }
        let len = self.cumulative[i + 1] - self.cumulative[i];
        let t = if len > 1e-12 { ((s - self.cumulative[i]) / len).clamp(0.0, 1.0) } else { 1.0 };
        let (a, b) = (self.points[i], self.points[i + 1]);
        a + (b - a) * t
    }
}

/// How the time limit is set.
#[derive(Clone, Copy, Debug)]
enum Limit {
    /// Fixed, seconds from the start.
    Fixed(f64),
    /// Seconds per metre of planned path.
    PerMetre(f64),
}

/// The global layer over [`Driver`]: plan, follow with a look-ahead waypoint, replan, time limit.
struct Navigator {
    driver: Driver,
    route: Option<Route>,
    started: Time,
    deadline_s: f64,
    next_replan: Time,
    /// Panorama stamp at which the path was last checked.
    checked_view: Option<Time>,
    /// Graph node at the start of the edge the robot is on.
    behind: Option<NodeId>,
    /// Graph node the robot is heading to (`None` on the last stretch to the target).
    ahead: Option<NodeId>,
}

/// What a navigation run asks for.
#[derive(Clone, Copy, Debug)]
struct Request {
    target: Point2,
    tolerance_m: f64,
    limit: Limit,
    stuck_timeout_s: f64,
    lookahead_m: f64,
}

/// Why a (re)plan was triggered.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Trigger {
    Start,
    Changed,
    Periodic,
}

impl Navigator {
    fn new(overrides: Overrides) -> Self {
        Navigator {
            driver: Driver::new(overrides),
            route: None,
            started: Time::ZERO,
            deadline_s: f64::INFINITY,
            next_replan: Time::ZERO,
            checked_view: None,
            behind: None,
            ahead: None,
        }
    }

    fn has_graph(rt: &RobotRuntime) -> bool {
        rt.nav().is_some_and(NavStack::has_graph)
    }

    /// Plans from `from`; `Ok(None)` when the robot has no graph yet (local-only driving).
    fn plan(rt: &mut RobotRuntime, from: Point2, to: Point2) -> Result<Option<GlobalPath>, String> {
        if !Self::has_graph(rt) {
            return Ok(None);
        }
        let Some(nav) = rt.nav_mut() else { return Ok(None) };
        nav.plan(from, to).map(Some).map_err(|e| e.to_string())
    }

    /// Takes a new route and publishes it.
    fn adopt(&mut self, rt: &mut RobotRuntime, route: Route, now: Time, trigger: Trigger, req: &Request) {
        let length = route.length();
        match (trigger, req.limit) {
            (Trigger::Start, Limit::Fixed(s)) => self.deadline_s = s,
            (Trigger::Start, Limit::PerMetre(k)) => self.deadline_s = k * length,
            (Trigger::Changed, Limit::PerMetre(k)) => {
                self.deadline_s = self.deadline_s.max(now.secs_since(self.started) + k * length);
            }
            _ => {}
        }
        let end = route.points.last().copied();
        rt.publish_path(route.points.clone(), end);
        self.route = Some(route);
        self.next_replan = now + std::time::Duration::from_secs_f64(REPLAN_PERIOD_S);
    }

    /// Clears the published path.
    fn clear(rt: &mut RobotRuntime) {
        rt.clear_path();
    }

    /// Ends the drive: stop, clear the path.
    fn finish(&mut self, rt: &mut RobotRuntime) {
        rt.command_velocity(Twist2::ZERO);
        Self::clear(rt);
        self.route = None;
    }

    fn start(&mut self, rt: &mut RobotRuntime, now: Time, req: &Request) -> Result<(), (Reason, String)> {
        self.driver.start(rt, now).map_err(|e| (Reason::NoNavigation, e))?;
        self.started = now;
        self.deadline_s = f64::INFINITY;
        self.checked_view = None;
        self.route = None;
        self.behind = None;
        self.ahead = None;
        let from = rt.pose().map_or(rt.start().position(), |p| p.pose.position());
        let path = Self::plan(rt, from, req.target).map_err(|e| (Reason::NoPath, format!("no path: {e}")))?;
        self.adopt(rt, Route::new(path, from, req.target), now, Trigger::Start, req);
        Ok(())
    }

    /// A route from `here` that starts with the graph search from `origin` (a node position)
    /// or, with none, from `here` itself. `lead` are the points to pass between `here` and
    /// `origin`: the rest of the edge being driven when it is routed around a curb.
    fn route_from(
        rt: &mut RobotRuntime,
        here: Point2,
        origin: Option<Point2>,
        lead: &[Point2],
        target: Point2,
    ) -> Result<Route, String> {
        let Some(p) = origin else {
            return Self::plan(rt, here, target).map(|path| Route::new(path, here, target));
        };
        match Self::plan(rt, p, target)? {
            Some(mut path) => {
                if let Some(first) = path.waypoints.first_mut() {
                    *first = here;
                }
                if !lead.is_empty() {
                    path.waypoints.splice(1..1, lead.iter().copied());
                    for k in &mut path.node_waypoints {
                        *k += lead.len();
                    }
                }
                path.length_m = path.waypoints.windows(2).map(|w| w[0].distance(w[1])).sum();
                Ok(Route::new(Some(path), here, target))
            }
            None => Ok(Route::new(None, here, target)),
        }
    }

    /// A route that first backs out along the robot's trail ([`NavStack::plan_backtracking`]).
    fn backtrack_route(rt: &mut RobotRuntime, here: Point2, target: Point2) -> Option<Route> {
        let nav = rt.nav_mut()?;
        nav.note_stuck_at(here);
        let path = nav.plan_backtracking(here, target).ok()?;
        Some(Route::new(Some(path), here, target))
    }

    fn node_position(rt: &RobotRuntime, node: Option<NodeId>) -> Option<Point2> {
        let node = node?;
        rt.nav()?.global.nodes().find(|(id, _, _)| *id == node).map(|(_, p, _)| p)
    }

    /// Replans keeping the robot's commitment: from the node it is heading to (the current
    /// edge stays), or — when the current edge is what failed (`avoid_current`) — from the node
    /// it came from; from its own position when neither applies or works.
    fn replan(
        &mut self,
        rt: &mut RobotRuntime,
        here: Point2,
        target: Point2,
        avoid_current: bool,
    ) -> Result<Route, String> {
        let mut origins: Vec<(Option<Point2>, Vec<Point2>)> = Vec::with_capacity(3);
        if !avoid_current && let Some(p) = Self::node_position(rt, self.ahead) {
            let lead = self.route.as_ref().map(|r| r.points_before(self.ahead)).unwrap_or_default();
            origins.push((Some(p), lead));
        }
        if let Some(p) = Self::node_position(rt, self.behind) {
            origins.push((Some(p), Vec::new()));
        }
        if !avoid_current || origins.is_empty() {
            origins.push((None, Vec::new()));
        }
        let mut last = Err("no origin to plan from".to_string());
        for (origin, lead) in origins {
            last = Self::route_from(rt, here, origin, &lead, target);
            if last.is_ok() {
                break;
            }
        }
        last
    }

    /// Checks the path after new information; replans when needed.
    fn maybe_replan(&mut self, rt: &mut RobotRuntime, now: Time, here: Point2, req: &Request) -> Result<(), String> {
        let stamp = rt.nav().and_then(|n| n.view.as_ref()).map(|v| v.stamp);
        let new_view = stamp.is_some() && stamp != self.checked_view;
        self.checked_view = stamp;
        let Some(route) = &self.route else { return Ok(()) };
        let ratio = self.driver.tuning.as_ref().map_or(0.2, |t| t.replan_ratio);
        let (trigger, current_edge_gone) = match (&route.path, rt.nav()) {
            (_, None) => return Ok(()),
            // Local-only so far: plan as soon as a map gives a graph.
            (None, Some(nav)) => {
                if new_view && nav.has_graph() {
                    (Trigger::Changed, false)
                } else {
                    return Ok(());
                }
            }
            // On the last stretch to the target: nothing left to replan.
            (Some(_), Some(_)) if self.ahead.is_none() => return Ok(()),
            (Some(path), Some(nav)) => {
                let changed = new_view
                    && match nav.global.path_graph_cost(path) {
                        None => true,
                        Some(cost) => cost > path.graph_cost * (1.0 + ratio) + 1e-9,
                    };
                let gone = match (self.behind, self.ahead) {
                    (Some(a), Some(b)) => nav.global.edge_between(a, b).is_none(),
                    _ => false,
                };
                // The edge being driven can go while the path's graph cost does not change (its
                // first leg, robot → node ahead, is no graph edge): that is a change too.
                if changed || gone {
                    (Trigger::Changed, gone)
                } else if now >= self.next_replan {
                    (Trigger::Periodic, false)
                } else {
                    return Ok(());
                }
            }
        };
        match self.replan(rt, here, req.target, current_edge_gone) {
            Ok(route) => {
                let remaining = route.length();
                self.adopt(rt, route, now, trigger, req);
                self.driver.rebase(remaining);
                Ok(())
            }
            // A periodic replan that fails keeps the current path (e.g. the robot is momentarily
            // off the graph); a blocked path with no alternative is a failure.
            Err(e) if trigger == Trigger::Changed => Err(e),
            Err(_) => {
                self.next_replan = now + std::time::Duration::from_secs_f64(REPLAN_PERIOD_S);
                Ok(())
            }
        }
    }

    fn tick(&mut self, rt: &mut RobotRuntime, now: Time, req: &Request) -> Step {
        let Some(pose) = rt.pose() else {
            rt.command_velocity(Twist2::ZERO);
            if self.driver.stuck(now, None, f64::INFINITY, req.stuck_timeout_s) {
                return Step::Failed(Reason::Stuck, "the robot has had no pose estimate".into());
            }
            return Step::Running;
        };
        let here = pose.pose.position();
        if here.distance(req.target) <= req.tolerance_m {
            return Step::Arrived;
        }
        if let Err(e) = self.maybe_replan(rt, now, here, req) {
            return Step::Failed(Reason::NoPath, format!("path blocked and no other path: {e}"));
        }
        if now.secs_since(self.started) > self.deadline_s {
            return Step::Failed(Reason::TimeLimit, format!("time limit of {:.0} s reached", self.deadline_s));
        }
        let Some(route) = self.route.as_mut() else {
            return Step::Failed(Reason::NoPath, "no route".into());
        };
        let global = rt.nav().map(|n| &n.global);
        // Whether the aerial map shows a step on the lines from `a` to `b` and to the points
        // `half_width_m` either side of `b` (a wedge: what lies right beside the robot, such
        // as a wall it drives along, does not count).
        let steps = |a: Point2, b: Point2, half_width_m: f64| {
            global.is_some_and(|g| {
                let d = b - a;
                let len = d.norm();
                let side = if len > 1e-9 { Point2::new(-d.y / len, d.x / len) * half_width_m } else { d * 0.0 };
                [Point2::new(0.0, 0.0), side, side * -1.0].iter().any(|&o| g.crosses_step(a, b + o))
            })
        };
        let (waypoint, remaining) = route.pursue(here, req.lookahead_m, steps);
        // The graph edge the robot is on: its nodes behind and ahead (kept across a replan that
        // re-attached the robot to the node it was heading to).
        let probe = (route.reached - waypoint.distance(here) + BLOCKAGE_PROBE_M).max(0.0);
        let (behind, ahead) = route.nodes_around(probe);
        if behind.is_some() || ahead != self.ahead {
            self.behind = behind;
        }
        self.ahead = ahead;
        if self.driver.stuck(now, Some(here), remaining, req.stuck_timeout_s) {
            let pinned = self.driver.pinned(now, Some(here), req.stuck_timeout_s);
            if let Some(nav) = rt.nav_mut()
                && let (Some(a), Some(b)) = (self.behind, self.ahead)
            {
                nav.block_edge(a, b);
            }
            // Pinned in one place (a corner of a parking lot whose edges cross curbs): back out
            // the way the robot came and plan on from there.
            if pinned && let Some(route) = Self::backtrack_route(rt, here, req.target) {
                let remaining = route.length();
                self.adopt(rt, route, now, Trigger::Changed, req);
                self.driver.restart_watchdog(now, remaining);
                return Step::Running;
            }
            // Stuck on a graph edge the scans could not judge (e.g. a blockage seen from too far
            // for the edge's nodes to be in the safe region): remember the edge as blocked and
            // take another route from the node behind; fail when there is none, or when stuck
            // with no node behind.
            let (Some(_), Some(_)) = (self.behind, self.ahead) else {
                return Step::Failed(
                    Reason::Stuck,
                    format!("no progress for {:.0} s ({remaining:.1} m of path left)", req.stuck_timeout_s),
                );
            };
            return match self.replan(rt, here, req.target, true) {
                Ok(route) => {
                    let remaining = route.length();
                    self.adopt(rt, route, now, Trigger::Changed, req);
                    self.driver.restart_watchdog(now, remaining);
                    Step::Running
                }
                Err(e) => Step::Failed(
                    Reason::NoPath,
                    format!("stuck for {:.0} s on the path, and no other path: {e}", req.stuck_timeout_s),
                ),
            };
        }
        self.driver.drive(rt, waypoint);
        Step::Running
    }
}

// ---------------------------------------------------------------------------------------------
// Nodes

/// A positive finite number from a port (its declared default when unset), or a report.
/// The robot's own stuck timeout (`navigation.watchdog`), for nodes that do not set one.
fn robot_stuck_timeout_s(rt: &RobotRuntime) -> f64 {
    rt.nav().map_or_else(|| WatchdogParams::default().stuck_timeout_s, |n| n.params.watchdog.stuck_timeout_s)
}

fn number(binding: &Binding, ctx: &mut Ctx<'_>, node: &str, port: &str, default: f64) -> Option<f64> {
    let v = match binding {
        Binding::Unset => default,
        b => match b.get::<f64>(ctx.blackboard) {
            Some(v) => v,
            None => {
                ctx.blackboard.report(format!("{node}: `{port}` is not set"));
                return None;
            }
        },
    };
    if v.is_finite() && v >= 0.0 {
        Some(v)
    } else {
        ctx.blackboard.report(format!("{node}: `{port}` must be a finite non-negative number, got {v}"));
        None
    }
}

fn target_of(binding: &Binding, ctx: &mut Ctx<'_>, node: &str) -> Option<Point2> {
    match binding.get::<Point2>(ctx.blackboard) {
        Some(p) if p.x.is_finite() && p.y.is_finite() => Some(p),
        Some(p) => {
            ctx.blackboard.report(format!("{node}: `target` is not finite: {p:?}"));
            None
        }
        None => {
            ctx.blackboard.report(format!("{node}: no point on its `target` port"));
            None
        }
    }
}

/// One tick of a global navigation (shared by `navigate_to` and `return_home`).
#[allow(clippy::too_many_arguments)]
fn run_navigation(
    nav: &mut Navigator,
    prev: Status,
    rt: &mut RobotRuntime,
    bb: &mut spomp_behaviors::Blackboard,
    now: Time,
    req: &Request,
    node: &str,
    failure_reason: &Binding,
) -> Status {
    let fail = |nav: &mut Navigator,
                rt: &mut RobotRuntime,
                bb: &mut spomp_behaviors::Blackboard,
                reason: Reason,
                msg: String| {
        nav.finish(rt);
        bb.report(format!("{node}: {msg}"));
        failure_reason.set(bb, BbValue::Str(reason.as_str().into()));
        Status::Failure
    };
    if prev != Status::Running {
        if rt.pose().is_some_and(|p| p.pose.position().distance(req.target) <= req.tolerance_m) {
            nav.finish(rt);
            return Status::Success;
        }
        if let Err((reason, msg)) = nav.start(rt, now, req) {
            return fail(nav, rt, bb, reason, msg);
        }
    }
    match nav.tick(rt, now, req) {
        Step::Running => Status::Running,
        Step::Arrived => {
            nav.finish(rt);
            Status::Success
        }
        Step::Failed(reason, msg) => fail(nav, rt, bb, reason, msg),
    }
}

struct NavigateTo {
    target: Binding,
    tolerance: Binding,
    time_limit: Binding,
    time_per_m: Binding,
    stuck_timeout: Binding,
    lookahead: Binding,
    failure_reason: Binding,
    nav: Navigator,
}

impl NavigateTo {
    fn new(p: &PortBindings) -> Result<Self, String> {
        Ok(NavigateTo {
            target: p.get("target"),
            tolerance: p.get("tolerance_m"),
            time_limit: p.get("time_limit_s"),
            time_per_m: p.get("time_per_m_s"),
            stuck_timeout: p.get("stuck_timeout_s"),
            lookahead: p.get("lookahead_m"),
            failure_reason: p.get("failure_reason"),
            nav: Navigator::new(Overrides::from_ports(p, true)?),
        })
    }
}

impl Behavior<RobotRuntime> for NavigateTo {
    fn tick(&mut self, prev: Status, ctx: &mut Ctx<'_>) -> Status {
        const NODE: &str = "navigate_to";
        let now = ctx.now;
        let Some(target) = target_of(&self.target, ctx, NODE) else { return Status::Failure };
        let (Some(tolerance_m), Some(stuck_timeout_s), Some(lookahead_m)) = (
            number(&self.tolerance, ctx, NODE, "tolerance_m", 2.0),
            number(&self.stuck_timeout, ctx, NODE, "stuck_timeout_s", robot_stuck_timeout_s(ctx.env)),
            number(&self.lookahead, ctx, NODE, "lookahead_m", 8.0),
        ) else {
            return Status::Failure;
        };
        let fixed = match self.time_limit {
            Binding::Unset => None,
            _ => match number(&self.time_limit, ctx, NODE, "time_limit_s", 0.0) {
                Some(v) => Some(v),
                None => return Status::Failure,
            },
        };
        let per_m = match self.time_per_m {
            Binding::Unset => None,
            _ => match number(&self.time_per_m, ctx, NODE, "time_per_m_s", 0.0) {
                Some(v) => Some(v),
                None => return Status::Failure,
            },
        };
        let (rt, bb) = (&mut *ctx.env, &mut *ctx.blackboard);
        let limit = match (fixed, per_m) {
            (Some(s), _) => Limit::Fixed(s),
            (None, Some(k)) => Limit::PerMetre(k),
            (None, None) => Limit::PerMetre(rt.goal_time_per_m_s()),
        };
        let req = Request { target, tolerance_m, limit, stuck_timeout_s, lookahead_m };
        run_navigation(&mut self.nav, prev, rt, bb, now, &req, NODE, &self.failure_reason)
    }

    fn halt(&mut self, ctx: &mut Ctx<'_>) {
        {
            let rt = &mut *ctx.env;
            self.nav.finish(rt);
        }
    }
}

struct ReturnHome {
    min_distance: Binding,
    tolerance: Binding,
    stuck_timeout: Binding,
    failure_reason: Binding,
    nav: Navigator,
}

impl ReturnHome {
    fn new(p: &PortBindings) -> Result<Self, String> {
        Ok(ReturnHome {
            min_distance: p.get("min_distance_m"),
            tolerance: p.get("tolerance_m"),
            stuck_timeout: p.get("stuck_timeout_s"),
            failure_reason: p.get("failure_reason"),
            nav: Navigator::new(Overrides::default()),
        })
    }
}

impl Behavior<RobotRuntime> for ReturnHome {
    fn tick(&mut self, prev: Status, ctx: &mut Ctx<'_>) -> Status {
        const NODE: &str = "return_home";
        let now = ctx.now;
        let (Some(min_distance_m), Some(tolerance_m), Some(stuck_timeout_s)) = (
            number(&self.min_distance, ctx, NODE, "min_distance_m", 5.0),
            number(&self.tolerance, ctx, NODE, "tolerance_m", 2.0),
            number(&self.stuck_timeout, ctx, NODE, "stuck_timeout_s", robot_stuck_timeout_s(ctx.env)),
        ) else {
            return Status::Failure;
        };
        let (rt, bb) = (&mut *ctx.env, &mut *ctx.blackboard);
        let home = rt.start().position();
        // Without a pose estimate the robot cannot know it is home: it waits for one (and fails as
        // stuck if none comes) like any drive.
        let here = rt.pose().map(|p| p.pose.position());
        if prev != Status::Running && here.is_some_and(|h| h.distance(home) <= min_distance_m) {
            return Status::Success;
        }
        let req = Request {
            target: home,
            tolerance_m,
            limit: Limit::PerMetre(rt.goal_time_per_m_s()),
            stuck_timeout_s,
            lookahead_m: 8.0,
        };
        run_navigation(&mut self.nav, prev, rt, bb, now, &req, NODE, &self.failure_reason)
    }

    fn halt(&mut self, ctx: &mut Ctx<'_>) {
        {
            let rt = &mut *ctx.env;
            self.nav.finish(rt);
        }
    }
}

/// The frame of `navigate_local`'s target.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum TargetFrame {
    Map,
    /// Relative to the robot's pose when the node starts.
    Robot,
}

impl TargetFrame {
    fn parse(name: &str) -> Result<Self, String> {
        match name {
            "map" => Ok(TargetFrame::Map),
            "robot" => Ok(TargetFrame::Robot),
            other => Err(format!("`frame` must be `map` or `robot`, not `{other}`")),
        }
    }
}

struct NavigateLocal {
    target: Binding,
    frame: Binding,
    tolerance: Binding,
    stuck_timeout: Binding,
    driver: Driver,
    /// A robot-frame target in the map frame, fixed at the first pose of this run.
    anchored: Option<Point2>,
}

impl NavigateLocal {
    fn new(p: &PortBindings) -> Result<Self, String> {
        // A literal frame is checked when the mission is loaded; a blackboard one when ticked.
        if let Some(BbValue::Str(name)) = p.literal("frame") {
            TargetFrame::parse(name)?;
        }
        Ok(NavigateLocal {
            target: p.get("target"),
            frame: p.get("frame"),
            tolerance: p.get("tolerance_m"),
            stuck_timeout: p.get("stuck_timeout_s"),
            driver: Driver::new(Overrides::from_ports(p, false)?),
            anchored: None,
        })
    }

    /// The frame on the `frame` port (`map` when unset), or a report.
    fn frame(&self, ctx: &mut Ctx<'_>, node: &str) -> Option<TargetFrame> {
        let Some(name) = self.frame.get::<std::sync::Arc<str>>(ctx.blackboard) else { return Some(TargetFrame::Map) };
        TargetFrame::parse(&name).map_err(|e| ctx.blackboard.report(format!("{node}: {e}"))).ok()
    }
}

impl Behavior<RobotRuntime> for NavigateLocal {
    fn tick(&mut self, prev: Status, ctx: &mut Ctx<'_>) -> Status {
        const NODE: &str = "navigate_local";
        let now = ctx.now;
        let Some(target) = target_of(&self.target, ctx, NODE) else { return Status::Failure };
        let Some(frame) = self.frame(ctx, NODE) else { return Status::Failure };
        let (Some(tolerance_m), Some(stuck_timeout_s)) = (
            number(&self.tolerance, ctx, NODE, "tolerance_m", 1.0),
            number(&self.stuck_timeout, ctx, NODE, "stuck_timeout_s", robot_stuck_timeout_s(ctx.env)),
        ) else {
            return Status::Failure;
        };
        let (rt, bb) = (&mut *ctx.env, &mut *ctx.blackboard);
        if prev != Status::Running {
            self.anchored = None;
            if let Err(e) = self.driver.start(rt, now) {
                rt.command_velocity(Twist2::ZERO);
                bb.report(format!("{NODE}: {e}"));
                return Status::Failure;
            }
        }
        // Without a pose estimate yet the target is not used below (the robot waits).
        let target = match frame {
            TargetFrame::Map => target,
            TargetFrame::Robot => match (self.anchored, rt.pose()) {
                (Some(anchored), _) => anchored,
                (None, Some(pose)) => *self.anchored.insert(pose.pose.transform_point(target)),
                (None, None) => target,
            },
        };
        let remaining = rt.pose().map_or(f64::INFINITY, |p| p.pose.position().distance(target));
        if remaining <= tolerance_m {
            rt.command_velocity(Twist2::ZERO);
            return Status::Success;
        }
        let here = rt.pose().map(|p| p.pose.position());
        if self.driver.stuck(now, here, remaining, stuck_timeout_s) {
            rt.command_velocity(Twist2::ZERO);
            let why = if rt.pose().is_none() {
                "the robot has no pose estimate".to_string()
            } else {
                format!("no safe progress for {stuck_timeout_s:.0} s ({remaining:.1} m from the target)")
            };
            bb.report(format!("{NODE}: {why}"));
            return Status::Failure;
        }
        if rt.pose().is_none() {
            rt.command_velocity(Twist2::ZERO);
            return Status::Running;
        }
        self.driver.drive(rt, target);
        Status::Running
    }

    fn halt(&mut self, ctx: &mut Ctx<'_>) {
        {
            let rt = &mut *ctx.env;
            rt.command_velocity(Twist2::ZERO);
        }
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]

    use std::sync::Arc;

    use super::*;

    /// No curbs anywhere.
    fn open(_: Point2, _: Point2, _: f64) -> bool {
        false
    }

    fn path(points: &[(f64, f64)]) -> GlobalPath {
        let waypoints: Vec<Point2> = points.iter().map(|&(x, y)| Point2::new(x, y)).collect();
        let inner = waypoints.len().saturating_sub(2);
        GlobalPath {
            length_m: waypoints.windows(2).map(|w| w[0].distance(w[1])).sum(),
            waypoints,
            cost: 0.0,
            edges: Vec::new(),
            nodes: (0..inner as u32).map(|i| NodeId(10 + i)).collect(),
            node_waypoints: (1..=inner).collect(),
            graph_cost: 0.0,
            lead_in: 0,
        }
    }

    #[test]
    fn pursuit_takes_the_farthest_point_within_reach_and_never_goes_back() {
        // The search attached the start to a node behind the robot: 14 → 6 → 34 → 46.
        let p = path(&[(14.0, 0.0), (6.0, 0.0), (34.0, 0.0), (46.0, 0.0)]);
        let mut route = Route::new(Some(p), Point2::new(14.0, 0.0), Point2::new(46.0, 0.0));
        let (q, remaining) = route.pursue(Point2::new(14.0, 0.0), 8.0, open);
        assert!((q.x - 22.0).abs() < 1e-9 && q.y.abs() < 1e-9, "{q:?}");
        assert!((remaining - 32.0).abs() < 1e-9, "{remaining}");
        // Moving on, the point moves on; straying back does not pull it back.
        let (q2, _) = route.pursue(Point2::new(20.0, 0.0), 8.0, open);
        assert!((q2.x - 28.0).abs() < 1e-9);
        let (q3, r3) = route.pursue(Point2::new(10.0, 0.0), 8.0, open);
        assert_eq!(q3, q2);
        assert!((r3 - (18.0 + 18.0)).abs() < 1e-9, "{r3}");
        // Near the end: the target itself.
        let (q4, r4) = route.pursue(Point2::new(40.0, 0.0), 8.0, open);
        assert_eq!(q4, Point2::new(46.0, 0.0));
        assert!((r4 - 6.0).abs() < 1e-9);
    }

    #[test]
    fn pursuit_follows_a_path_that_folds_back_instead_of_cutting_across() {
        // Up a ramp 11 m to the side and back along the sidewalk: (10, 5) → (21, 8) → (21, 11)
        // → (10, 12). The last leg ends 7 m from the start, across the curb.
        let p = path(&[(10.0, 5.0), (21.0, 8.0), (21.0, 11.0), (10.0, 12.0)]);
        let mut route = Route::new(Some(p), Point2::new(10.0, 5.0), Point2::new(10.0, 12.0));
        let (q, _) = route.pursue(Point2::new(10.0, 5.0), 8.0, open);
        assert!(q.y < 8.0 && q.x < 21.0, "on the first leg, not the last: {q:?}");
        assert!((q.distance(Point2::new(10.0, 5.0)) - 8.0).abs() < 1e-9);
        // Past the fold, the last leg is next.
        let (q2, _) = route.pursue(Point2::new(21.0, 10.0), 8.0, open);
        assert!(q2.y > 11.0 && q2.x < 21.0, "{q2:?}");

        // A fold that stays within the circle: the ramp 3 m to the side. Only a curb along
        // y = 9 m (x < 18.5 m) keeps the look-ahead on the way up the ramp.
        let tight = path(&[(14.0, 5.0), (19.0, 8.0), (19.0, 10.0), (14.0, 11.0)]);
        let curb = |a: Point2, b: Point2, _: f64| {
            if (a.y < 9.0) == (b.y < 9.0) {
                return false;
            }
            let x = a.x + (b.x - a.x) * (9.0 - a.y) / (b.y - a.y);
            x < 18.5
        };
        let mut route = Route::new(Some(tight.clone()), Point2::new(14.0, 5.0), Point2::new(14.0, 11.0));
        let (cut, _) = route.pursue(Point2::new(14.0, 5.0), 8.0, open);
        assert_eq!(cut, Point2::new(14.0, 11.0), "without the curb the target itself is in reach");
        let mut route = Route::new(Some(tight), Point2::new(14.0, 5.0), Point2::new(14.0, 11.0));
        let (q3, _) = route.pursue(Point2::new(14.0, 5.0), 8.0, curb);
        assert_eq!(q3, Point2::new(19.0, 8.0), "the foot of the ramp");
        let (q4, _) = route.pursue(Point2::new(19.0, 9.5), 8.0, curb);
        assert_eq!(q4, Point2::new(14.0, 11.0), "up the ramp, the target");
    }

    #[test]
    fn nodes_around_names_the_edge_under_the_robot() {
        let p = path(&[(0.0, 0.0), (5.0, 0.0), (20.0, 0.0), (30.0, 0.0)]);
        let route = Route::new(Some(p), Point2::new(0.0, 0.0), Point2::new(30.0, 0.0));
        assert_eq!(route.nodes_around(2.0), (None, Some(NodeId(10))));
        assert_eq!(route.nodes_around(10.0), (Some(NodeId(10)), Some(NodeId(11))));
        assert_eq!(route.nodes_around(25.0), (Some(NodeId(11)), None));
        // An edge routed around a curb has waypoints of its own between its nodes.
        let mut routed = path(&[(0.0, 0.0), (5.0, 0.0), (10.0, 3.0), (15.0, 3.0), (20.0, 0.0), (30.0, 0.0)]);
        routed.nodes = vec![NodeId(10), NodeId(11)];
        routed.node_waypoints = vec![1, 4];
        let route = Route::new(Some(routed), Point2::new(0.0, 0.0), Point2::new(30.0, 0.0));
        assert_eq!(route.nodes_around(2.0), (None, Some(NodeId(10))));
        assert_eq!(route.nodes_around(7.0), (Some(NodeId(10)), Some(NodeId(11))));
        assert_eq!(route.nodes_around(13.0), (Some(NodeId(10)), Some(NodeId(11))));
        assert_eq!(route.nodes_around(23.0), (Some(NodeId(11)), None));
        let straight = Route::new(None, Point2::new(0.0, 0.0), Point2::new(30.0, 0.0));
        assert_eq!(straight.nodes_around(10.0), (None, None));
    }

    fn ports(name: &'static str, v: Value) -> PortBindings {
        let mut p = PortBindings::default();
        p.insert(name, Binding::Literal(BbValue::Params(Arc::new(v))));
        p
    }

    #[test]
    fn per_node_parameters_override_only_what_a_node_may_own() {
        let ok =
            Overrides::from_ports(&ports("local_planner", json!({ "dwa": { "max_speed_mps": 1.0 } })), true).unwrap();
        assert!(ok.local.is_some());
        let terrain =
            Overrides::from_ports(&ports("local_planner", json!({ "terrain": { "inflation_m": 1.0 } })), true);
        assert!(terrain.unwrap_err().contains("terrain"));
        let unknown = Overrides::from_ports(&ports("local_planner", json!({ "dwa": { "warp": 9 } })), true);
        assert!(unknown.is_err());
        let graph = Overrides::from_ports(&ports("global_planner", json!({ "graph": {} })), true);
        assert!(graph.unwrap_err().contains("global_planner.graph"));
        let search = Overrides::from_ports(
            &ports("global_planner", json!({ "search": { "replan_cost_rise_ratio": 0.5 } })),
            true,
        )
        .unwrap();
        assert_eq!(search.search.unwrap().replan_cost_rise_ratio, 0.5);

        // Applied over the robot's parameters: only the named fields change.
        let mut base = serde_json::to_value(LocalPlannerParams::simulation()).unwrap();
        merge(&mut base, ok.local.as_ref().unwrap());
        let merged: LocalPlannerParams = serde_json::from_value(base).unwrap();
        assert_eq!(merged.dwa.max_speed_mps, 1.0);
        assert_eq!(merged.dwa.max_turn_rate_radps, LocalPlannerParams::simulation().dwa.max_turn_rate_radps);
        assert_eq!(merged.terrain, LocalPlannerParams::simulation().terrain);
    }

    #[test]
    fn watchdog_needs_a_metre_of_progress_within_the_timeout() {
        let mut d = Driver::new(Overrides::default());
        let t = |s: f64| Time::from_secs_f64(s);
        d.best_at = t(0.0);
        assert!(!d.stuck(t(0.0), None, 20.0, 10.0));
        assert!(!d.stuck(t(8.0), None, 19.5, 10.0), "half a metre is not progress, but the window is not over");
        assert!(!d.stuck(t(9.0), None, 18.9, 10.0), "a metre restarts the window");
        assert!(!d.stuck(t(18.0), None, 18.5, 10.0));
        assert!(d.stuck(t(19.5), None, 18.5, 10.0));
    }

    #[test]
    fn watchdog_catches_a_robot_pinned_in_one_place_whatever_its_route_says() {
        let mut d = Driver::new(Overrides::default());
        let t = |s: f64| Time::from_secs_f64(s);
        let at = |x: f64| Some(Point2::new(x, 0.0));
        // Replans keep shortening the remaining distance, but the robot wiggles within 2 m.
        for k in 0..=20 {
            let s = k as f64;
            let stuck = d.stuck(t(s), at((s * 1.7).sin()), 100.0 - 2.0 * s, 10.0);
            assert!(!stuck, "within two timeouts: {s} s");
        }
        assert!(d.stuck(t(21.0), at(0.5), 50.0, 10.0), "pinned for more than 20 s");
        // A robot that moves on is not pinned.
        let mut moving = Driver::new(Overrides::default());
        for k in 0..60 {
            let s = k as f64;
            assert!(!moving.stuck(t(s), at(0.5 * s), 100.0 - 2.0 * s, 10.0));
        }
    }
}
