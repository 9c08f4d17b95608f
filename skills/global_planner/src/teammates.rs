//! Teammates are not terrain. A ground robot standing in the road shows in another robot's
//! panorama as an obstacle, and that robot's reachability scan stops at it. The paper's edge
//! rules take such a scan like any other: two of the robot's own scans that end at the teammate
//! mark the edges through it not_trav, lock them and remove them for good. Robots that start in
//! a file, or meet head-on in a lane, then cut the very roads they stand on, and a robot whose
//! every way out was cut so never finds a path again. The robot therefore judges an edge whose
//! boundary crossing is a teammate's body (a bin on either side of the crossing ends at the
//! teammate) as it judges an edge from another robot's scan: not_trav marks it (a cost that
//! steers the robot away from where teammates stand) but never removes it. Every other edge of
//! the same scan is judged as the paper says: a roadblock beside a teammate still cuts the
//! road. The scan itself is not changed: its training votes and what the team receives stay as
//! they were.

use spomp_core::{Point2, ReachabilityScan};

/// How many bins of `scan` (map frame) end at one of `teammates` (their last known positions):
/// bins with an obstacle whose end point lies within `clearance_m` of a teammate. A clearance of
/// 0 (or one that is not a number) finds none.
///
/// The obstacle of a bin lies just beyond the bin's end point (the safe stretch stops the
/// local planner's inflation short of it), so the test is on the end point: `clearance_m` must
/// cover the teammate's body radius, that inflation and both robots' localization error.
pub fn bins_ending_at_teammates(scan: &ReachabilityScan, teammates: &[Point2], clearance_m: f64) -> usize {
    if scan.obstacle.len() != scan.bins() {
        return 0;
    }
    let bins = BinFan { origin: scan.pose.position(), yaw: scan.pose.yaw, bins: scan.bins() };
    let max_range = scan.range_m.iter().copied().fold(0.0f32, f32::max) as f64;
    let mut count = 0;
    bins.for_each_ending_at(
        |bin| scan.obstacle[bin].then(|| scan.endpoint(bin)),
        max_range,
        teammates,
        clearance_m,
        |_| count += 1,
    );
    count
}

/// The bins of a scan as directions: bin k looks along `yaw − k·2π/bins` from `origin`.
#[derive(Clone, Copy, Debug)]
pub(crate) struct BinFan {
    pub origin: Point2,
    pub yaw: f64,
    pub bins: usize,
}

impl BinFan {
    /// Calls `visit` once for every bin whose obstacle end point (`obstacle_end(bin)`, `None`
    /// for a bin that ends in the unknown) lies within `clearance_m` of one of `teammates`. No
    /// end point lies beyond `max_range_m` of the origin. A clearance of 0 (or one that is not a
    /// number) visits none.
    pub fn for_each_ending_at(
        &self,
        obstacle_end: impl Fn(usize) -> Option<Point2>,
        max_range_m: f64,
        teammates: &[Point2],
        clearance_m: f64,
        mut visit: impl FnMut(usize),
    ) {
        let n = self.bins;
        if n == 0 || teammates.is_empty() || !(clearance_m.is_finite() && clearance_m > 0.0) {
            return;
        }
        let origin = self.origin;
        // Only teammates a bin's end point can come near.
        let near = |t: &Point2| t.x.is_finite() && t.y.is_finite() && t.distance(origin) <= max_range_m + clearance_m;
        let step = std::f64::consts::TAU / n as f64;
        for (k, &t) in teammates.iter().enumerate() {
            if !near(&t) {
                continue;
            }
            // A point within `clearance_m` of a teammate `dist` away lies within asin(clearance /
            // dist) of its bearing, so only the bins in that window (a bin of margin for
            // rounding) can end near it: the exact test runs on those alone.
            let d = t - origin;
            let dist = d.norm();
            let half = if dist > clearance_m { (clearance_m / dist).asin() } else { std::f64::consts::PI };
            // Bin k looks along yaw − k·step.
            let centre = -(d.angle() - self.yaw) / step;
            let half_bins = half / step + 1.0;
            let (lo, hi) = ((centre - half_bins).ceil() as i64, (centre + half_bins).floor() as i64);
            let window = if hi - lo + 1 >= n as i64 { 0..n as i64 } else { lo..hi + 1 };
            for bin in window.map(|b| b.rem_euclid(n as i64) as usize) {
                let Some(end) = obstacle_end(bin) else { continue };
                // A bin that also ends at an earlier teammate was visited with that one.
                if t.distance(end) <= clearance_m
                    && !teammates[..k].iter().any(|u| near(u) && u.distance(end) <= clearance_m)
                {
                    visit(bin);
                }
            }
        }
    }
}

/// [`bins_ending_at_teammates`] as first written, every bin tested: the reference the tests
/// hold the windowed count to.
#[cfg(test)]
fn bins_ending_at_teammates_every_bin(scan: &ReachabilityScan, teammates: &[Point2], clearance_m: f64) -> usize {
    (0..scan.bins())
        .filter(|&bin| scan.obstacle[bin] && teammates.iter().any(|t| t.distance(scan.endpoint(bin)) <= clearance_m))
        .count()
}

#[cfg(test)]
mod tests {
    use super::*;
    use spomp_core::{Pose2, RobotId, Time};

    /// A scan from the origin looking along +x, every bin ending at an obstacle `range` away.
    fn ring(range: f32, bins: usize) -> ReachabilityScan {
        ReachabilityScan {
            robot: RobotId::new("ugv1"),
            stamp: Time::from_secs_f64(1.0),
            pose: Pose2::new(0.0, 0.0, 0.0),
            range_m: vec![range; bins],
            obstacle: vec![true; bins],
        }
    }

    #[test]
    fn counts_the_bins_that_end_at_a_teammate() {
        let scan = ring(5.0, 360);
        let mate = Point2::new(6.0, 0.0);
        let n = bins_ending_at_teammates(&scan, &[mate], 2.0);
        let expected = (0..scan.bins()).filter(|&b| scan.endpoint(b).distance(mate) <= 2.0).count();
        assert_eq!(n, expected);
        assert!(n > 0 && n < 60, "{n}");
        // A bin without an obstacle ends in the unknown, never at a teammate.
        let mut open = ring(5.0, 360);
        open.obstacle.iter_mut().for_each(|o| *o = false);
        assert_eq!(bins_ending_at_teammates(&open, &[mate], 2.0), 0);
    }

    #[test]
    fn no_teammate_in_reach_or_no_clearance_finds_none() {
        let scan = ring(5.0, 64);
        assert_eq!(bins_ending_at_teammates(&scan, &[Point2::new(40.0, 0.0)], 2.0), 0);
        assert_eq!(bins_ending_at_teammates(&scan, &[Point2::new(6.0, 0.0)], 0.0), 0);
        assert_eq!(bins_ending_at_teammates(&scan, &[Point2::new(6.0, 0.0)], f64::NAN), 0);
        assert_eq!(bins_ending_at_teammates(&scan, &[Point2::new(f64::NAN, 0.0)], 2.0), 0);
        assert_eq!(bins_ending_at_teammates(&scan, &[], 2.0), 0);
    }

    #[test]
    fn the_windowed_count_equals_testing_every_bin() {
        // Scans from several poses with ranges and obstacles of every kind, teammates near and
        // far, inside the clearance of the origin and around the ±π seam.
        let mut state = 0x2545_f491_4f6c_dd1du64;
        let mut next = move || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            (state >> 11) as f64 / (1u64 << 53) as f64
        };
        for case in 0..200 {
            let bins = [64, 360, 1024][case % 3];
            let pose = Pose2::new(next() * 40.0 - 20.0, next() * 40.0 - 20.0, next() * 8.0 - 4.0);
            let scan = ReachabilityScan {
                robot: RobotId::new("ugv1"),
                stamp: Time::from_secs_f64(1.0),
                pose,
                range_m: (0..bins).map(|_| (next() * 12.0) as f32).collect(),
                obstacle: (0..bins).map(|_| next() < 0.7).collect(),
            };
            let mates: Vec<Point2> = (0..1 + case % 4)
                .map(|_| Point2::new(pose.x + next() * 24.0 - 12.0, pose.y + next() * 24.0 - 12.0))
                .collect();
            let clearance = [0.5, 2.0, 6.0][case % 3];
            assert_eq!(
                bins_ending_at_teammates(&scan, &mates, clearance),
                bins_ending_at_teammates_every_bin(&scan, &mates, clearance),
                "case {case}"
            );
        }
    }

    #[test]
    fn a_malformed_scan_finds_none() {
        let mut scan = ring(5.0, 64);
        scan.obstacle.truncate(10);
        assert_eq!(bins_ending_at_teammates(&scan, &[Point2::new(6.0, 0.0)], 2.0), 0);
    }
}
