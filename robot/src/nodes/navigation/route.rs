//! Route geometry: a global path prepared for following, pure pursuit, the edge under the robot.

#[allow(clippy::wildcard_imports)]
use super::*;

/// A global path prepared for following: cumulative lengths and the robot's progress on it.
pub(super) struct Route {
    /// The planner's path (`None`: local-only, the straight line to the target).
    pub(super) path: Option<GlobalPath>,
    pub(super) points: Vec<Point2>,
    pub(super) cumulative: Vec<f64>,
    /// Segment of the last look-ahead point.
    pub(super) segment: usize,
    /// Arc length of the last look-ahead point.
    pub(super) reached: f64,
}

impl Route {
    pub(super) fn new(path: Option<GlobalPath>, from: Point2, target: Point2) -> Self {
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

    pub(super) fn length(&self) -> f64 {
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
    pub(super) fn pursue(
        &mut self,
        p: Point2,
        lookahead_m: f64,
        steps: impl Fn(Point2, Point2, f64) -> bool,
    ) -> (Point2, f64) {
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
    pub(super) fn nodes_around(&self, s: f64) -> (Option<NodeId>, Option<NodeId>) {
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

    /// Arc length of the point of the route nearest `p`, among the segments up to the
    /// look-ahead point's (the stretch the robot has been driving; ties go to the later point).
    pub(super) fn project(&self, p: Point2) -> f64 {
        let n = self.points.len();
        if n < 2 {
            return 0.0;
        }
        let mut best = (f64::INFINITY, 0.0);
        for i in 0..=self.segment.min(n - 2) {
            let (a, b) = (self.points[i], self.points[i + 1]);
            let d = b - a;
            let dd = d.dot(d);
            let t = if dd > 1e-12 { ((p - a).dot(d) / dd).clamp(0.0, 1.0) } else { 0.0 };
            let s = (self.cumulative[i] + t * (self.cumulative[i + 1] - self.cumulative[i])).min(self.reached.max(0.0));
            let gap = self.point_at_from(i, s).distance(p);
            if gap <= best.0 {
                best = (gap, s);
            }
        }
        best.1
    }

    /// The point at arc length `s` on segment `i` or later.
    fn point_at_from(&self, i: usize, s: f64) -> Point2 {
        let n = self.points.len();
        let mut i = i.min(n - 2);
        while i + 2 < n && self.cumulative[i + 1] < s {
            i += 1;
        }
        let len = self.cumulative[i + 1] - self.cumulative[i];
        let t = if len > 1e-12 { ((s - self.cumulative[i]) / len).clamp(0.0, 1.0) } else { 1.0 };
        let (a, b) = (self.points[i], self.points[i + 1]);
        a + (b - a) * t
    }

    /// The look-ahead point and the waypoints after it up to (not including) the first
    /// waypoint of `node` from there on: the rest of the way to that node, which a replan from
    /// the node keeps. Empty when `node` is not ahead on the path or is the next waypoint.
    pub(super) fn points_before(&self, node: Option<NodeId>) -> Vec<Point2> {
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
    pub(super) fn point_at(&self, s: f64) -> Point2 {
        if self.points.len() < 2 {
            return self.points.first().copied().unwrap_or_default();
        }
        self.point_at_from(self.segment, s)
    }
}
