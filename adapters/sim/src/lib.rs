//! Built-in 2.5D simulator: worlds, UGV/UAV/sensor/radio models.
//!
//! The crate is an adapter: it may read and write world files, but every model is a plain,
//! deterministic state machine stepped with the time passed in and a seeded RNG. The lockstep
//! runner ([`run`]) owns the clock and the robots' behaviour trees and calls into these models.
//!
//! - [`World`]: class, elevation and colour layers at 0.5 m, the class table and ground truth;
//!   [`generate_city`] builds one, [`World::load`] / [`World::save`] read and write world files,
//!   [`render_png`] draws one.
//! - [`UgvLimits`] and [`ground_truth_traversability`]: what a ground robot can physically drive.
//! - [`Ugv`]: skid-steer kinematics with acceleration limits and collisions; [`OdometryModel`];
//!   [`NoisyPoseSource`] (ground truth with noise, the paper's localization stand-in).
//! - [`PanoramaRenderer`]: depth + semantic panoramas in the core convention.
//! - [`Uav`] and [`OrthoCamera`]: waypoint flight and the orthomap tiles its camera reveals.
//! - [`Radio`] and [`Faults`]: which links carry which tiers, byte budgets, blackouts, kills.
//! - [`run::Simulation`]: a whole mission in lockstep simulated time (the `spomp sim` engine).

mod city;
mod error;
mod files;
mod panorama;
mod radio;
pub mod run;
mod terrain;
mod uav;
mod ugv;
mod world;

pub use city::{CityParams, generate_city};
pub use error::SimError;
pub use files::{
    AerialLayers, ClassTableSource, DerivedElevationParams, ElevationLayer, LayerFiles, MAX_DEPTH_PNG_BYTES,
    MAX_WORLD_CELLS, RESOLUTION_RANGE_M, WORLD_FILE, WorldFile, decode_depth_png, read_depth_png, render_png,
};
pub use panorama::{PanoramaRenderer, PanoramaSensor, SensorParams};
pub use radio::{Blackout, Faults, KillFault, Link, LinkTier, Radio, RadioNode, RadioParams, Region};
pub use terrain::{
    FootprintHeights, Obstacle, UgvLimits, footprint_heights, ground_truth_traversability, reachable_cells,
};
pub use uav::{OrthoCamera, Uav, UavParams};
pub use ugv::{NoisyPoseSource, OdometryModel, OdometryNoiseParams, PoseNoiseParams, Ugv, UgvParams, UgvStep};
pub use world::{World, WorldMeta};
