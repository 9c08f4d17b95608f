//! Local ground planner of spomp (paper §Local Ground Planner): terrain analysis directly on the
//! depth panorama, the reachability scan S(φ), local goal selection in the known-safe region,
//! and a Dynamic Window Approach controller.
//!
//! Pure library: no threads, no clock, no I/O; randomness comes in as an RNG.
//!
//! Pipeline per panorama:
//! 1. [`TerrainAnalyzer::analyze`] → [`TerrainOutput`] (filled ranges, x/y/z/r, gradient,
//!    obstacles, distance transform, traversable mask, reachability scan);
//! 2. [`SafeRegion::from_terrain`] → the safe star polygon with a clearance table;
//! 3. [`select_local_goal`] → local goal g;
//!
//! and per control period (10 Hz): [`Dwa::step`] / [`Dwa::step_in_region`] → [`spomp_core::Twist2`].

pub mod dwa;
pub mod error;
pub mod local_goal;
pub mod region;
pub mod stages;
pub mod synthetic;
pub mod terrain;

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

pub use dwa::{Dwa, DwaParams};
pub use error::{ParamsError, RegionError, TerrainError};
pub use local_goal::{LocalGoalParams, local_goal_cost, select_local_goal};
pub use region::SafeRegion;
pub use terrain::{InstructionSet, TerrainAnalyzer, TerrainOutput, TerrainParams, TerrainStage};

/// All parameters of the local planner, as a mission sets them (`local_planner: { ... }`).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct LocalPlannerParams {
    /// Terrain analysis and reachability scan.
    pub terrain: TerrainParams,
    /// Local goal selection.
    pub local_goal: LocalGoalParams,
    /// DWA controller.
    pub dwa: DwaParams,
}

impl LocalPlannerParams {
    /// The paper's simulation values (terrain slope threshold 0.25, inflation 0.75 m).
    pub fn simulation() -> Self {
        LocalPlannerParams { terrain: TerrainParams::simulation(), ..Self::default() }
    }

    /// Checks every nested parameter set.
    pub fn validate(&self) -> Result<(), ParamsError> {
        self.terrain.validate()?;
        self.local_goal.validate()?;
        self.dwa.validate()
    }
}
