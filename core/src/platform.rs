//! The small set of traits through which behaviour nodes see a robot (DESIGN.md §2).
//!
//! Adapters (the simulator, ROS 2, MCAP replay) implement them; nodes never call an adapter
//! directly. Every method is cheap and non-blocking: nodes call them from `tick`.

use std::sync::Arc;

use crate::ids::RobotId;
use crate::motion::{Odometry, PoseEstimate, Twist2};
use crate::panorama::PanoramaFrame;
use crate::time::Clock;

/// The robot's pose in the shared map frame (from the localizer, or GPS on the UAV).
pub trait PoseSource {
    /// The latest map-frame estimate, if any.
    fn pose(&self) -> Option<PoseEstimate>;
}

/// Odometry in the robot's own frame.
pub trait OdometrySource {
    /// The latest odometry.
    fn odometry(&self) -> Option<Odometry>;
}

/// Depth + semantic panoramas.
pub trait PanoramaSource {
    /// The latest panorama; compare `seq` to see whether it is new.
    fn latest_panorama(&self) -> Option<Arc<PanoramaFrame>>;
}

/// Where motion commands go.
pub trait MotionSink {
    /// Commands a velocity; it holds until the next command.
    fn command(&mut self, twist: Twist2);
}

/// The radio as the robot sees it: opaque payloads to and from peers. What flows is the team
/// state's business; when and how much is the link's.
pub trait TeamLink {
    /// Peers reachable right now.
    fn peers_in_range(&self) -> Vec<RobotId>;
    /// Queues a payload for a peer; returns false if the link refuses it (out of range, full).
    fn send(&mut self, to: &RobotId, payload: Vec<u8>) -> bool;
    /// Takes the next received payload, if any.
    fn receive(&mut self) -> Option<(RobotId, Vec<u8>)>;
}

/// Everything a robot's behaviour tree can reach.
pub trait Platform: Clock + PoseSource + OdometrySource + PanoramaSource + MotionSink + TeamLink {
    /// This robot's id.
    fn robot_id(&self) -> &RobotId;
}
