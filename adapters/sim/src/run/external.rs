//! Robots driven from outside the simulator: the simulator moves their bodies and renders their
//! sensors, and a driver (the ROS 2 robot farm: `spomp run` processes) decides what they do.
//!
//! For a driven robot the simulator hands its sensor data to the driver instead of its own
//! [`spomp_robot::Robot`], takes the driver's command instead of ticking a tree (a command older
//! than the driver's timeout stops the robot), carries the team-state messages the driver's
//! robots send over the same radio model as everyone else's, and learns their goals, claims and
//! visits from the status they report.

use spomp_core::{FlightCommand, GridSpec, MapTile, Odometry, PanoramaFrame, PoseEstimate, RobotId, Time, Twist2};
use spomp_teamstate::GoalView;

/// A team-state message a driven robot sent.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct DrivenTeamMessage {
    /// Sender (a driven robot).
    pub from: RobotId,
    /// Addressee.
    pub to: RobotId,
    /// The encoded sync message.
    pub bytes: Vec<u8>,
}

/// What drives some of a simulation's robots.
pub trait ExternalDrivers {
    /// Whether `robot` is driven from outside.
    fn drives(&self, robot: &RobotId) -> bool;
    /// Called at the start of every step with the new simulated time: publish the clock, pace
    /// the run to real time if the driver needs it, take what the robots sent.
    fn begin_step(&mut self, now: Time);
    /// A driven robot's odometry.
    fn odometry(&mut self, robot: &RobotId, odom: &Odometry);
    /// A driven robot's panorama.
    fn panorama(&mut self, robot: &RobotId, frame: &PanoramaFrame);
    /// A map-frame pose for a driven robot (ground truth or GPS where the mission asks).
    fn pose(&mut self, robot: &RobotId, estimate: &PoseEstimate, z_m: f64);
    /// What a driven UAV's camera mapped this step: tiles of the map over `grid`.
    fn camera_tiles(&mut self, robot: &RobotId, now: Time, tiles: &[MapTile], grid: &GridSpec);
    /// The driven UGV's velocity command now; `None` (nothing fresh) stops it.
    fn command(&mut self, robot: &RobotId, now: Time) -> Option<Twist2>;
    /// The driven UAV's flight command now; `None` hovers.
    fn flight(&mut self, robot: &RobotId, now: Time) -> Option<FlightCommand>;
    /// Team-state messages the driven robots sent since the last call.
    fn take_team_messages(&mut self) -> Vec<DrivenTeamMessage>;
    /// Delivers a team-state message to a driven robot.
    fn deliver_team_message(&mut self, to: &RobotId, from: &RobotId, bytes: &[u8]);
    /// The goals as a driven robot last reported them.
    fn goals(&self, robot: &RobotId) -> &[GoalView];
    /// Whether a driven robot reported its tree finished.
    fn tree_done(&self, robot: &RobotId) -> bool;
}
