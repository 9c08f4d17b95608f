//! Putting inputs back together: depth and label images of one instant into a panorama, and the
//! odometry pose at a panorama's stamp.

use std::collections::VecDeque;

use spomp_core::{DepthPanorama, Odometry, Pose2, SemanticPanorama, Time, normalize_angle};

/// Recent odometry, to find the odometry pose at a panorama's stamp.
#[derive(Debug, Clone)]
pub struct OdometryHistory {
    samples: VecDeque<Odometry>,
    capacity: usize,
}

/// How far outside the odometry it holds a stamp may be and still get a pose, seconds.
const POSE_TOLERANCE_S: f64 = 0.1;

impl OdometryHistory {
    /// Keeps the newest `capacity` samples.
    pub fn new(capacity: usize) -> Self {
        OdometryHistory { samples: VecDeque::with_capacity(capacity), capacity: capacity.max(2) }
    }

    /// Adds a sample; one older than the newest is ignored (out-of-order delivery).
    pub fn push(&mut self, odom: Odometry) {
        if self.samples.back().is_some_and(|last| odom.stamp < last.stamp) {
            return;
        }
        if self.samples.len() == self.capacity {
            self.samples.pop_front();
        }
        self.samples.push_back(odom);
    }

    /// The newest sample.
    pub fn latest(&self) -> Option<&Odometry> {
        self.samples.back()
    }

    /// The pose at `stamp`, interpolated between the samples around it; `None` when the history
    /// does not reach it (yet, or any more).
    pub fn pose_at(&self, stamp: Time) -> Option<Pose2> {
        let first = self.samples.front()?;
        let last = self.samples.back()?;
        let tol = Time::from_secs_f64(POSE_TOLERANCE_S).nanos;
        if stamp.nanos < first.stamp.nanos - tol || stamp.nanos > last.stamp.nanos + tol {
            return None;
        }
        if stamp <= first.stamp {
            return Some(first.pose);
        }
        if stamp >= last.stamp {
            return Some(last.pose);
        }
        let after = self.samples.partition_point(|s| s.stamp <= stamp);
        let (a, b) = (&self.samples[after - 1], &self.samples[after]);
        let span = (b.stamp.nanos - a.stamp.nanos) as f64;
        let f = if span > 0.0 { (stamp.nanos - a.stamp.nanos) as f64 / span } else { 0.0 };
        let yaw = a.pose.yaw + f * normalize_angle(b.pose.yaw - a.pose.yaw);
        Some(Pose2::new(
            a.pose.x + f * (b.pose.x - a.pose.x),
            a.pose.y + f * (b.pose.y - a.pose.y),
            normalize_angle(yaw),
        ))
    }
}

/// A depth and a label image of the same stamp.
pub type PanoramaPair = (Time, DepthPanorama, SemanticPanorama);

/// Pairs depth and label images by stamp. A half that waits while a newer stamp completes is
/// dropped and counted.
#[derive(Debug, Default)]
pub struct PanoramaPairer {
    depth: Option<(Time, DepthPanorama)>,
    semantic: Option<(Time, SemanticPanorama)>,
    dropped: u64,
}

impl PanoramaPairer {
    /// A depth image arrived.
    pub fn push_depth(&mut self, stamp: Time, depth: DepthPanorama) -> Option<PanoramaPair> {
        if self.depth.take().is_some() {
            self.dropped += 1;
        }
        self.depth = Some((stamp, depth));
        self.try_pair()
    }

    /// A label image arrived.
    pub fn push_semantic(&mut self, stamp: Time, semantic: SemanticPanorama) -> Option<PanoramaPair> {
        if self.semantic.take().is_some() {
            self.dropped += 1;
        }
        self.semantic = Some((stamp, semantic));
        self.try_pair()
    }

    /// Halves dropped so far.
    pub fn dropped(&self) -> u64 {
        self.dropped
    }

    fn try_pair(&mut self) -> Option<PanoramaPair> {
        let (ds, ss) = (self.depth.as_ref()?.0, self.semantic.as_ref()?.0);
        if ds != ss {
            // The older half can never be completed: drop it.
            if ds < ss {
                self.depth = None;
            } else {
                self.semantic = None;
            }
            self.dropped += 1;
            return None;
        }
        let (t, d) = self.depth.take()?;
        let (_, s) = self.semantic.take()?;
        if d.geometry.rows != s.geometry.rows || d.geometry.cols != s.geometry.cols {
            self.dropped += 2;
            return None;
        }
        Some((t, d, s))
    }
}

#[cfg(test)]
mod tests {
    use spomp_core::{PanoramaGeometry, Twist2};

    use super::*;

    fn odom(t: f64, x: f64, yaw: f64) -> Odometry {
        Odometry { stamp: Time::from_secs_f64(t), pose: Pose2::new(x, 0.0, yaw), twist: Twist2::ZERO }
    }

    #[test]
    fn pose_is_interpolated_between_samples_and_refused_outside() {
        let mut h = OdometryHistory::new(10);
        h.push(odom(1.0, 0.0, 3.0));
        h.push(odom(2.0, 2.0, -3.0));
        let p = h.pose_at(Time::from_secs_f64(1.5)).expect("inside");
        assert!((p.x - 1.0).abs() < 1e-9);
        // Across ±π the short way round: 3.0 → −3.0 passes through π.
        assert!((p.yaw.abs() - std::f64::consts::PI).abs() < 0.01, "{}", p.yaw);
        assert!(h.pose_at(Time::from_secs_f64(2.05)).is_some());
        assert!(h.pose_at(Time::from_secs_f64(2.5)).is_none());
        assert!(h.pose_at(Time::from_secs_f64(0.5)).is_none());
    }

    #[test]
    fn images_pair_by_stamp_and_stale_halves_are_dropped() {
        let g = PanoramaGeometry { rows: 2, cols: 4, v_fov_rad: 1.0 };
        let d = DepthPanorama::empty(g);
        let s = SemanticPanorama { geometry: g, class: vec![0; 8] };
        let mut p = PanoramaPairer::default();
        assert!(p.push_depth(Time::from_secs_f64(1.0), d.clone()).is_none());
        assert!(p.push_semantic(Time::from_secs_f64(2.0), s.clone()).is_none());
        assert_eq!(p.dropped(), 1, "the depth of t=1 can never pair");
        let pair = p.push_depth(Time::from_secs_f64(2.0), d).expect("t=2 pairs");
        assert_eq!(pair.0, Time::from_secs_f64(2.0));
    }
}
