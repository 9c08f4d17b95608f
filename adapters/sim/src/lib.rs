//! Built-in 2.5D simulator: UGV/UAV/sensor/radio models and the lockstep runner.
//!
//! The world the models move through is `spomp-world`'s (layers, world files, the city
//! generator, ground-truth terrain): data, shared with `spomp run` and the `spomp world`
//! commands. Every model here is a plain, deterministic state machine stepped with the time
//! passed in and a seeded RNG. The lockstep runner ([`run`]) owns the clock and the robots'
//! behaviour trees and calls into these models.
//!
//! - [`Ugv`]: skid-steer kinematics with acceleration limits and collisions; [`OdometryModel`];
//!   [`NoisyPoseSource`] (ground truth with noise, the paper's localization stand-in).
//! - [`PanoramaRenderer`]: depth + semantic panoramas in the core convention.
//! - [`Uav`] and [`OrthoCamera`]: waypoint flight and the orthomap tiles its camera reveals.
//! - [`Radio`] and [`Faults`]: which links carry which tiers, byte budgets, blackouts, kills.
//! - [`run::Simulation`]: a whole mission in lockstep simulated time (the `spomp sim` engine).

mod error;
mod panorama;
mod radio;
pub mod run;
mod uav;
mod ugv;

#[cfg(test)]
use spomp_world::{CityParams, generate_city};

pub use error::SimError;
pub use panorama::{PanoramaRenderer, PanoramaSensor, SensorParams};
pub use radio::{Blackout, Faults, KillFault, Link, LinkTier, Radio, RadioNode, RadioParams, Region};
pub use uav::{OrthoCamera, Uav, UavParams};
pub use ugv::{NoisyPoseSource, OdometryModel, OdometryNoiseParams, PoseNoiseParams, Ugv, UgvParams, UgvStep};
