//! Robots driven from outside the simulator: the simulator moves their bodies and renders their
//! sensors, and a driver (the ROS 2 robot farm: `spomp run` processes) decides what they do.
//!
//! For a driven robot the simulator hands its sensor data to the driver instead of its own
//! [`spomp_robot::Robot`], takes the driver's command instead of ticking a tree (a command older
//! than the driver's timeout stops the robot), carries the team-state messages the driver's
//! robots send over the same radio model as everyone else's, and learns their goals, claims and
//! visits from the status they report.
//!
//! A driver in lockstep ([`ExternalDrivers::lockstep`]) is given every call the simulator makes
//! on its own robots' seams at the same point of the step — inputs, background work, each radio
//! message out and in, the tick — and the step's outcome ([`DrivenStep`]) before the simulator
//! goes on: the run is then the one the simulator makes with the robots inside it.

use spomp_core::{
    FlightCommand, GridSpec, MapTile, Odometry, OdometryCovariance, PanoramaFrame, PoseEstimate, RobotId, Time, Twist2,
};
use spomp_teamstate::{GoalView, TierSet};

/// What a driven robot in lockstep did in a step ([`ExternalDrivers::end_step`]).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct DrivenStep {
    /// Whether its tree ticked.
    pub ticked: bool,
    /// `command()` after the step.
    pub command: Option<Twist2>,
    /// Its estimate right after this step's panorama, if one came.
    pub estimate_after_panorama: Option<PoseEstimate>,
    /// Its estimate at the end of the step.
    pub estimate: Option<PoseEstimate>,
    /// Nodes (depth-first ids) whose status changed in the tick.
    pub transitioned: Vec<u32>,
    /// Problems reported in the tick.
    pub problems: Vec<String>,
}

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
    /// A driven robot's odometry with its uncertainty under the simulator's noise model (what a
    /// driver publishing `nav_msgs/Odometry` fills in); by default the odometry alone.
    fn odometry_with_covariance(&mut self, robot: &RobotId, odom: &Odometry, covariance: &OdometryCovariance) {
        let _ = covariance;
        self.odometry(robot, odom);
    }
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

    /// Whether the driven robots run in lockstep with the simulator (the calls below).
    fn lockstep(&self) -> bool {
        false
    }
    /// Lockstep: hand the robot its background work due back, and take the work it has due.
    fn exchange_work(&mut self, _robot: &RobotId, _now: Time) {}
    /// Lockstep: the robot's team-state message for `to` over a link allowing `tiers` and
    /// `budget_bytes` (its `team_message_for`), at this point of the step.
    fn team_message_for(
        &mut self,
        _robot: &RobotId,
        _to: &RobotId,
        _tiers: TierSet,
        _budget_bytes: usize,
    ) -> Option<Vec<u8>> {
        None
    }
    /// Lockstep: the robot's upkeep and tick, when due.
    fn tick(&mut self, _robot: &RobotId, _now: Time) {}
    /// Lockstep: waits until every robot told to tick has answered (a robot that does not
    /// answer in time is reported and no longer driven).
    fn end_step(&mut self, _now: Time) {}
    /// Lockstep: what the robot did in this step, once [`ExternalDrivers::end_step`] returned.
    fn step_of(&self, _robot: &RobotId) -> Option<&DrivenStep> {
        None
    }
    /// The robot was killed: halt it.
    fn halt(&mut self, _robot: &RobotId, _now: Time) {}
    /// The root status of a driven robot's tree as it last reported it (`running`, `success`, …).
    fn tree_status(&self, _robot: &RobotId) -> Option<String> {
        None
    }
    /// The run is over.
    fn end_run(&mut self) {}
    /// Robots whose process reported since the last call (it started late): the simulator stops
    /// running them itself and hands them to the driver from this step on.
    fn joined(&mut self) -> Vec<RobotId> {
        Vec::new()
    }
}
