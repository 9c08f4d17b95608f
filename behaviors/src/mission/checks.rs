//! What the mission language leaves to the layer that turns a mission into robots
//! (`spomp-robot`), registered beside the node types so the language stays below that layer
//! and the engine knows nothing of either.

use std::sync::Arc;

use crate::registry::{NodeCatalog, NodeRegistry};

use super::schema::MissionFile;

/// A problem the robot layer found in a mission, at a field path of the mission file
/// (`["team", "2", "navigation", "terrain", "inflation_m"]`).
#[derive(Clone, Debug, PartialEq)]
pub struct RobotProblem {
    /// Field path in the mission file (mapping keys and list indices).
    pub path: Vec<String>,
    /// What is wrong, in the skill's words.
    pub message: String,
}

/// The robots' `navigation:` settings, whose types, defaults and rules are the skills', and
/// the checks of every parameter the skills validate: what the robot layer resolves and the
/// language points at with a line and column.
pub trait RobotChecks: Send + Sync {
    /// The JSON Schema of a `navigation:` section (with its own `$defs`).
    fn navigation_schema(&self) -> serde_json::Value;
    /// Checks every robot of a typed mission as the robot layer will set it up.
    fn check(&self, mission: &MissionFile) -> Vec<RobotProblem>;
    /// What the robot layer finds questionable but valid (e.g. a role that ignores the
    /// operator's holds and recalls), given the node types each role's tree uses (its subtrees
    /// expanded): reported as warnings.
    fn warnings(
        &self,
        _mission: &MissionFile,
        _role_nodes: &std::collections::BTreeMap<String, std::collections::BTreeSet<String>>,
    ) -> Vec<RobotProblem> {
        Vec::new()
    }
}

/// The registered checks, as the registry keeps them (one value per type).
struct RegisteredChecks(Arc<dyn RobotChecks>);

impl<E> NodeRegistry<E> {
    /// Sets the robot layer's checks of robot settings (see [`RobotChecks`]).
    pub fn set_robot_checks(&mut self, checks: Arc<dyn RobotChecks>) {
        self.set_extension(RegisteredChecks(checks));
    }
}

impl NodeCatalog {
    /// The robot layer's checks, when a robot layer is registered.
    pub fn robot_checks(&self) -> Option<&dyn RobotChecks> {
        self.extension::<RegisteredChecks>().map(|c| &*c.0)
    }
}
