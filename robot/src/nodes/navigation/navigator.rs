//! The navigator policy: planning, replanning, blocked edges, backtracking and the time limit.

#[allow(clippy::wildcard_imports)]
use super::*;

/// How the time limit is set.
#[derive(Clone, Copy, Debug)]
pub(super) enum Limit {
    /// Fixed, seconds from the start.
    Fixed(f64),
    /// Seconds per metre of planned path.
    PerMetre(f64),
}

/// The global layer over [`Driver`]: plan, follow with a look-ahead waypoint, replan, time limit.
pub(super) struct Navigator {
    pub(super) driver: Driver,
    pub(super) route: Option<Route>,
    pub(super) started: Time,
    pub(super) deadline_s: f64,
    pub(super) next_replan: Time,
    /// Panorama stamp at which the path was last checked.
    pub(super) checked_view: Option<Time>,
    /// Graph node at the start of the edge the robot is on.
    pub(super) behind: Option<NodeId>,
    /// Graph node the robot is heading to (`None` on the last stretch to the target).
    pub(super) ahead: Option<NodeId>,
    /// The graph edge the robot itself stands on, from its projection on the route (kept
    /// while a replan from the node ahead makes the rest of it the route's first leg).
    pub(super) on_edge: Option<(NodeId, NodeId)>,
}

/// What a navigation run asks for.
#[derive(Clone, Copy, Debug)]
pub(super) struct Request {
    pub(super) target: Point2,
    pub(super) tolerance_m: f64,
    pub(super) limit: Limit,
    pub(super) stuck_timeout_s: f64,
    /// The no-progress bound ([`Driver::no_progress`]), seconds.
    pub(super) no_progress_timeout_s: f64,
    pub(super) lookahead_m: f64,
}

/// Why a (re)plan was triggered.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Trigger {
    Start,
    Changed,
    Periodic,
}

impl Navigator {
    pub(super) fn new(overrides: Overrides) -> Self {
        Navigator {
            driver: Driver::new(overrides),
            route: None,
            started: Time::ZERO,
            deadline_s: f64::INFINITY,
            next_replan: Time::ZERO,
            checked_view: None,
            behind: None,
            ahead: None,
            on_edge: None,
        }
    }

    pub(super) fn has_graph(rt: &RobotRuntime) -> bool {
        rt.nav().is_some_and(NavStack::has_graph)
    }

    /// Plans from `from`; `Ok(None)` when the robot has no graph yet (local-only driving).
    pub(super) fn plan(rt: &mut RobotRuntime, from: Point2, to: Point2) -> Result<Option<GlobalPath>, String> {
        if !Self::has_graph(rt) {
            return Ok(None);
        }
        let Some(nav) = rt.nav_mut() else { return Ok(None) };
        nav.plan(from, to).map(Some).map_err(|e| e.to_string())
    }

    /// Takes a new route and publishes it.
    pub(super) fn adopt(&mut self, rt: &mut RobotRuntime, route: Route, now: Time, trigger: Trigger, req: &Request) {
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
    pub(super) fn clear(rt: &mut RobotRuntime) {
        rt.clear_path();
    }

    /// Ends the drive: stop, clear the path.
    pub(super) fn finish(&mut self, rt: &mut RobotRuntime) {
        rt.command_velocity(Twist2::ZERO);
        Self::clear(rt);
        self.route = None;
    }

    pub(super) fn start(&mut self, rt: &mut RobotRuntime, now: Time, req: &Request) -> Result<(), (Reason, String)> {
        self.driver.start(rt, now).map_err(|e| (Reason::NoNavigation, e))?;
        self.started = now;
        self.deadline_s = f64::INFINITY;
        self.checked_view = None;
        self.route = None;
        self.behind = None;
        self.ahead = None;
        self.on_edge = None;
        let from = rt.pose().map_or(rt.start().position(), |p| p.pose.position());
        let path = Self::plan(rt, from, req.target).map_err(|e| (Reason::NoPath, format!("no path: {e}")))?;
        self.adopt(rt, Route::new(path, from, req.target), now, Trigger::Start, req);
        Ok(())
    }

    /// A route from `here` that starts with the graph search from `origin` (a node position)
    /// or, with none, from `here` itself. `lead` are the points to pass between `here` and
    /// `origin`: the rest of the edge being driven when it is routed around a curb.
    pub(super) fn route_from(
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
    pub(super) fn backtrack_route(rt: &mut RobotRuntime, here: Point2, target: Point2) -> Option<Route> {
        let nav = rt.nav_mut()?;
        nav.note_stuck_at(here);
        let path = nav.plan_backtracking(here, target).ok()?;
        Some(Route::new(Some(path), here, target))
    }

    pub(super) fn node_position(rt: &RobotRuntime, node: Option<NodeId>) -> Option<Point2> {
        let node = node?;
        rt.nav()?.global().nodes().find(|(id, _, _)| *id == node).map(|(_, p, _)| p)
    }

    /// Replans keeping the robot's commitment: from the node it is heading to (the current
    /// edge stays), or — when the current edge is what failed (`avoid_current`) — from the node
    /// it came from; from its own position when neither applies or works.
    pub(super) fn replan(
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
    pub(super) fn maybe_replan(
        &mut self,
        rt: &mut RobotRuntime,
        now: Time,
        here: Point2,
        req: &Request,
    ) -> Result<(), String> {
        let stamp = rt.nav().and_then(NavStack::view).map(|v| v.stamp);
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
                    && match nav.global().path_graph_cost(path) {
                        None => true,
                        Some(cost) => cost > path.graph_cost * (1.0 + ratio) + 1e-9,
                    };
                let gone = match (self.behind, self.ahead) {
                    (Some(a), Some(b)) => nav.global().edge_between(a, b).is_none(),
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
                if trigger == Trigger::Changed {
                    self.driver.take_detour(remaining);
                }
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

    pub(super) fn tick(&mut self, rt: &mut RobotRuntime, now: Time, req: &Request) -> Step {
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
        let odom = rt.odometry().map(|o| o.pose.position());
        if let Some(why) = self.driver.no_progress(
            now,
            here.distance(req.target),
            odom,
            req.no_progress_timeout_s,
            req.stuck_timeout_s,
        ) {
            // The edge being driven is the one it failed to drive: the planner learns it.
            if let Some(nav) = rt.nav_mut()
                && let (Some(a), Some(b)) = (self.behind, self.ahead)
            {
                nav.block_edge(a, b);
            }
            return Step::Failed(Reason::NoProgress, why);
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
        let global = rt.nav().map(NavStack::global);
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
        self.driver.route_progress(now, remaining);
        // The graph edge the robot is on: its nodes behind and ahead (kept across a replan that
        // re-attached the robot to the node it was heading to).
        let probe = (route.reached - waypoint.distance(here) + BLOCKAGE_PROBE_M).max(0.0);
        let (behind, ahead) = route.nodes_around(probe);
        if behind.is_some() || ahead != self.ahead {
            self.behind = behind;
        }
        self.ahead = ahead;
        self.on_edge = match route.nodes_around(route.project(here)) {
            (Some(a), Some(b)) => Some((a, b)),
            (None, Some(b)) => self.on_edge.filter(|&(_, e)| e == b),
            _ => None,
        };
        if self.driver.stuck(now, Some(here), remaining, req.stuck_timeout_s) {
            let pinned = self.driver.pinned(now, Some(here), req.stuck_timeout_s);
            // The look-ahead may have moved past the edge that wedged the robot (onto the last
            // leg to a target just beyond a curb): then the edge is the one the robot stands on.
            if (self.behind.is_none() || self.ahead.is_none())
                && let Some((a, b)) = self.on_edge
            {
                self.behind = Some(a);
                self.ahead = Some(b);
            }
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
                self.driver.take_detour(remaining);
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
                    self.driver.take_detour(remaining);
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
