//! Which reachability scans a robot shares with its team (paper §Communication): none, all, or a
//! downsampled set in which every shared scan is at least `min_separation_m` from every scan
//! shared before.

use std::collections::HashMap;

use spomp_core::{Point2, ReachabilityScan};

use crate::params::{SharingMode, SharingParams};

/// The sharing filter. Remembers where it shared scans, bucketed on a grid of the separation
/// distance so each decision looks at nine buckets.
#[derive(Debug, Clone)]
pub struct ScanSharer {
    params: SharingParams,
    buckets: HashMap<(i64, i64), Vec<Point2>>,
    shared: usize,
}

impl ScanSharer {
    /// A filter that has shared nothing yet.
    pub fn new(params: SharingParams) -> Self {
        ScanSharer { params, buckets: HashMap::new(), shared: 0 }
    }

    /// Number of scans shared so far.
    pub fn shared_count(&self) -> usize {
        self.shared
    }

    fn bucket_size(&self) -> f64 {
        let s = self.params.min_separation_m;
        if s.is_finite() && s > 1e-3 { s } else { 1.0 }
    }

    fn bucket_of(&self, p: Point2) -> (i64, i64) {
        let s = self.bucket_size();
        ((p.x / s).floor() as i64, (p.y / s).floor() as i64)
    }

    /// Whether to share `scan`; a shared scan is remembered. Scans with a non-finite pose are
    /// never shared.
    pub fn should_share(&mut self, scan: &ReachabilityScan) -> bool {
        let p = scan.pose.position();
        if !(p.x.is_finite() && p.y.is_finite()) {
            return false;
        }
        match self.params.mode {
            SharingMode::None => return false,
            SharingMode::All => {
                self.shared += 1;
                return true;
            }
            SharingMode::Downsampled => {}
        }
        let (bx, by) = self.bucket_of(p);
        let min_sep = self.params.min_separation_m;
        for dx in -1..=1 {
            for dy in -1..=1 {
                if let Some(points) = self.buckets.get(&(bx + dx, by + dy))
                    && points.iter().any(|q| q.distance(p) < min_sep)
                {
                    return false;
                }
            }
        }
        self.buckets.entry((bx, by)).or_default().push(p);
        self.shared += 1;
        true
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use spomp_core::{Pose2, RobotId, Time};

    fn scan_at(x: f64, y: f64) -> ReachabilityScan {
        ReachabilityScan {
            robot: RobotId::new("ugv1"),
            stamp: Time::ZERO,
            pose: Pose2::new(x, y, 0.0),
            range_m: vec![1.0],
            obstacle: vec![false],
        }
    }

    #[test]
    fn downsampled_keeps_two_metre_spacing() {
        let mut s = ScanSharer::new(SharingParams::default());
        assert!(s.should_share(&scan_at(0.0, 0.0)));
        assert!(!s.should_share(&scan_at(1.9, 0.0)));
        assert!(s.should_share(&scan_at(2.1, 0.0)));
        assert!(!s.should_share(&scan_at(1.0, 1.0)), "within 2 m of both");
        assert!(s.should_share(&scan_at(1.0, 1.9)));
        assert!(!s.should_share(&scan_at(f64::NAN, 0.0)));
        assert_eq!(s.shared_count(), 3);
    }

    #[test]
    fn none_and_all_modes() {
        let mut none = ScanSharer::new(SharingParams { mode: SharingMode::None, ..Default::default() });
        let mut all = ScanSharer::new(SharingParams { mode: SharingMode::All, ..Default::default() });
        for _ in 0..3 {
            assert!(!none.should_share(&scan_at(0.0, 0.0)));
            assert!(all.should_share(&scan_at(0.0, 0.0)));
        }
    }
}
