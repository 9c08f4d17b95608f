//! What a run tells its observer: the robot layer's `RobotObserver` plus what only the
//! simulator knows.

use super::*;

/// What happened, for logs (team-level changes and faults).
#[derive(Clone, Debug, PartialEq, Serialize)]
#[serde(tag = "event", rename_all = "snake_case")]
pub enum SimEvent {
    /// A goal became known to the team.
    GoalIdentified {
        /// Goal id.
        goal: String,
        /// Who identified it.
        by: String,
        /// Where, metres.
        position: [f64; 2],
    },
    /// A robot took a claim on a goal (as seen in its own team state).
    GoalClaimed {
        /// Goal id.
        goal: String,
        /// Claimant.
        by: String,
    },
    /// A robot gave up its claim.
    GoalReleased {
        /// Goal id.
        goal: String,
        /// Former claimant.
        by: String,
    },
    /// A goal was visited.
    GoalVisited {
        /// Goal id.
        goal: String,
        /// Visitor.
        by: String,
    },
    /// The simulator refused a UGV's commanded motion for [`STUCK_AFTER_S`] on end (wedged: every
    /// move collides); counted in its summary's `stuck_events` and reported as a problem.
    RobotStuck {
        /// Robot id.
        robot: String,
        /// Where (ground truth), metres.
        position: [f64; 2],
    },
    /// A robot was killed (fault injection).
    RobotKilled {
        /// Robot id.
        robot: String,
    },
    /// A goal was cancelled by the operator (first seen in a robot's team state).
    GoalCancelled {
        /// Goal id.
        goal: String,
        /// The cancelling command.
        by: String,
    },
    /// The operator issued a command (`sim.operator`, issue 37).
    OperatorCommand {
        /// Command id (`operator#3`).
        command: String,
        /// `goal_add`, `goal_cancel`, `goal_priority`, `recall`, `hold` or `resume`.
        kind: String,
        /// The command in words.
        action: String,
    },
    /// A robot applied an operator command (its acknowledgement record, as its own team state
    /// holds it).
    OperatorAcknowledged {
        /// Command id.
        command: String,
        /// The robot.
        robot: String,
    },
    /// The mission ended.
    MissionEnded {
        /// How.
        outcome: Outcome,
    },
}

/// A robot's state at a step, for observers.
#[derive(Clone, Copy, Debug)]
pub struct RobotSnapshot {
    /// What the robot is.
    pub kind: RobotKind,
    /// Ground-truth pose.
    pub truth: Pose2,
    /// Height of the body above the datum (UAV altitude, UGV ground elevation), metres.
    pub z_m: f64,
    /// The robot's own estimate.
    pub estimate: Option<PoseEstimate>,
    /// Velocity command in force (UGVs).
    pub command: Twist2,
}

/// Receives everything a run produces: what each robot saw and did (the robot layer's
/// [`RobotObserver`]: seam calls, transitions, problems, scans, paths, and the odometry and
/// panoramas of every robot, driven ones included) and what only the simulator knows (below).
/// Every method has an empty default.
pub trait SimObserver: RobotObserver {
    /// Each robot's state, every `record_period_s` (see [`SimObserver::record_period_s`]).
    fn on_state(&mut self, _robot: &RobotId, _now: Time, _state: &RobotSnapshot) {}
    /// The obstacle mask of the terrain analysis of a panorama (row-major in its geometry).
    fn on_terrain(&mut self, _robot: &RobotId, _stamp: Time, _geometry: PanoramaGeometry, _obstacle: &[bool]) {}
    /// A team-level event.
    fn on_event(&mut self, _now: Time, _event: &SimEvent) {}
    /// The aerial map as it grows: a robot's copy of the map when it publishes a new version
    /// to the team (the mapping UAV, every `map_publish_period_s` while the map changes), and
    /// once at the start when the robots begin with a prior map. Checked once a simulated
    /// second.
    fn on_map(&mut self, _robot: &RobotId, _now: Time, _map: &AerialMap) {}
    /// How often `on_state` is called, seconds.
    fn record_period_s(&self) -> f64 {
        0.1
    }
}

/// An observer that keeps nothing.
pub struct NoObserver;

impl SimObserver for NoObserver {}

impl RobotObserver for NoObserver {}
