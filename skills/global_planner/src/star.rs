//! The star-shaped safe region of a reachability scan S(φ) and the paper's edge test against it
//! (paper §Updating Graph with Experience).

use spomp_core::{Point2, ReachabilityScan, normalize_angle};

use crate::error::ScanError;
use crate::teammates::BinFan;

/// Bins beyond a segment's own arc whose chords are still tested ([`StarRegion::chords_facing`]).
const CHORD_MARGIN_BINS: usize = 2;
/// A segment passing this close to the region's origin is tested against every chord: its arc
/// seen from the origin approaches half a turn.
const NEAR_ORIGIN_M: f64 = 0.01;

/// What one scan says about one edge.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum EdgeObservation {
    /// Both ends inside the safe region and no crossing of its boundary.
    Trav,
    /// A single crossing of the boundary where no bin within Δφ is unknown.
    NotTrav,
    /// Anything else: both ends outside, several crossings, or unknown bins near the crossing.
    UnkTrav,
}

/// A scan's judgement of one edge: the observation, and for not_trav whether the boundary the
/// edge crosses is a teammate's body ([`StarRegion::mark_teammates`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct Verdict {
    pub obs: EdgeObservation,
    /// Not_trav only because a teammate stands there: the edge may be marked, never removed.
    pub at_teammate: bool,
}

impl Verdict {
    fn plain(obs: EdgeObservation) -> Self {
        Verdict { obs, at_teammate: false }
    }
}

/// How edges are judged against a scan's safe region.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Judging {
    /// Δφ: half-width of the window around a single crossing searched for unknown bins.
    pub window_rad: f64,
    /// Within this distance of the robot an edge is judged from the robot (see
    /// [`StarRegion::classify_polyline`]); 0 turns that off.
    pub on_edge_radius_m: f64,
    /// A single crossing nearer to the robot than this counts as unknown.
    pub min_crossing_range_m: f64,
}

/// A scan's safe region: the polygon through the end points of the bins, star-shaped around the
/// robot.
#[derive(Debug, Clone, Default)]
pub(crate) struct StarRegion {
    pub origin: Point2,
    yaw: f64,
    bin_step_rad: f64,
    pub range_m: Vec<f64>,
    pub obstacle: Vec<bool>,
    ends: Vec<Point2>,
    /// Bins whose obstacle is a ground teammate (empty when none is).
    at_teammate: Vec<bool>,
    pub max_range_m: f64,
}

impl StarRegion {
    /// The region of a scan; ranges that are not finite or negative count as 0 (unknown), and
    /// ranges are clipped to `max_range_m`.
    #[cfg(test)]
    pub fn from_scan(scan: &ReachabilityScan, max_range_m: f64) -> Result<Self, ScanError> {
        let mut region = StarRegion::default();
        region.load(scan, max_range_m)?;
        Ok(region)
    }

    /// Makes this the region of `scan`, reusing the buffers (see [`StarRegion::from_scan`]).
    pub fn load(&mut self, scan: &ReachabilityScan, max_range_m: f64) -> Result<(), ScanError> {
        if scan.range_m.is_empty() {
            return Err(ScanError::Empty);
        }
        if scan.range_m.len() != scan.obstacle.len() {
            return Err(ScanError::LengthMismatch { ranges: scan.range_m.len(), obstacle: scan.obstacle.len() });
        }
        let p = scan.pose;
        if !(p.x.is_finite() && p.y.is_finite() && p.yaw.is_finite()) {
            return Err(ScanError::NonFinitePose);
        }
        let cap = if max_range_m.is_finite() && max_range_m > 0.0 { max_range_m } else { 30.0 };
        let n = scan.range_m.len();
        self.origin = p.position();
        self.yaw = p.yaw;
        self.bin_step_rad = std::f64::consts::TAU / n as f64;
        self.range_m.clear();
        self.obstacle.clear();
        self.ends.clear();
        self.at_teammate.clear();
        for (b, (&r, &o)) in scan.range_m.iter().zip(&scan.obstacle).enumerate() {
            let r = r as f64;
            let (range, obstacle) = if r.is_finite() && r >= 0.0 { (r.min(cap), o && r <= cap) } else { (0.0, false) };
            self.range_m.push(range);
            self.obstacle.push(obstacle);
            let a = p.yaw - b as f64 * self.bin_step_rad;
            self.ends.push(Point2::new(self.origin.x + range * a.cos(), self.origin.y + range * a.sin()));
        }
        self.max_range_m = self.range_m.iter().copied().fold(0.0, f64::max);
        Ok(())
    }

    fn bins(&self) -> usize {
        self.range_m.len()
    }

    /// Marks the bins whose obstacle end point lies within `clearance_m` of one of `teammates`
    /// (their last known positions, map frame): an edge crossing the boundary between such a
    /// bin and its neighbour is blocked by a teammate, not by terrain. Returns how many bins.
    pub fn mark_teammates(&mut self, teammates: &[Point2], clearance_m: f64) -> usize {
        self.at_teammate.clear();
        let n = self.bins();
        let fan = BinFan { origin: self.origin, yaw: self.yaw, bins: n };
        let (ends, obstacle, marks) = (&self.ends, &self.obstacle, &mut self.at_teammate);
        let mut count = 0;
        fan.for_each_ending_at(
            |b| obstacle[b].then(|| ends[b]),
            self.max_range_m,
            teammates,
            clearance_m,
            |b| {
                // Sized on the first mark: a scan with no teammate in it keeps the buffer empty.
                marks.resize(n, false);
                marks[b] = true;
                count += 1;
            },
        );
        count
    }

    /// Whether bin `b` ends at a teammate.
    fn bin_at_teammate(&self, b: usize) -> bool {
        self.at_teammate.get(b).copied().unwrap_or(false)
    }

    /// Fractional bin position of the direction towards `p`, in [0, bins).
    pub fn bin_position(&self, p: Point2) -> f64 {
        let d = p - self.origin;
        let a = (self.yaw - d.angle()).rem_euclid(std::f64::consts::TAU);
        (a / self.bin_step_rad).min(self.bins() as f64 - 1e-9).max(0.0)
    }

    /// Whether `p` lies inside the safe polygon.
    pub fn contains(&self, p: Point2) -> bool {
        let n = self.bins();
        let dist = p.distance(self.origin);
        if dist > self.max_range_m {
            return false;
        }
        let u = self.bin_position(p);
        let b = (u.floor() as usize).min(n - 1);
        let b2 = (b + 1) % n;
        let (e1, e2) = (self.ends[b], self.ends[b2]);
        let chord = e2 - e1;
        let side_origin = chord.cross(self.origin - e1);
        let side_p = chord.cross(p - e1);
        if side_origin.abs() < 1e-12 {
            // Degenerate sector (a zero range, or a single bin): fall back to polar interpolation.
            let f = u - u.floor();
            return dist <= self.range_m[b] * (1.0 - f) + self.range_m[b2] * f;
        }
        side_p * side_origin >= 0.0
    }

    /// The paper's classification of the segment `a`–`b` against this region.
    #[cfg(test)]
    pub fn classify(&self, a: Point2, b: Point2, window_rad: f64) -> EdgeObservation {
        self.classify_path(&[a, b], &Judging { window_rad, on_edge_radius_m: 0.0, min_crossing_range_m: 0.0 }).obs
    }

    /// The paper's classification of an edge, as the polyline `points` (two points for a
    /// straight edge; more for an edge routed around elevation steps), against this region:
    /// its boundary crossings are counted along every piece. One addition to the paper: a
    /// single crossing nearer to the robot than `min_crossing_range_m` is unknown, since so near
    /// the boundary is the robot's own clearance from an obstacle beside it (the bins there end
    /// at the inflation margin, whatever lies along the edge), as at the foot of a ramp beside
    /// the curb's corner.
    fn classify_path(&self, points: &[Point2], judging: &Judging) -> Verdict {
        self.classify_path_among(points, judging, false)
    }

    /// [`Self::classify_path`], testing each segment against the chords it faces or, with
    /// `every_chord`, against all of them (the same verdict: a test compares the two).
    fn classify_path_among(&self, points: &[Point2], judging: &Judging, every_chord: bool) -> Verdict {
        let unknown = Verdict::plain(EdgeObservation::UnkTrav);
        let (Some(&first), Some(&last)) = (points.first(), points.last()) else {
            return unknown;
        };
        if polyline_point_distance(points, self.origin) > self.max_range_m {
            return unknown;
        }
        let n = self.bins();
        let mut crossings = 0usize;
        let mut crossing = first;
        let mut chord = 0;
        for piece in points.windows(2) {
            let (a, b) = (piece[0], piece[1]);
            let clearance = segment_point_distance(a, b, self.origin);
            if clearance > self.max_range_m {
                continue;
            }
            for j in self.chords_facing(a, b, clearance, every_chord) {
                let (c, d) = (self.ends[j], self.ends[(j + 1) % n]);
                if let Some(p) = segment_intersection(a, b, c, d) {
                    crossings += 1;
                    crossing = p;
                    chord = j;
                    if crossings > 1 {
                        return unknown;
                    }
                }
            }
        }
        match crossings {
            0 if self.contains(first) && self.contains(last) => Verdict::plain(EdgeObservation::Trav),
            0 => unknown,
            _ if crossing.distance(self.origin) < judging.min_crossing_range_m => unknown,
            _ if self.unknown_near(crossing, judging.window_rad) => unknown,
            _ => Verdict {
                obs: EdgeObservation::NotTrav,
                at_teammate: self.bin_at_teammate(chord) || self.bin_at_teammate((chord + 1) % n),
            },
        }
    }

    /// The boundary chords a segment `a`–`b` (passing `clearance` metres from the origin) may
    /// cross, in bin order: chord j joins the ends of bins j and j + 1, so it lies within their
    /// wedge, and a segment that keeps clear of the origin sweeps the shorter arc between the
    /// bins of its ends. Those bins with a margin of [`CHORD_MARGIN_BINS`] on each side (for the
    /// rounding of the bin positions); every chord when the segment passes within
    /// [`NEAR_ORIGIN_M`] of the origin or the arc is wide.
    fn chords_facing(&self, a: Point2, b: Point2, clearance: f64, every_chord: bool) -> impl Iterator<Item = usize> {
        let n = self.bins();
        let every = (0, n);
        let (first, count) = if every_chord || n <= 4 * CHORD_MARGIN_BINS || clearance < NEAR_ORIGIN_M {
            every
        } else {
            let (ua, ub) = (self.bin_position(a), self.bin_position(b));
            // The arc from the lower bin position to the higher, or round the other way when
            // that is the shorter.
            let (low, high) = if ua <= ub { (ua, ub) } else { (ub, ua) };
            let (from, span) =
                if high - low <= n as f64 / 2.0 { (low, high - low) } else { (high, n as f64 - (high - low)) };
            let count = span.floor() as usize + 1 + 2 * CHORD_MARGIN_BINS;
            if count >= n {
                every
            } else {
                let start = from.floor() as usize + n - CHORD_MARGIN_BINS;
                (start % n, count)
            }
        };
        (first..first + count).map(move |k| k % n)
    }

    /// Judges the edge `a`–`b` as [`StarRegion::classify_polyline`] does.
    #[cfg(test)]
    pub fn classify_edge(&self, a: Point2, b: Point2, window_rad: f64, on_edge_radius_m: f64) -> EdgeObservation {
        self.classify_polyline(&[a, b], &Judging { window_rad, on_edge_radius_m, min_crossing_range_m: 0.0 }).obs
    }

    /// Judges the edge `points` (its ends and any interior vertices) as the paper does, except
    /// when the region's origin (the robot) is on the edge: within `on_edge_radius_m` of it,
    /// with its closest point `q` on the edge inside the safe region. Then the parts from `q`
    /// to either end are judged each: not traversable when one of them is (the robot can reach
    /// `q`, so the edge is blocked beyond it), traversable when both are, unknown otherwise.
    /// This is how the edge a robot is driving gets judged from where the robot is, when the
    /// safe region (≈ 5 m on flat ground) is much shorter than the edge. A not_trav edge is at a
    /// teammate when every not_trav part of it crosses the boundary at one.
    pub fn classify_polyline(&self, points: &[Point2], judging: &Judging) -> Verdict {
        if judging.on_edge_radius_m > 0.0 && points.len() >= 2 {
            let (piece, q) = closest_on_polyline(points, self.origin);
            if q.distance(self.origin) <= judging.on_edge_radius_m && self.contains(q) {
                let mut towards_a = Vec::with_capacity(piece + 2);
                towards_a.push(q);
                towards_a.extend(points[..=piece].iter().rev().copied());
                let mut towards_b = Vec::with_capacity(points.len() - piece);
                towards_b.push(q);
                towards_b.extend_from_slice(&points[piece + 1..]);
                let halves = [self.classify_path(&towards_a, judging), self.classify_path(&towards_b, judging)];
                let mut blocked = halves.iter().filter(|v| v.obs == EdgeObservation::NotTrav).peekable();
                if blocked.peek().is_some() {
                    return Verdict { obs: EdgeObservation::NotTrav, at_teammate: blocked.all(|v| v.at_teammate) };
                }
                let both_trav = halves.iter().all(|v| v.obs == EdgeObservation::Trav);
                return Verdict::plain(if both_trav { EdgeObservation::Trav } else { EdgeObservation::UnkTrav });
            }
        }
        self.classify_path(points, judging)
    }

    /// Whether a bin within `window_rad` of the direction towards `p` ends in the unknown.
    fn unknown_near(&self, p: Point2, window_rad: f64) -> bool {
        let n = self.bins();
        let u = self.bin_position(p);
        let reach = (window_rad.abs() / self.bin_step_rad).ceil() as i64 + 1;
        let centre = u.round() as i64;
        for k in centre - reach..=centre + reach {
            let bin = k.rem_euclid(n as i64) as usize;
            let diff = normalize_angle((k as f64 - u) * self.bin_step_rad).abs();
            if diff <= window_rad && !self.obstacle[bin] {
                return true;
            }
        }
        false
    }
}

/// The point of the segment `a`–`b` closest to `p`.
fn closest_on_segment(a: Point2, b: Point2, p: Point2) -> Point2 {
    let ab = b - a;
    let len2 = ab.dot(ab);
    if len2 <= 0.0 {
        return a;
    }
    let t = ((p - a).dot(ab) / len2).clamp(0.0, 1.0);
    a + ab * t
}

/// Distance from `p` to the segment `a`–`b`.
pub(crate) fn segment_point_distance(a: Point2, b: Point2, p: Point2) -> f64 {
    p.distance(closest_on_segment(a, b, p))
}

/// The piece (index of its first vertex) and the point of the polyline `points` (at least two)
/// closest to `p`.
fn closest_on_polyline(points: &[Point2], p: Point2) -> (usize, Point2) {
    let mut best = (0, points[0], f64::INFINITY);
    for (k, w) in points.windows(2).enumerate() {
        let q = closest_on_segment(w[0], w[1], p);
        let d = q.distance(p);
        if d < best.2 {
            best = (k, q, d);
        }
    }
    (best.0, best.1)
}

/// Distance from `p` to the polyline `points` (infinite when empty).
pub(crate) fn polyline_point_distance(points: &[Point2], p: Point2) -> f64 {
    match points {
        [] => f64::INFINITY,
        [only] => only.distance(p),
        _ => closest_on_polyline(points, p).1.distance(p),
    }
}

/// Intersection of segment `a`–`b` (closed) with `c`–`d` (half-open: `d` excluded, so a crossing
/// through a polygon vertex counts once).
fn segment_intersection(a: Point2, b: Point2, c: Point2, d: Point2) -> Option<Point2> {
    let r = b - a;
    let s = d - c;
    let denom = r.cross(s);
    if denom.abs() < 1e-12 {
        return None;
    }
    let ca = c - a;
    let t = ca.cross(s) / denom;
    let u = ca.cross(r) / denom;
    ((0.0..=1.0).contains(&t) && (0.0..1.0).contains(&u)).then(|| a + r * t)
}

#[cfg(test)]
mod tests {
    use super::*;
    use spomp_core::{Pose2, RobotId, Time};

    pub(crate) fn scan(pose: Pose2, range: Vec<f32>, obstacle: Vec<bool>) -> ReachabilityScan {
        ReachabilityScan { robot: RobotId::new("ugv1"), stamp: Time::ZERO, pose, range_m: range, obstacle }
    }

    fn circle(n: usize, r: f32, obstacle: bool) -> ReachabilityScan {
        scan(Pose2::new(0.0, 0.0, 0.0), vec![r; n], vec![obstacle; n])
    }

    #[test]
    fn inside_and_outside_a_disc() {
        let s = StarRegion::from_scan(&circle(360, 10.0, true), 30.0).unwrap();
        assert!(s.contains(Point2::new(3.0, 4.0)));
        assert!(s.contains(Point2::new(-9.9, 0.0)));
        assert!(!s.contains(Point2::new(7.5, 7.5)));
    }

    #[test]
    fn paper_cases() {
        let w = 0.3;
        let wall = StarRegion::from_scan(&circle(360, 10.0, true), 30.0).unwrap();
        assert_eq!(wall.classify(Point2::new(-5.0, 0.0), Point2::new(5.0, 1.0), w), EdgeObservation::Trav);
        assert_eq!(wall.classify(Point2::new(0.0, 0.0), Point2::new(20.0, 0.0), w), EdgeObservation::NotTrav);
        assert_eq!(
            wall.classify(Point2::new(-20.0, 0.5), Point2::new(20.0, 0.5), w),
            EdgeObservation::UnkTrav,
            "two crossings"
        );
        assert_eq!(
            wall.classify(Point2::new(20.0, 0.0), Point2::new(20.0, 15.0), w),
            EdgeObservation::UnkTrav,
            "outside"
        );
        let open = StarRegion::from_scan(&circle(360, 10.0, false), 30.0).unwrap();
        assert_eq!(
            open.classify(Point2::new(0.0, 0.0), Point2::new(20.0, 0.0), w),
            EdgeObservation::UnkTrav,
            "ends in unknown"
        );
    }

    #[test]
    fn unknown_bin_within_window_makes_a_crossing_unknown() {
        // Obstacles everywhere except bins around azimuth −0.2 rad (bin index grows clockwise).
        let n = 360;
        let mut obstacle = vec![true; n];
        let unknown_bin = 11; // ≈ −0.19 rad
        obstacle[unknown_bin] = false;
        let s = StarRegion::from_scan(&scan(Pose2::new(0.0, 0.0, 0.0), vec![10.0; n], obstacle), 30.0).unwrap();
        assert_eq!(s.classify(Point2::new(0.0, 0.0), Point2::new(20.0, 0.0), 0.3), EdgeObservation::UnkTrav);
        assert_eq!(s.classify(Point2::new(0.0, 0.0), Point2::new(0.0, 20.0), 0.3), EdgeObservation::NotTrav);
        assert_eq!(s.classify(Point2::new(0.0, 0.0), Point2::new(20.0, 0.0), 0.1), EdgeObservation::NotTrav);
    }

    #[test]
    fn an_edge_under_the_robot_is_judged_from_the_robot() {
        let w = 0.3;
        // A 6 m safe disc ending at a wall all round: the robot at the origin drives a 30 m edge
        // from (−15, 0) to (15, 0), both ends far outside the region.
        let wall = StarRegion::from_scan(&circle(360, 6.0, true), 30.0).unwrap();
        let (a, b) = (Point2::new(-15.0, 0.5), Point2::new(15.0, 0.5));
        assert_eq!(wall.classify(a, b, w), EdgeObservation::UnkTrav, "the paper's rule: two crossings");
        assert_eq!(wall.classify_edge(a, b, w, 3.0), EdgeObservation::NotTrav, "blocked ahead of the robot");
        assert_eq!(wall.classify_edge(a, b, w, 0.0), EdgeObservation::UnkTrav, "rule switched off");
        // An open road ahead (unknown beyond the region): nothing is learnt.
        let open = StarRegion::from_scan(&circle(360, 6.0, false), 30.0).unwrap();
        assert_eq!(open.classify_edge(a, b, w, 3.0), EdgeObservation::UnkTrav);
        // A short edge through the robot inside the region is traversable either way.
        let (c, d) = (Point2::new(-4.0, 1.0), Point2::new(4.0, 1.0));
        assert_eq!(open.classify_edge(c, d, w, 3.0), EdgeObservation::Trav);
        // An edge 4 m away is not "under" the robot: the paper's rule applies.
        let (e, f) = (Point2::new(-15.0, 4.0), Point2::new(15.0, 4.0));
        assert_eq!(wall.classify_edge(e, f, w, 3.0), EdgeObservation::UnkTrav);
    }

    fn judging(window_rad: f64, on_edge_radius_m: f64) -> Judging {
        Judging { window_rad, on_edge_radius_m, min_crossing_range_m: 0.0 }
    }

    #[test]
    fn a_crossing_at_the_robots_own_clearance_is_unknown() {
        // The robot 0.6 m from a wall to its north (range 0.6 there), open elsewhere to 10 m.
        let n = 360;
        let mut range = vec![10.0; n];
        let mut obstacle = vec![true; n];
        for (b, (r, o)) in range.iter_mut().zip(obstacle.iter_mut()).enumerate() {
            // Bins run clockwise from +x: north is bin 270.
            if (225..=315).contains(&b) {
                *r = 0.6;
                *o = true;
            }
        }
        let s = StarRegion::from_scan(&scan(Pose2::new(0.0, 0.0, 0.0), range, obstacle), 30.0).unwrap();
        let north = [Point2::new(0.0, 0.0), Point2::new(0.0, 5.0)];
        assert_eq!(s.classify_polyline(&north, &judging(0.3, 0.0)).obs, EdgeObservation::NotTrav, "the paper's rule");
        let near = Judging { window_rad: 0.3, on_edge_radius_m: 0.0, min_crossing_range_m: 1.0 };
        assert_eq!(s.classify_polyline(&north, &near).obs, EdgeObservation::UnkTrav);
        // A crossing farther out still counts.
        let east = [Point2::new(0.0, 0.0), Point2::new(20.0, 0.0)];
        assert_eq!(s.classify_polyline(&east, &near).obs, EdgeObservation::NotTrav);
    }

    #[test]
    fn a_routed_edge_is_judged_along_all_its_pieces() {
        let w = 0.3;
        let wall = StarRegion::from_scan(&circle(360, 10.0, true), 30.0).unwrap();
        let p = |x: f64, y: f64| Point2::new(x, y);
        // Inside all along, around a corner.
        assert_eq!(
            wall.classify_polyline(&[p(-5.0, 0.0), p(0.0, 5.0), p(5.0, 0.0)], &judging(w, 0.0)).obs,
            EdgeObservation::Trav
        );
        // The second piece leaves through the wall: one crossing.
        assert_eq!(
            wall.classify_polyline(&[p(0.0, 0.0), p(5.0, 0.0), p(5.0, 20.0)], &judging(w, 0.0)).obs,
            EdgeObservation::NotTrav
        );
        // Out through the wall and back in: two crossings, although each piece's straight
        // chord from end to end would say otherwise.
        let out_and_back = [p(0.0, 0.0), p(20.0, 0.0), p(20.0, 1.0), p(0.0, 1.0)];
        assert_eq!(wall.classify_polyline(&out_and_back, &judging(w, 0.0)).obs, EdgeObservation::UnkTrav);
        assert_eq!(wall.classify(p(0.0, 0.0), p(0.0, 1.0), w), EdgeObservation::Trav);
        // The robot on the routed edge, 0.5 m from its corner piece: blocked towards the far end.
        let l_shape = [p(-15.0, 0.5), p(0.0, 0.5), p(0.0, 15.0)];
        assert_eq!(wall.classify_polyline(&l_shape, &judging(w, 3.0)).obs, EdgeObservation::NotTrav);
        assert_eq!(wall.classify_polyline(&l_shape, &judging(w, 0.0)).obs, EdgeObservation::UnkTrav, "two crossings");
        assert_eq!(polyline_point_distance(&l_shape, p(1.0, 5.0)), 1.0);
        assert!(polyline_point_distance(&[], p(0.0, 0.0)).is_infinite());
    }

    #[test]
    fn bad_scans_are_errors() {
        assert!(matches!(StarRegion::from_scan(&circle(0, 1.0, true), 30.0), Err(ScanError::Empty)));
        let mismatched = scan(Pose2::default(), vec![1.0; 3], vec![true; 2]);
        assert!(matches!(StarRegion::from_scan(&mismatched, 30.0), Err(ScanError::LengthMismatch { .. })));
        let nan = scan(Pose2::new(f64::NAN, 0.0, 0.0), vec![1.0; 3], vec![true; 3]);
        assert!(matches!(StarRegion::from_scan(&nan, 30.0), Err(ScanError::NonFinitePose)));
    }

    #[test]
    fn a_not_trav_verdict_is_at_a_teammate_only_where_the_crossing_is_a_teammates_bin() {
        // A closed wall 10 m around the robot; a teammate stands at the wall due east.
        let mut wall = StarRegion::from_scan(&circle(360, 10.0, true), 30.0).unwrap();
        let mate = Point2::new(10.5, 0.0);
        let marked = wall.mark_teammates(&[mate], 2.0);
        assert!(marked > 0 && marked < 30, "{marked}");
        let j = judging(0.3, 0.0);
        let east = wall.classify_polyline(&[Point2::new(0.0, 0.0), Point2::new(20.0, 0.0)], &j);
        assert_eq!(east, Verdict { obs: EdgeObservation::NotTrav, at_teammate: true });
        let north = wall.classify_polyline(&[Point2::new(0.0, 0.0), Point2::new(0.0, 20.0)], &j);
        assert_eq!(north, Verdict { obs: EdgeObservation::NotTrav, at_teammate: false });
        // The robot on an edge running east-west through it: judged from it both ways (each half
        // crosses the wall once). At a teammate only when both halves are.
        let on_edge = judging(0.3, 3.0);
        let through = [Point2::new(-20.0, 0.0), Point2::new(20.0, 0.0)];
        assert_eq!(
            wall.classify_polyline(&through, &on_edge),
            Verdict { obs: EdgeObservation::NotTrav, at_teammate: false }
        );
        wall.mark_teammates(&[mate, Point2::new(-10.5, 0.0)], 2.0);
        assert_eq!(
            wall.classify_polyline(&through, &on_edge),
            Verdict { obs: EdgeObservation::NotTrav, at_teammate: true }
        );
        // Reloading a scan forgets the teammates; no teammates, or no clearance, marks none.
        wall.load(&circle(360, 10.0, true), 30.0).unwrap();
        assert!(!wall.classify_polyline(&[Point2::new(0.0, 0.0), Point2::new(20.0, 0.0)], &j).at_teammate);
        assert_eq!(wall.mark_teammates(&[], 2.0), 0);
        assert_eq!(wall.mark_teammates(&[mate], 0.0), 0);
    }

    #[test]
    fn testing_only_the_chords_a_segment_faces_gives_the_verdict_of_testing_every_chord() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        let judging = Judging { window_rad: 0.3, on_edge_radius_m: 0.0, min_crossing_range_m: 0.0 };
        let mut verdicts = std::collections::HashMap::new();
        for _ in 0..200 {
            let n = [16, 64, 360, 1024][rng.random_range(0..4)];
            let pose = Pose2::new(
                rng.random_range(-300.0..300.0),
                rng.random_range(-300.0..300.0),
                rng.random_range(-4.0..4.0),
            );
            let range: Vec<f32> =
                (0..n).map(|_| if rng.random_bool(0.1) { 0.0 } else { rng.random_range(0.5..25.0) }).collect();
            let obstacle: Vec<bool> = (0..n).map(|_| rng.random_bool(0.5)).collect();
            let region = StarRegion::from_scan(&scan(pose, range, obstacle), 30.0).unwrap();
            for _ in 0..50 {
                // Polylines of one to three pieces around the robot, some passing right by it.
                let (pieces, reach) = (rng.random_range(2..5), if rng.random_bool(0.5) { 6.0 } else { 35.0 });
                let mut points: Vec<Point2> = (0..pieces)
                    .map(|_| {
                        let (d, a) = (rng.random_range(0.0..reach), rng.random_range(-4.0..4.0f64));
                        Point2::new(pose.x + d * a.cos(), pose.y + d * a.sin())
                    })
                    .collect();
                if rng.random_bool(0.1) {
                    points.insert(1, Point2::new(pose.x + 0.004, pose.y - 0.003));
                }
                let facing = region.classify_path_among(&points, &judging, false);
                let every = region.classify_path_among(&points, &judging, true);
                assert_eq!(facing, every, "{points:?} against {n} bins");
                *verdicts.entry(format!("{:?}", every.obs)).or_insert(0) += 1;
            }
        }
        // Every kind of verdict was compared.
        assert!(verdicts.len() == 3 && verdicts.values().all(|&k| k >= 100), "{verdicts:?}");
    }
}
