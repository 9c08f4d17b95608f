//! Identifiers of robots and goals.

use std::fmt;
use std::sync::Arc;

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

/// A robot's id as written in the mission (`ugv1`, `uav`, `base`).
///
/// Cheap to clone (a shared string): ids travel in every team-state record.
#[derive(Clone, Debug, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize, JsonSchema)]
#[serde(transparent)]
pub struct RobotId(#[schemars(with = "String")] Arc<str>);

impl RobotId {
    /// A robot id.
    pub fn new(id: &str) -> Self {
        RobotId(Arc::from(id))
    }

    /// The id as text.
    pub fn as_str(&self) -> &str {
        &self.0
    }
}

impl fmt::Display for RobotId {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.0)
    }
}

impl From<&str> for RobotId {
    fn from(s: &str) -> Self {
        RobotId::new(s)
    }
}

/// Goals closer than this to each other are one goal, metres (the paper's 10 m): the default
/// of the team state's deconfliction (claims, preemption) and of goal detection's
/// deduplication, which a mission sets once for both (`goals.deconfliction_radius_m`). A
/// convention both skills share, so it lives with the goal's identity.
pub const DEFAULT_DECONFLICTION_RADIUS_M: f64 = 10.0;

/// A goal's id, unique across the team: the robot that first identified it and a counter.
#[derive(Clone, Debug, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize, JsonSchema)]
pub struct GoalId {
    /// The robot (or `mission` / the basestation) that created the goal.
    pub origin: RobotId,
    /// Sequence number at the origin.
    pub seq: u32,
}

impl fmt::Display for GoalId {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}/{}", self.origin, self.seq)
    }
}

/// What kind of robot a team member is.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum RobotKind {
    /// A ground vehicle.
    Ugv,
    /// An aerial vehicle.
    Uav,
    /// A fixed basestation (radio and operator).
    Basestation,
}

impl RobotKind {
    /// The name used in missions.
    pub fn as_str(self) -> &'static str {
        match self {
            RobotKind::Ugv => "ugv",
            RobotKind::Uav => "uav",
            RobotKind::Basestation => "basestation",
        }
    }
}

impl fmt::Display for RobotKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}
