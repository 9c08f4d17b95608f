//! Reachability scans: the local planner's summary of one panorama, shared with the team and used
//! by the global planner to update its graph and train its traversability model.

use serde::{Deserialize, Serialize};

use crate::geometry::{Point2, Pose2};
use crate::ids::RobotId;
use crate::time::Time;

/// The `range_max` of a reachability scan as a `sensor_msgs/LaserScan`, metres: fixed and above
/// any reach (a panorama's depth ends at 128 m in its 16-bit form, and terrain analysis well
/// before), so every bin is a valid reading to ROS tools (REP-117).
pub const REACHABILITY_RANGE_MAX_M: f32 = 1000.0;

/// S(φ): per azimuth bin (one per panorama column, same angle convention), how far the robot
/// knows the ground to be safe, and whether a known obstacle ends that safe stretch (otherwise
/// the unknown begins there).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ReachabilityScan {
    /// Robot that took it.
    pub robot: RobotId,
    /// When the panorama was taken.
    pub stamp: Time,
    /// Map-frame pose of the robot at the panorama.
    pub pose: Pose2,
    /// Safe distance per bin, metres.
    pub range_m: Vec<f32>,
    /// Whether a known obstacle ends the bin's safe stretch.
    pub obstacle: Vec<bool>,
}

impl ReachabilityScan {
    /// Number of bins.
    pub fn bins(&self) -> usize {
        self.range_m.len()
    }

    /// Robot-frame azimuth of a bin (column 0 along +x, decreasing clockwise).
    pub fn azimuth_of_bin(&self, bin: usize) -> f64 {
        -(bin as f64) * std::f64::consts::TAU / self.bins().max(1) as f64
    }

    /// Map-frame end point of a bin's safe stretch.
    pub fn endpoint(&self, bin: usize) -> Point2 {
        let a = self.pose.yaw + self.azimuth_of_bin(bin);
        let r = self.range_m[bin] as f64;
        Point2::new(self.pose.x + r * a.cos(), self.pose.y + r * a.sin())
    }

    /// Whether the two per-bin vectors have the same, non-zero length.
    pub fn is_consistent(&self) -> bool {
        !self.range_m.is_empty() && self.range_m.len() == self.obstacle.len()
    }
}
