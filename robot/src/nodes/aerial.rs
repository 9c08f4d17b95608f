//! UAV nodes of the paper's aerial planner (§Aerial Planner, docs/design.md §5 "UAV time-sharing"):
//! `follow_waypoints` (a mission list or a QGroundControl `.plan`, resumable, routed around
//! no-fly polygons), `seek_robot` (round-robin over the robots the team state knows, flying to a
//! robot's last known pose or, when that is stale, the end of its last known path) and
//! `wait_for_sync` (hover or track until a fresh full team-state sync with the robot).
//!
//! A flying node commands a flight target every tick it runs; the runtime clears it before each tick,
//! so a halted node's command never outlives it (halting clears it too).

use std::collections::VecDeque;
use std::path::Path;
use std::sync::Arc;

use serde_json::json;
use spomp_core::{FlightCommand, Point2, RobotId, RobotKind, Time};

use super::qgc_plan::{Polygons, load_plan};
use super::{Ctx, literal_number, number};
use crate::runtime::RobotRuntime;
use spomp_behaviors::Status;
use spomp_behaviors::blackboard::{BbValue, Binding, PortType};
use spomp_behaviors::node::Behavior;
use spomp_behaviors::registry::{Category, NodeError, NodeRegistry, NodeTypeSpec, PortBindings, PortSpec};

/// Default clearance kept from no-fly polygons, metres.
const DEFAULT_NO_FLY_MARGIN_M: f64 = 5.0;

/// Registers the UAV nodes.
pub fn register_aerial(r: &mut NodeRegistry<RobotRuntime>) {
    use Category::Action;
    use PortType::{Bool, Float, Int, Params, Point, Points, Robot, String as Str};
    use RobotKind::Uav;

    r.register(
        NodeTypeSpec::leaf(
            "follow_waypoints",
            Action,
            "Flies the waypoint list — `waypoints`, or the waypoints of a QGroundControl `plan_file` (read when the mission is built; NAV_WAYPOINT items, surveys' generated items, return to launch; placed by their latitude and longitude through the operating area's GPS reference when it has one — an imported world's `gps_origin`, a robot's `ros2.gps_origin` — else around the plan's planned home as the map origin; x east, y north, metres; exclusion geofences become no-fly zones, inclusion geofences fences the transfers stay inside) — at `altitude_m` and `speed_mps`, starting at index `progress` and advancing it on arrival within `arrive_radius_m` of each waypoint, so a state machine that leaves and re-enters the state resumes where it left off. With `resume_from` connected it resumes at the very point it was interrupted: it flies back there first and then on along the interrupted leg, so a survey leaves no gap. Transfers route around `no_fly` polygons and stay inside its `inside` fences, if any (shortest path over their corners, kept `margin_m` clear; a UAV outside every fence flies straight in); a waypoint inside a zone or outside every fence is refused when the mission is built (a waypoint read from the blackboard: reported and skipped), one with no route to it reported and skipped. Succeeds when the list is exhausted. Give exactly one of `waypoints` and `plan_file`.",
            vec![
                PortSpec::optional("waypoints", Points, "Waypoints (map frame), flown in order."),
                PortSpec::optional("plan_file", Str, "QGroundControl .plan file, relative to the mission file; its altitudes are ignored in favour of `altitude_m`."),
                PortSpec::input("altitude_m", Float, "Flight altitude above take-off, metres.").with_default(json!(60.0)),
                PortSpec::input("speed_mps", Float, "Cruise speed, m/s.").with_default(json!(5.0)),
                PortSpec::input("arrive_radius_m", Float, "A waypoint (or route corner) counts as reached within this distance, metres.").with_default(json!(2.0)),
                PortSpec::optional("no_fly", Params, "No-fly polygons and inclusion fences: `{zones: [[{x, y}, …], …], inside: [[{x, y}, …], …], margin_m: 5}` (map frame, metres; `inside`: fly only inside one of these)."),
                PortSpec::in_out("progress", Int, "Index of the next waypoint; share one entry between states so exploring resumes where it left off."),
                PortSpec {
                    optional: true,
                    ..PortSpec::in_out("resume_from", Point, "Where the flight toward waypoint `progress` was last interrupted (written while flying the leg); share one entry between states, like `progress`, so a re-entered survey completes the interrupted leg.")
                },
            ],
            build_follow,
        )
        .for_kinds(&[Uav]),
    );
    r.register(
        NodeTypeSpec::leaf(
            "seek_robot",
            Action,
            "On start picks the next target round-robin (in id order, after the robot last written to `target`) among the robots the team state knows a pose or path end of — UGVs and the basestation; restrict with `candidates`, drop robots unheard for `alive_within_s` — skipping itself, and writes it to `target`. Flies to its last known pose, or to the end of its last known path when the pose is older than `stale_after_s`, re-targeting every tick as newer information arrives. Succeeds on arrival within `arrive_radius_m`; fails if there is no robot to seek.",
            vec![
                PortSpec::input("stale_after_s", Float, "A pose older than this is stale: fly to the path end instead, seconds.").with_default(json!(30.0)),
                PortSpec::input("arrive_radius_m", Float, "Arrival radius (within radio range for a full sync), metres.").with_default(json!(20.0)),
                PortSpec::input("speed_mps", Float, "Cruise speed, m/s.").with_default(json!(5.0)),
                PortSpec::input("altitude_m", Float, "Flight altitude above take-off, metres.").with_default(json!(60.0)),
                PortSpec::optional("candidates", Str, "Robot ids to choose among, separated by commas or spaces (default: every robot the team state knows; the team state does not record kinds, so list the UGVs and basestation in teams with several UAVs)."),
                PortSpec::optional("alive_within_s", Float, "Skip robots whose last pose is older than this, seconds (default: every known robot counts as alive)."),
                PortSpec::output("target", Robot, "The robot sought; also the round-robin memory (the next pick follows it)."),
            ],
            build_seek,
        )
        .for_kinds(&[Uav])
        .using_skills(&["teamstate"]),
    );
    r.register(
        NodeTypeSpec::leaf(
            "wait_for_sync",
            Action,
            "Hovers (or, with `track`, follows `robot`'s latest known pose) until a full team-state sync with it completes, then succeeds; fails after `timeout_s`. Only a sync completed during this wait counts: the team state must report it complete after having reported it incomplete since the wait began, or together with a pose of the robot stamped after the wait began.",
            vec![
                PortSpec::input("robot", Robot, "Peer to sync with."),
                PortSpec::input("timeout_s", Float, "Give up after this long, seconds.").with_default(json!(45.0)),
                PortSpec::input("track", Bool, "Follow the robot while waiting (false: hover in place).").with_default(json!(true)),
                PortSpec::input("speed_mps", Float, "Cruise speed while tracking, m/s.").with_default(json!(5.0)),
                PortSpec::input("altitude_m", Float, "Flight altitude above take-off, metres.").with_default(json!(60.0)),
            ],
            build_wait,
        )
        .for_kinds(&[Uav])
        .using_skills(&["teamstate"]),
    );
}

// ---------------------------------------------------------------------------------- ports

/// Altitude and speed of a flying node.
fn flight_params(altitude: &Binding, speed: &Binding, ctx: &mut Ctx<'_>, node: &str) -> Option<(f64, f64)> {
    let altitude_m = number(altitude, ctx, node, "altitude_m", false)?;
    let speed_mps = number(speed, ctx, node, "speed_mps", true)?;
    Some((altitude_m, speed_mps))
}

/// Clears the flight command on halt.
fn stop_flying(ctx: &mut Ctx<'_>) {
    ctx.env.hover();
}

// ---------------------------------------------------------------------------------- no-fly zones

/// One no-fly polygon and the corners routes turn at.
#[derive(Clone, Debug)]
struct Zone {
    /// Vertices, counter-clockwise.
    poly: Vec<Point2>,
    /// Vertices pushed outward by the margin (mitred), where routes may turn.
    corners: Vec<Point2>,
}

/// The no-fly polygons a node routes around, and the inclusion fences it stays inside.
#[derive(Clone, Debug, Default)]
struct NoFly {
    zones: Vec<Zone>,
    /// Inclusion fences: when any is given, transfers stay inside one of them at every point
    /// (their corners pushed inward by the margin are where routes turn).
    fences: Vec<Zone>,
}

fn signed_area(poly: &[Point2]) -> f64 {
    let n = poly.len();
    (0..n).map(|i| poly[i].cross(poly[(i + 1) % n])).sum::<f64>() / 2.0
}

/// Even-odd point-in-polygon test.
fn contains(poly: &[Point2], p: Point2) -> bool {
    let n = poly.len();
    let mut inside = false;
    for i in 0..n {
        let (a, b) = (poly[i], poly[(i + n - 1) % n]);
        if (a.y > p.y) != (b.y > p.y) && p.x < (b.x - a.x) * (p.y - a.y) / (b.y - a.y) + a.x {
            inside = !inside;
        }
    }
    inside
}

/// Whether segments ab and cd share a point (touching counts).
fn segments_meet(a: Point2, b: Point2, c: Point2, d: Point2) -> bool {
    const EPS: f64 = 1e-9;
    let o = |p: Point2, q: Point2, r: Point2| (q - p).cross(r - p);
    let on = |p: Point2, q: Point2, r: Point2| {
        r.x >= p.x.min(q.x) - EPS && r.x <= p.x.max(q.x) + EPS && r.y >= p.y.min(q.y) - EPS && r.y <= p.y.max(q.y) + EPS
    };
    let (d1, d2, d3, d4) = (o(c, d, a), o(c, d, b), o(a, b, c), o(a, b, d));
    if ((d1 > EPS && d2 < -EPS) || (d1 < -EPS && d2 > EPS)) && ((d3 > EPS && d4 < -EPS) || (d3 < -EPS && d4 > EPS)) {
        return true;
    }
    (d1.abs() <= EPS && on(c, d, a))
        || (d2.abs() <= EPS && on(c, d, b))
        || (d3.abs() <= EPS && on(a, b, c))
        || (d4.abs() <= EPS && on(a, b, d))
}

impl Zone {
    fn new(mut poly: Vec<Point2>, margin: f64) -> Result<Zone, String> {
        if poly.len() < 3 {
            return Err(format!("a zone needs at least 3 vertices, found {}", poly.len()));
        }
        if poly.iter().any(|p| !(p.x.is_finite() && p.y.is_finite())) {
            return Err("zone vertices must be finite".into());
        }
        let area = signed_area(&poly);
        if area.abs() < 1e-6 {
            return Err("a zone must enclose an area".into());
        }
        if area < 0.0 {
            poly.reverse();
        }
        let n = poly.len();
        let outward = |d: Point2| {
            let len = d.norm().max(1e-12);
            Point2::new(d.y / len, -d.x / len)
        };
        let corners = (0..n)
            .map(|i| {
                let (prev, cur, next) = (poly[(i + n - 1) % n], poly[i], poly[(i + 1) % n]);
                let n1 = outward(cur - prev);
                let n2 = outward(next - cur);
                let sum = n1 + n2;
                let dir = if sum.norm() < 1e-9 { n1 } else { sum * (1.0 / sum.norm()) };
                cur + dir * (margin / dir.dot(n1).max(0.2))
            })
            .collect();
        Ok(Zone { poly, corners })
    }

    fn blocks(&self, a: Point2, b: Point2) -> bool {
        let n = self.poly.len();
        (0..n).any(|i| segments_meet(a, b, self.poly[i], self.poly[(i + 1) % n])) || contains(&self.poly, (a + b) * 0.5)
    }

    /// Whether the segment ab lies inside this polygon (as a fence): both ends inside and no
    /// edge crossed or touched.
    fn holds(&self, a: Point2, b: Point2) -> bool {
        let n = self.poly.len();
        contains(&self.poly, a)
            && contains(&self.poly, b)
            && !(0..n).any(|i| segments_meet(a, b, self.poly[i], self.poly[(i + 1) % n]))
    }
}

impl NoFly {
    /// Parses the `no_fly` parameter block: the zones, the inclusion fences (`inside`) and the
    /// margin.
    fn from_params(v: &serde_json::Value) -> Result<(Polygons, Polygons, f64), String> {
        let Some(obj) = v.as_object() else { return Err("`no_fly` must be a mapping `{zones: […]}`".into()) };
        if let Some(k) = obj.keys().find(|k| !matches!(k.as_str(), "zones" | "inside" | "margin_m")) {
            return Err(format!("`no_fly`: unknown key `{k}`; expected `zones`, `inside`, `margin_m`"));
        }
        let margin = match obj.get("margin_m") {
            None => DEFAULT_NO_FLY_MARGIN_M,
            Some(m) => m
                .as_f64()
                .filter(|m| m.is_finite() && *m >= 0.0)
                .ok_or_else(|| format!("`no_fly.margin_m` must be a non-negative number of metres, found {m}"))?,
        };
        let polygons = |key: &str| -> Result<Polygons, String> {
            match obj.get(key) {
                None => Ok(Vec::new()),
                Some(v) => serde_json::from_value(v.clone())
                    .map_err(|e| format!("`no_fly.{key}` must be a list of polygons [[{{x, y}}, …], …]: {e}")),
            }
        };
        if !obj.contains_key("zones") && !obj.contains_key("inside") {
            return Err("`no_fly` needs `zones: [[{x, y}, …], …]` (and/or `inside: […]`, fences to stay in)".into());
        }
        Ok((polygons("zones")?, polygons("inside")?, margin))
    }

    fn new(polys: Polygons, fences: Polygons, margin: f64) -> Result<NoFly, String> {
        let zones = polys
            .into_iter()
            .enumerate()
            .map(|(i, p)| Zone::new(p, margin).map_err(|e| format!("no-fly zone {i}: {e}")))
            .collect::<Result<Vec<_>, _>>()?;
        // A fence's corners are pushed inward: the same construction with the margin negated.
        let fences = fences
            .into_iter()
            .enumerate()
            .map(|(i, p)| Zone::new(p, -margin).map_err(|e| format!("inclusion fence {i}: {e}")))
            .collect::<Result<Vec<_>, _>>()?;
        Ok(NoFly { zones, fences })
    }

    /// The zone containing `p`, if any.
    fn zone_containing(&self, p: Point2) -> Option<usize> {
        self.zones.iter().position(|z| contains(&z.poly, p))
    }

    /// Whether there are inclusion fences and `p` is outside all of them.
    fn outside_fences(&self, p: Point2) -> bool {
        !self.fences.is_empty() && !self.fences.iter().any(|f| contains(&f.poly, p))
    }

    /// The shortest polyline from `from` to `to` that crosses no zone (except zones `from` is
    /// already inside, which it may leave) and, with inclusion fences, stays inside one fence on
    /// every segment (a UAV outside every fence flies straight in on its first segment), as the
    /// points to fly through, `to` last. Shortest over the visibility graph of the zones'
    /// outward-pushed and the fences' inward-pushed corners. None: no route.
    fn route(&self, from: Point2, to: Point2) -> Option<VecDeque<Point2>> {
        let active: Vec<&Zone> = self.zones.iter().filter(|z| !contains(&z.poly, from)).collect();
        let from_outside = self.outside_fences(from);
        let fenced = |a: Point2, b: Point2| self.fences.is_empty() || self.fences.iter().any(|f| f.holds(a, b));
        // Node 0 is `from`: the segments leaving it are exempt from the fences when it is outside.
        let clear = |u: usize, a: Point2, b: Point2| {
            active.iter().all(|z| !z.blocks(a, b)) && ((u == 0 && from_outside) || fenced(a, b))
        };
        if clear(0, from, to) {
            return Some(VecDeque::from([to]));
        }
        let mut nodes = vec![from, to];
        nodes.extend(
            active
                .iter()
                .flat_map(|z| z.corners.iter().copied())
                .chain(self.fences.iter().flat_map(|f| f.corners.iter().copied()))
                .filter(|c| active.iter().all(|z| !contains(&z.poly, *c)) && !self.outside_fences(*c)),
        );
        // Dijkstra on the dense visibility graph (tens of nodes).
        let n = nodes.len();
        let mut dist = vec![f64::INFINITY; n];
        let mut prev = vec![usize::MAX; n];
        let mut done = vec![false; n];
        dist[0] = 0.0;
        loop {
            let next = (0..n).filter(|&i| !done[i] && dist[i].is_finite()).min_by(|&a, &b| dist[a].total_cmp(&dist[b]));
            let u = next?;
            if u == 1 {
                break;
            }
            done[u] = true;
            for v in 0..n {
                if done[v] || v == u {
                    continue;
                }
                let d = dist[u] + nodes[u].distance(nodes[v]);
                if d < dist[v] && clear(u, nodes[u], nodes[v]) {
                    dist[v] = d;
                    prev[v] = u;
                }
            }
        }
        let mut path = VecDeque::new();
        let mut at = 1;
        while at != 0 {
            path.push_front(nodes[at]);
            at = *prev.get(at)?;
        }
        Some(path)
    }
}

// ---------------------------------------------------------------------------------- follow_waypoints

const FOLLOW: &str = "follow_waypoints";

/// Where the waypoints come from.
enum Source {
    /// Known when the mission was built (literal list or plan file).
    Fixed(Arc<Vec<Point2>>),
    /// Read from the blackboard when the node starts.
    Port(Binding),
}

struct FollowWaypoints {
    source: Source,
    altitude: Binding,
    speed: Binding,
    radius: Binding,
    progress: Binding,
    resume_from: Binding,
    no_fly: Arc<NoFly>,
    /// Index of the waypoint flown to (mirrors `progress`).
    index: usize,
    /// Remaining points of the transfer to waypoint `route_to`.
    route: VecDeque<Point2>,
    route_to: Option<usize>,
    /// Where to rejoin the interrupted leg, read from `resume_from` on (re)start.
    rejoin: Option<Point2>,
    /// How many of `route`'s points lie on the leg itself (after the flight back to the point
    /// of interruption): only positions flown there are written to `resume_from`.
    leg_points: usize,
}

fn build_follow(p: &PortBindings) -> Result<Box<dyn Behavior<RobotRuntime>>, NodeError> {
    // Every port read first, so the registry's probe sees each name whatever the checks below
    // refuse.
    let (no_fly_binding, no_fly_literal) = (p.get("no_fly")?, p.literal("no_fly")?);
    let (waypoints, plan_file) = (p.get("waypoints")?, p.get("plan_file")?);
    let (altitude, speed, radius) = (p.get("altitude_m")?, p.get("speed_mps")?, p.get("arrive_radius_m")?);
    let (progress, resume_from) = (p.get("progress")?, p.get("resume_from")?);
    let mut polys = Vec::new();
    let mut fences = Vec::new();
    let mut margin = DEFAULT_NO_FLY_MARGIN_M;
    match (no_fly_binding, no_fly_literal) {
        (Binding::Unset, _) => {}
        (_, Some(BbValue::Params(v))) => {
            (polys, fences, margin) = NoFly::from_params(v).map_err(|e| NodeError::port("no_fly", e))?;
        }
        _ => {
            return Err(NodeError::port(
                "no_fly",
                "`no_fly` must be written in the mission as `{zones: [[{x, y}, …], …]}`",
            ));
        }
    }
    let source = match (waypoints, plan_file.clone()) {
        (Binding::Unset, Binding::Unset) => {
            return Err(NodeError::port(
                "waypoints",
                "no waypoints: give either `waypoints` (a list of points) or `plan_file` (a QGroundControl .plan)",
            ));
        }
        (Binding::Unset, Binding::Literal(BbValue::Str(path))) => {
            let plan = load_plan(Path::new(&*path), p.map_origin())
                .map_err(|e| NodeError::port("plan_file", e.to_string()))?;
            if plan.waypoints.is_empty() {
                return Err(NodeError::port(
                    "plan_file",
                    format!("QGroundControl plan `{path}` has no waypoints to fly"),
                ));
            }
            polys.extend(plan.no_fly);
            fences.extend(plan.fly_inside);
            Source::Fixed(Arc::new(plan.waypoints.iter().map(|w| w.position).collect()))
        }
        (Binding::Unset, _) => {
            return Err(NodeError::port(
                "plan_file",
                "`plan_file` must be a path written in the mission (not a blackboard entry), so the plan is checked when the mission is built",
            ));
        }
        (Binding::Literal(BbValue::Points(w)), Binding::Unset) => Source::Fixed(w),
        (b, Binding::Unset) => Source::Port(b),
        (_, _) => return Err(NodeError::port("plan_file", "give either `waypoints` or `plan_file`, not both")),
    };
    let no_fly = NoFly::new(polys, fences, margin).map_err(|e| NodeError::port("no_fly", e))?;
    if let Source::Fixed(w) = &source {
        // Name the plan the waypoints and fences came from, so the operator knows which file.
        let (port, from) = match &plan_file {
            Binding::Literal(BbValue::Str(path)) => ("plan_file", format!("QGroundControl plan `{path}`: ")),
            _ => ("waypoints", String::new()),
        };
        for (i, wp) in w.iter().enumerate() {
            if !(wp.x.is_finite() && wp.y.is_finite()) {
                return Err(NodeError::port(port, format!("{from}waypoint {i} is not finite")));
            }
            if let Some(z) = no_fly.zone_containing(*wp) {
                return Err(NodeError::port(
                    port,
                    format!("{from}waypoint {i} at ({:.1}, {:.1}) lies inside no-fly zone {z}", wp.x, wp.y),
                ));
            }
            if no_fly.outside_fences(*wp) {
                return Err(NodeError::port(
                    port,
                    format!(
                        "{from}waypoint {i} at ({:.1}, {:.1}) lies outside the inclusion geofence (fly only inside)",
                        wp.x, wp.y
                    ),
                ));
            }
        }
    }
    literal_number(p, "altitude_m", false)?;
    literal_number(p, "speed_mps", true)?;
    literal_number(p, "arrive_radius_m", true)?;
    Ok(Box::new(FollowWaypoints {
        source,
        altitude,
        speed,
        radius,
        progress,
        resume_from,
        no_fly: Arc::new(no_fly),
        index: 0,
        route: VecDeque::new(),
        route_to: None,
        rejoin: None,
        leg_points: 0,
    }))
}

impl FollowWaypoints {
    /// The route from `here` to `goal` and how many of its points lie on the leg itself: back to
    /// where the leg was interrupted first, when that point is known, clear of the zones and
    /// reachable; else straight on to the waypoint. `None`: no route to the waypoint.
    fn plan_leg(&mut self, no_fly: &NoFly, here: Point2, goal: Point2) -> Option<(VecDeque<Point2>, usize)> {
        let rejoin = self.rejoin.take().filter(|r| no_fly.zone_containing(*r).is_none());
        if let Some((mut back, leg)) = rejoin.and_then(|r| Some((no_fly.route(here, r)?, no_fly.route(r, goal)?))) {
            let on_leg = leg.len();
            back.extend(leg);
            return Some((back, on_leg));
        }
        no_fly.route(here, goal).map(|leg| {
            let on_leg = leg.len();
            (leg, on_leg)
        })
    }
}

impl Behavior<RobotRuntime> for FollowWaypoints {
    fn tick(&mut self, prev: Status, ctx: &mut Ctx<'_>) -> Status {
        let waypoints = match &self.source {
            Source::Fixed(w) => w.clone(),
            Source::Port(b) => match b.get::<Arc<Vec<Point2>>>(ctx.blackboard) {
                Some(w) => w,
                None => {
                    ctx.blackboard.report(format!("{FOLLOW}: no list on its `waypoints` port"));
                    return Status::Failure;
                }
            },
        };
        let Some((altitude_m, speed_mps)) = flight_params(&self.altitude, &self.speed, ctx, FOLLOW) else {
            return Status::Failure;
        };
        let Some(radius) = number(&self.radius, ctx, FOLLOW, "arrive_radius_m", true) else { return Status::Failure };
        if prev != Status::Running {
            self.route_to = None;
            match self.progress.get::<i64>(ctx.blackboard) {
                Some(i) if i < 0 => {
                    ctx.blackboard.report(format!("{FOLLOW}: `progress` is {i}; starting from waypoint 0"));
                    self.index = 0;
                }
                Some(i) => self.index = usize::try_from(i).unwrap_or(usize::MAX),
                None => {} // not written yet: continue from this node's own count
            }
            self.rejoin = self.resume_from.get::<Point2>(ctx.blackboard).filter(|p| p.x.is_finite() && p.y.is_finite());
        }
        let no_fly = self.no_fly.clone();
        let mut reports = Vec::new();
        let rt = &mut *ctx.env;
        let here = rt.pose().map(|p| p.pose.position());
        let status = loop {
            let Some(&goal) = waypoints.get(self.index) else { break Status::Success };
            if self.route_to != Some(self.index) {
                if let Some(z) = no_fly.zone_containing(goal) {
                    reports.push(format!("{FOLLOW}: waypoint {} lies inside no-fly zone {z}; skipped", self.index));
                    self.index += 1;
                    continue;
                }
                if no_fly.outside_fences(goal) {
                    reports.push(format!(
                        "{FOLLOW}: waypoint {} lies outside the inclusion geofence; skipped",
                        self.index
                    ));
                    self.index += 1;
                    continue;
                }
                match here {
                    // No pose yet: head for the waypoint; route once the pose is known.
                    None => {
                        self.route = VecDeque::from([goal]);
                        self.leg_points = 1;
                    }
                    Some(h) => match self.plan_leg(&no_fly, h, goal) {
                        Some((route, leg_points)) => {
                            self.route = route;
                            self.leg_points = leg_points;
                            self.route_to = Some(self.index);
                        }
                        None => {
                            reports.push(format!(
                                "{FOLLOW}: no route around the no-fly zones to waypoint {}; skipped",
                                self.index
                            ));
                            self.index += 1;
                            continue;
                        }
                    },
                }
            }
            if let Some(h) = here {
                while self.route.front().is_some_and(|p| p.distance(h) <= radius) {
                    self.route.pop_front();
                }
            }
            match self.route.front() {
                Some(&target) => {
                    rt.command_flight(FlightCommand { target, altitude_m, speed_mps });
                    if let Some(h) = here
                        && self.route.len() <= self.leg_points
                    {
                        self.resume_from.set(ctx.blackboard, BbValue::Point(h));
                    }
                    break Status::Running;
                }
                None => {
                    self.index += 1;
                    self.route_to = None;
                }
            }
        };
        for r in reports {
            ctx.blackboard.report(r);
        }
        self.progress.set(ctx.blackboard, BbValue::Int(i64::try_from(self.index).unwrap_or(i64::MAX)));
        status
    }

    fn halt(&mut self, ctx: &mut Ctx<'_>) {
        self.route_to = None;
        stop_flying(ctx);
    }
}

// ---------------------------------------------------------------------------------- seek_robot

const SEEK: &str = "seek_robot";

struct SeekRobot {
    stale: Binding,
    radius: Binding,
    speed: Binding,
    altitude: Binding,
    candidates: Binding,
    alive_within: Binding,
    target: Binding,
    /// Last robot picked (round-robin memory when `target` is not a blackboard entry).
    last: Option<RobotId>,
    /// Robot sought in the current activation.
    current: Option<RobotId>,
}

fn build_seek(p: &PortBindings) -> Result<Box<dyn Behavior<RobotRuntime>>, NodeError> {
    literal_number(p, "stale_after_s", true)?;
    literal_number(p, "arrive_radius_m", true)?;
    literal_number(p, "speed_mps", true)?;
    literal_number(p, "altitude_m", false)?;
    literal_number(p, "alive_within_s", true)?;
    Ok(Box::new(SeekRobot {
        stale: p.get("stale_after_s")?,
        radius: p.get("arrive_radius_m")?,
        speed: p.get("speed_mps")?,
        altitude: p.get("altitude_m")?,
        candidates: p.get("candidates")?,
        alive_within: p.get("alive_within_s")?,
        target: p.get("target")?,
        last: None,
        current: None,
    }))
}

fn parse_ids(s: &str) -> Vec<RobotId> {
    s.split(|c: char| c == ',' || c.is_whitespace()).filter(|t| !t.is_empty()).map(RobotId::new).collect()
}

impl SeekRobot {
    /// The next robot round-robin after the last one, among those eligible now.
    fn pick(&mut self, ctx: &mut Ctx<'_>) -> Option<RobotId> {
        let now = ctx.now;
        let last = self.target.get::<RobotId>(ctx.blackboard).or_else(|| self.last.clone());
        let only: Option<Vec<RobotId>> = self.candidates.get::<Arc<str>>(ctx.blackboard).map(|s| parse_ids(&s));
        let alive_within = match self.alive_within {
            Binding::Unset => None,
            ref b => Some(number(b, ctx, SEEK, "alive_within_s", true)?),
        };
        let rt = &*ctx.env;
        let me = rt.id();
        let mut eligible: Vec<RobotId> = rt
            .team()
            .robots()
            .into_iter()
            .filter(|(id, s)| *id != me && (s.pose.is_some() || s.path_end.is_some()))
            .filter(|(id, _)| only.as_ref().is_none_or(|l| l.contains(id)))
            .filter(|(_, s)| alive_within.is_none_or(|w| s.pose.is_some() && now.secs_since(s.stamp) <= w))
            .map(|(id, _)| id.clone())
            .collect();
        eligible.sort();
        let pick = eligible.iter().find(|id| last.as_ref().is_none_or(|l| *id > l)).or(eligible.first()).cloned();
        if pick.is_none() {
            ctx.blackboard.report(format!("{SEEK}: no robot to seek: the team state knows no other eligible robot"));
        }
        pick
    }
}

impl Behavior<RobotRuntime> for SeekRobot {
    fn tick(&mut self, prev: Status, ctx: &mut Ctx<'_>) -> Status {
        let now = ctx.now;
        let Some((altitude_m, speed_mps)) = flight_params(&self.altitude, &self.speed, ctx, SEEK) else {
            return Status::Failure;
        };
        let Some(stale) = number(&self.stale, ctx, SEEK, "stale_after_s", true) else { return Status::Failure };
        let Some(radius) = number(&self.radius, ctx, SEEK, "arrive_radius_m", true) else { return Status::Failure };
        if prev != Status::Running || self.current.is_none() {
            let Some(pick) = self.pick(ctx) else { return Status::Failure };
            self.target.set(ctx.blackboard, BbValue::Robot(pick.clone()));
            self.last = Some(pick.clone());
            self.current = Some(pick);
        }
        let Some(id) = self.current.clone() else { return Status::Failure };
        let rt = &mut *ctx.env;
        let aim = rt.team().robot_status(&id).and_then(|s| match (s.pose, s.path_end) {
            (Some(p), None) => Some(p.position()),
            (Some(p), Some(_)) if now.secs_since(s.stamp) <= stale => Some(p.position()),
            (_, end) => end,
        });
        let Some(aim) = aim else {
            ctx.blackboard.report(format!("{SEEK}: the team state has no position of `{id}`"));
            return Status::Failure;
        };
        if rt.pose().is_some_and(|p| p.pose.position().distance(aim) <= radius) {
            return Status::Success;
        }
        rt.command_flight(FlightCommand { target: aim, altitude_m, speed_mps });
        Status::Running
    }

    fn halt(&mut self, ctx: &mut Ctx<'_>) {
        self.current = None;
        stop_flying(ctx);
    }

    fn reset(&mut self) {
        self.current = None;
    }
}

// ---------------------------------------------------------------------------------- wait_for_sync

const WAIT: &str = "wait_for_sync";

struct WaitForSync {
    robot: Binding,
    timeout: Binding,
    track: Binding,
    speed: Binding,
    altitude: Binding,
    started: Time,
    /// The team state reported the sync incomplete at some tick of this wait.
    saw_incomplete: bool,
}

fn build_wait(p: &PortBindings) -> Result<Box<dyn Behavior<RobotRuntime>>, NodeError> {
    literal_number(p, "timeout_s", true)?;
    literal_number(p, "speed_mps", true)?;
    literal_number(p, "altitude_m", false)?;
    Ok(Box::new(WaitForSync {
        robot: p.get("robot")?,
        timeout: p.get("timeout_s")?,
        track: p.get("track")?,
        speed: p.get("speed_mps")?,
        altitude: p.get("altitude_m")?,
        started: Time::ZERO,
        saw_incomplete: false,
    }))
}

impl Behavior<RobotRuntime> for WaitForSync {
    fn tick(&mut self, prev: Status, ctx: &mut Ctx<'_>) -> Status {
        let now = ctx.now;
        let Some(robot) = self.robot.get::<RobotId>(ctx.blackboard) else {
            ctx.blackboard.report(format!("{WAIT}: no robot on its `robot` port"));
            return Status::Failure;
        };
        let Some(timeout) = number(&self.timeout, ctx, WAIT, "timeout_s", true) else { return Status::Failure };
        let Some((altitude_m, speed_mps)) = flight_params(&self.altitude, &self.speed, ctx, WAIT) else {
            return Status::Failure;
        };
        // Always bound (the declared default when the mission leaves it out).
        let Some(track) = self.track.get::<bool>(ctx.blackboard) else {
            ctx.blackboard.report(format!("{WAIT}: no value on its `track` port"));
            return Status::Failure;
        };
        if prev != Status::Running {
            self.started = now;
            self.saw_incomplete = false;
        }
        let started = self.started;
        let rt = &mut *ctx.env;
        if &robot == rt.id() {
            ctx.blackboard.report(format!("{WAIT}: `{robot}` is this robot"));
            return Status::Failure;
        }
        let complete = rt.team().sync_complete_with(&robot);
        let pose = rt.team().robot_pose(&robot);
        // A completion reported before the wait began may be stale: require that it completed
        // during the wait, or that the peer's state reached us during the wait.
        let fresh = self.saw_incomplete || pose.is_some_and(|(_, stamp)| stamp >= started);
        if complete && fresh {
            return Status::Success;
        }
        self.saw_incomplete |= !complete;
        if now.secs_since(started) >= timeout {
            return Status::Failure;
        }
        if track && let Some((p, _)) = pose {
            rt.command_flight(FlightCommand { target: p.position(), altitude_m, speed_mps });
        }
        Status::Running
    }

    fn halt(&mut self, ctx: &mut Ctx<'_>) {
        stop_flying(ctx);
    }
}
