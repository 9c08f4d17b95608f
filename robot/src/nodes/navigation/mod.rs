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
//!   the stuck timeout → stuck; and the no-progress bound, on the straight-line distance and
//!   the path left, whatever the replans do).
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
use spomp_behaviors::registry::{Category, NodeError, NodeRegistry, NodeTypeSpec, PortBindings, PortSpec};

mod driver;
mod navigator;
mod recovery;
mod route;
mod tuning;

use driver::{Driver, Reason, Step};
use navigator::{Limit, Navigator, Request};
use recovery::register_recovery;
use route::Route;
use tuning::{Overrides, Tuning};

/// The remaining distance must drop by this much within the stuck timeout, metres.
pub const PROGRESS_MARGIN_M: f64 = 1.0;
/// `navigate_to` replans at least this often even when the path looks valid, seconds.
pub const REPLAN_PERIOD_S: f64 = 10.0;

/// A robot whose odometry stays within this distance of one point for the stuck timeout has
/// not moved at all (wedged: its commands are refused), metres.
pub const MOTIONLESS_RADIUS_M: f64 = 0.25;

/// A robot that stays within this distance of one point ...
pub const PINNED_RADIUS_M: f64 = 2.0;

/// ... for this many stuck timeouts is stuck, and backs out along its own trail.
pub const PINNED_TIMEOUTS: f64 = 2.0;

/// Detours a drive may take ([`driver::Driver::take_detour`]): each is a longer route forced by
/// an edge found blocked or costlier, against which progress along the path is measured anew.
pub const DETOURS_PER_DRIVE: u32 = 3;
/// `navigate_to`'s look-ahead when the mission leaves `lookahead_m` out, and `return_home`'s,
/// metres: the port's declared default.
pub const DEFAULT_LOOKAHEAD_M: f64 = 8.0;
/// When stuck, the blocked edge is taken this far ahead of the robot along the path, metres.
const BLOCKAGE_PROBE_M: f64 = 2.0;
/// A robot this close to its look-ahead point may take one whose line is not clear of curbs.
const LOOKAHEAD_STALL_M: f64 = 2.0;
/// Half the width of the band along the look-ahead line that must be free of curbs, metres.
const CLEARANCE_HALF_WIDTH_M: f64 = 1.0;
/// How far beyond the last look-ahead point (plus the look-ahead) the path is searched, metres.
const PROJECTION_WINDOW_M: f64 = 20.0;

/// Registers the navigation nodes (the recovery behaviours `back_up` and `spin` too).
pub fn register_navigation(r: &mut NodeRegistry<RobotRuntime>) {
    use Category::Action;
    use PortType::{Float, Params, Point, String as Str};
    use RobotKind::Ugv;

    register_recovery(r);

    r.register(
        NodeTypeSpec::leaf(
            "navigate_to",
            Action,
            "Plans a path on the robot's traversability graph from its pose to `target`, follows it by giving the local planner the farthest path point within `lookahead_m` that the path reaches without leaving that circle and whose straight line (widened to 1 m either side at the point) crosses no curb the aerial map shows unless the path does (a path up a curb ramp is followed, not cut across the curb) (local goal per panorama, DWA at every tick), and replans when an edge of the path is removed or the path's cost rises after a reachability scan (checked at every panorama), and every 10 s; replans keep the edge being driven (they search from the node ahead, keeping the rest of an edge routed around a curb). When the remaining path length has not shrunk by 1 m for `stuck_timeout_s` on a graph edge, the robot marks that edge failed on its global planner and replans from the node behind (a blockage the scans could not judge). A robot that stays within 2 m of one point for twice `stuck_timeout_s` is stuck too: it backs out along its own trail to the newest trail point from which the graph has a path (so does any plan from a place the graph has no path from, such as a node whose edges were all removed). Success within `tolerance_m`; Failure (reason in `failure_reason`) when there is no path (`no_path`, also when a blocked path has no alternative), when stuck with no edge to give up (`stuck`; the edge is the one the robot stands on when its look-ahead has moved past it, say onto the last leg to a target beyond a curb), when it makes no progress (`no_progress`: for `no_progress_timeout_s`, replans or not, neither 1 m nearer the target than its best nor 1 m less path left than its best — a route forced by an edge found blocked or costlier that is longer than the path left sets a new path-left baseline, at most 3 times a drive, so a detour round a block is not given up while the robot gains on it — or its odometry not 0.25 m from one point for `stuck_timeout_s`; the edge being driven is marked failed on the robot's global planner, which then plans around it), or past the time limit (`time_limit`): `time_limit_s` if given, else `time_per_m_s` (unset: the mission's `goals.time_limit_per_m_s`) × the planned path length, counted from the start and extended by a replan forced by a blocked or costlier path to now + `time_per_m_s` × the new length. With no aerial map yet (empty graph) it drives toward the target with the local planner alone (time limit from the straight-line distance) and plans as soon as a graph exists. A target where the robot's map has no data yet (a goal another robot found in a map version that has not reached this one) is approached over the graph to the reachable node nearest it, then straight on with the local planner alone. Writes the robot's planned path and publishes its end on the team state; finishing or halting stops the robot and clears both.",
            vec![
                PortSpec::input("target", Point, "Where to go (map frame)."),
                PortSpec::input("tolerance_m", Float, "Arrival radius, metres.").with_default(json!(2.0)),
                PortSpec::optional("time_limit_s", Float, "Fixed time limit, seconds; overrides `time_per_m_s`."),
                PortSpec::optional("time_per_m_s", Float, "Time limit per metre of planned path, s/m; unset: the mission's `goals.time_limit_per_m_s`."),
                PortSpec::optional("stuck_timeout_s", Float, "Fail as stuck after this long without 1 m of progress along the path, seconds; unset: the robot's `navigation.watchdog.stuck_timeout_s` (30 s unless the mission says otherwise)."),
                PortSpec::optional("no_progress_timeout_s", Float, "Fail with `no_progress` when the robot has come neither 1 m nearer the target (straight line, best so far) nor 1 m further along its path (path left, best so far; up to 3 detours reset that baseline) for this long, whatever the replans did, seconds; unset: the robot's `navigation.watchdog.no_progress_timeout_s` (120 s unless the mission says otherwise)."),
                PortSpec::input("lookahead_m", Float, "Distance ahead along the global path of the waypoint given to the local planner, metres.").with_default(json!(DEFAULT_LOOKAHEAD_M)),
                PortSpec::optional("global_planner", Params, "Only `search: { replan_cost_rise_ratio }` (the robot's graph, learning and experience are shared by all nodes and set in its navigation parameters)."),
                PortSpec::optional("local_planner", Params, "Overrides of `local_goal` and `dwa` (spomp-local-planner) over the robot's parameters, for this node; `terrain` is the robot's."),
                PortSpec::output("failure_reason", Str, "Why it failed: no_path, stuck, no_progress or time_limit (no_navigation: the robot has no navigation stack)."),
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
                PortSpec::output("failure_reason", Str, "Why it failed: no_path, stuck, no_progress or time_limit."),
            ],
            |p| Ok(Box::new(ReturnHome::new(p)?)),
        )
        .for_kinds(&[Ugv])
        .using_skills(&["global_planner", "local_planner", "localization"]),
    );
}

// ---------------------------------------------------------------------------------------------
// Nodes

/// A positive finite number from a port (its declared default when unset), or a report.
/// The robot's own stuck timeout (`navigation.watchdog`), for nodes that do not set one.
fn robot_stuck_timeout_s(rt: &RobotRuntime) -> f64 {
    rt.nav().map_or_else(|| WatchdogParams::default().stuck_timeout_s, |n| n.params().watchdog.stuck_timeout_s)
}

/// The robot's own no-progress bound (`navigation.watchdog`), for nodes that do not set one.
fn robot_no_progress_timeout_s(rt: &RobotRuntime) -> f64 {
    rt.nav()
        .map_or_else(|| WatchdogParams::default().no_progress_timeout_s, |n| n.params().watchdog.no_progress_timeout_s)
}

/// A finite non-negative number from a port, or a report. A port with a declared default is
/// always bound (the loader binds the default), so there is no default here.
fn number(binding: &Binding, ctx: &mut Ctx<'_>, node: &str, port: &str) -> Option<f64> {
    let Some(v) = binding.get::<f64>(ctx.blackboard) else {
        ctx.blackboard.report(format!("{node}: `{port}` is not set"));
        return None;
    };
    if v.is_finite() && v >= 0.0 {
        Some(v)
    } else {
        ctx.blackboard.report(format!("{node}: `{port}` must be a finite non-negative number, got {v}"));
        None
    }
}

/// [`number`] for an optional port with no declared default, whose value when the mission
/// leaves it out is the robot's (`unset`).
fn number_or(binding: &Binding, ctx: &mut Ctx<'_>, node: &str, port: &str, unset: f64) -> Option<f64> {
    match binding {
        Binding::Unset => Some(unset),
        b => number(b, ctx, node, port),
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
    no_progress_timeout: Binding,
    lookahead: Binding,
    failure_reason: Binding,
    nav: Navigator,
}

impl NavigateTo {
    fn new(p: &PortBindings) -> Result<Self, NodeError> {
        Ok(NavigateTo {
            target: p.get("target")?,
            tolerance: p.get("tolerance_m")?,
            time_limit: p.get("time_limit_s")?,
            time_per_m: p.get("time_per_m_s")?,
            stuck_timeout: p.get("stuck_timeout_s")?,
            no_progress_timeout: p.get("no_progress_timeout_s")?,
            lookahead: p.get("lookahead_m")?,
            failure_reason: p.get("failure_reason")?,
            nav: Navigator::new(Overrides::from_ports(p, true)?),
        })
    }
}

impl Behavior<RobotRuntime> for NavigateTo {
    fn tick(&mut self, prev: Status, ctx: &mut Ctx<'_>) -> Status {
        const NODE: &str = "navigate_to";
        let now = ctx.now;
        let Some(target) = target_of(&self.target, ctx, NODE) else { return Status::Failure };
        let (Some(tolerance_m), Some(stuck_timeout_s), Some(no_progress_timeout_s), Some(lookahead_m)) = (
            number(&self.tolerance, ctx, NODE, "tolerance_m"),
            number_or(&self.stuck_timeout, ctx, NODE, "stuck_timeout_s", robot_stuck_timeout_s(ctx.env)),
            number_or(
                &self.no_progress_timeout,
                ctx,
                NODE,
                "no_progress_timeout_s",
                robot_no_progress_timeout_s(ctx.env),
            ),
            number(&self.lookahead, ctx, NODE, "lookahead_m"),
        ) else {
            return Status::Failure;
        };
        let fixed = match self.time_limit {
            Binding::Unset => None,
            _ => match number(&self.time_limit, ctx, NODE, "time_limit_s") {
                Some(v) => Some(v),
                None => return Status::Failure,
            },
        };
        let per_m = match self.time_per_m {
            Binding::Unset => None,
            _ => match number(&self.time_per_m, ctx, NODE, "time_per_m_s") {
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
        let req = Request { target, tolerance_m, limit, stuck_timeout_s, no_progress_timeout_s, lookahead_m };
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
    fn new(p: &PortBindings) -> Result<Self, NodeError> {
        Ok(ReturnHome {
            min_distance: p.get("min_distance_m")?,
            tolerance: p.get("tolerance_m")?,
            stuck_timeout: p.get("stuck_timeout_s")?,
            failure_reason: p.get("failure_reason")?,
            nav: Navigator::new(Overrides::default()),
        })
    }
}

impl Behavior<RobotRuntime> for ReturnHome {
    fn tick(&mut self, prev: Status, ctx: &mut Ctx<'_>) -> Status {
        const NODE: &str = "return_home";
        let now = ctx.now;
        let (Some(min_distance_m), Some(tolerance_m), Some(stuck_timeout_s)) = (
            number(&self.min_distance, ctx, NODE, "min_distance_m"),
            number(&self.tolerance, ctx, NODE, "tolerance_m"),
            number_or(&self.stuck_timeout, ctx, NODE, "stuck_timeout_s", robot_stuck_timeout_s(ctx.env)),
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
            no_progress_timeout_s: robot_no_progress_timeout_s(rt),
            lookahead_m: DEFAULT_LOOKAHEAD_M,
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
    fn new(p: &PortBindings) -> Result<Self, NodeError> {
        // A literal frame is checked when the mission is loaded; a blackboard one when ticked.
        if let Some(BbValue::Str(name)) = p.literal("frame")? {
            TargetFrame::parse(name).map_err(|e| NodeError::port("frame", e))?;
        }
        Ok(NavigateLocal {
            target: p.get("target")?,
            frame: p.get("frame")?,
            tolerance: p.get("tolerance_m")?,
            stuck_timeout: p.get("stuck_timeout_s")?,
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
            number(&self.tolerance, ctx, NODE, "tolerance_m"),
            number_or(&self.stuck_timeout, ctx, NODE, "stuck_timeout_s", robot_stuck_timeout_s(ctx.env)),
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
    use crate::settings::merge;

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
    fn a_robot_wedged_below_the_last_node_is_on_the_edge_that_led_it_there() {
        // The last edge climbs a curb (5, 0) → (12, 0); the target lies 3 m off it, 4 m short of
        // its end. The look-ahead reaches the last leg while the robot stands mid-edge.
        let p = path(&[(0.0, 0.0), (5.0, 0.0), (12.0, 0.0), (8.0, 3.0)]);
        let mut route = Route::new(Some(p), Point2::new(0.0, 0.0), Point2::new(8.0, 3.0));
        let here = Point2::new(8.0, 0.2);
        let (q, _) = route.pursue(here, 8.0, open);
        assert_eq!(q, Point2::new(8.0, 3.0), "the look-ahead is the target");
        assert_eq!(route.nodes_around(route.reached), (Some(NodeId(11)), None), "no edge ahead of the look-ahead");
        let s = route.project(here);
        assert!((s - 8.0).abs() < 1e-9, "{s}");
        assert_eq!(route.nodes_around(s), (Some(NodeId(10)), Some(NodeId(11))));
        // Never beyond the look-ahead point: a robot that strayed past it projects onto it.
        let mut early = Route::new(Some(path(&[(0.0, 0.0), (5.0, 0.0), (40.0, 0.0)])), here, Point2::new(40.0, 0.0));
        early.pursue(Point2::new(0.0, 0.0), 8.0, open);
        assert!((early.project(Point2::new(20.0, 1.0)) - 8.0).abs() < 1e-9);
    }

    #[test]
    fn progress_along_a_detour_is_progress_but_flipping_routes_is_not() {
        let t = |s: f64| Time::from_secs_f64(s);
        let far = |d: &mut Driver, s: f64| d.no_progress(t(s), 130.0, Some(Point2::new(s, 0.0)), 120.0, 30.0);
        // Round a block: the path left shrinks by 1.5 m/s from 480 m while the straight line
        // to the target stays at 130 m or more for 300 s.
        let mut d = Driver::new(Overrides::default());
        d.take_detour(480.0);
        for k in 0..300 {
            let s = k as f64;
            d.route_progress(t(s), 480.0 - 1.5 * s);
            assert!(far(&mut d, s).is_none(), "gaining on the detour at {s} s");
        }
        // Two routes flipping every 10 s, each driven 15 m: each switch to the longer one is a
        // detour until the three are spent; then only the shorter one's least path left counts,
        // and the drive ends one bound after the last progress (70 s).
        let mut d = Driver::new(Overrides::default());
        d.route_progress(t(0.0), 300.0);
        let mut ended = None;
        for k in 0..2000 {
            let s = k as f64 * 0.5;
            let since = s % 10.0;
            let length = if ((s / 10.0) as u32).is_multiple_of(2) { 300.0 } else { 400.0 };
            if since == 0.0 {
                d.take_detour(length);
            }
            d.route_progress(t(s), length - 1.5 * since);
            if let Some(why) = far(&mut d, s) {
                ended = Some((s, why));
                break;
            }
        }
        let (s, why) = ended.expect("the flipping drive ends");
        assert!(s > 120.0 && s <= 70.0 + 120.5, "ended at {s} s: {why}");
        assert!(why.contains("nor less than 286.5 m of path left"), "{why}");
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
        let registry = crate::nodes::registry();
        let mut p = PortBindings::declared(registry.get("navigate_to").unwrap());
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
        assert!(terrain.unwrap_err().to_string().contains("terrain"));
        let unknown = Overrides::from_ports(&ports("local_planner", json!({ "dwa": { "warp": 9 } })), true);
        assert!(unknown.is_err());
        let graph = Overrides::from_ports(&ports("global_planner", json!({ "graph": {} })), true);
        assert!(graph.unwrap_err().to_string().contains("global_planner.graph"));
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
    fn no_progress_is_bounded_whatever_the_replans_do() {
        let mut d = Driver::new(Overrides::default());
        let t = |s: f64| Time::from_secs_f64(s);
        let at = |x: f64| Some(Point2::new(x, 0.0));
        d.progress_at = t(0.0);
        d.still_since = t(0.0);
        // The robot drives back and forth (never still) while replans keep restarting the stuck
        // window and extending the time limit: it never gets 1 m nearer than 40 m.
        for k in 0..120 {
            let s = k as f64;
            d.restart_watchdog(t(s), 100.0);
            let distance = 40.0 + 5.0 * (s * 0.3).sin().abs();
            let why = d.no_progress(t(s), distance, at(3.0 * (s * 0.3).sin()), 120.0, 30.0);
            assert!(why.is_none(), "within the bound at {s} s: {why:?}");
        }
        let why = d.no_progress(t(121.0), 40.5, at(1.0), 120.0, 30.0).unwrap();
        assert!(why.contains("no nearer than 40.0 m"), "{why}");
        // Getting a metre nearer restarts the bound.
        let mut nearer = Driver::new(Overrides::default());
        for k in 0..300 {
            let s = k as f64;
            assert!(nearer.no_progress(t(s), 300.0 - s, at(s), 120.0, 30.0).is_none());
        }
    }

    #[test]
    fn a_robot_that_does_not_move_at_all_makes_no_progress_after_the_stuck_timeout() {
        let mut d = Driver::new(Overrides::default());
        let t = |s: f64| Time::from_secs_f64(s);
        // Wedged: odometry within a few centimetres (turning in place), the target as far.
        for k in 0..30 {
            let s = k as f64;
            assert!(d.no_progress(t(s), 50.0, Some(Point2::new(0.01 * (s % 3.0), 0.0)), 120.0, 30.0).is_none());
        }
        let why = d.no_progress(t(30.5), 50.0, Some(Point2::new(0.02, 0.0)), 120.0, 30.0).unwrap();
        assert!(why.contains("has not moved for 30 s"), "{why}");
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
