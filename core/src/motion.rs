//! Commands, odometry and pose estimates.

use serde::{Deserialize, Serialize};

use crate::geometry::Pose2;
use crate::time::Time;

/// A velocity command for a planar robot.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Twist2 {
    /// Forward speed, m/s.
    pub v: f64,
    /// Turn rate, rad/s, counter-clockwise positive.
    pub omega: f64,
}

impl Twist2 {
    /// Standing still.
    pub const ZERO: Twist2 = Twist2 { v: 0.0, omega: 0.0 };
}

/// Odometry: the robot's pose in its own drifting odometry frame.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Odometry {
    /// When it was measured.
    pub stamp: Time,
    /// Pose in the odometry frame.
    pub pose: Pose2,
    /// Measured velocity.
    pub twist: Twist2,
}

/// The uncertainty of an odometry reading, as its source's noise model gives it.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct OdometryCovariance {
    /// Row-major 3 × 3 covariance of the pose (x, y, yaw) in the odometry frame: m², m·rad,
    /// rad². It grows with the distance driven (dead reckoning).
    pub pose: [f64; 9],
    /// Variances of the measured velocity: forward (m²/s²) and turn rate (rad²/s²).
    pub twist: [f64; 2],
}

/// A pose estimate in the map frame, with uncertainty.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct PoseEstimate {
    /// When it holds.
    pub stamp: Time,
    /// Map-frame pose.
    pub pose: Pose2,
    /// Row-major 3 × 3 covariance of (x, y, yaw).
    pub covariance: [f64; 9],
    /// 0 (lost) … 1 (certain).
    pub confidence: f64,
}

/// A flight command for a multirotor UAV: fly to `target` at `altitude_m` with at most
/// `speed_mps`; hover there once arrived.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct FlightCommand {
    /// Where to fly (map frame).
    pub target: crate::geometry::Point2,
    /// Altitude above the take-off point, metres.
    pub altitude_m: f64,
    /// Cruise speed cap, m/s.
    pub speed_mps: f64,
}
