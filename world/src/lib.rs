//! The world model: what a mission's robots operate in, as data.
//!
//! A world is class, elevation and colour layers on a grid, its class table and the ground
//! truth its author knows (vehicle clusters, roadblocks, start poses, a GPS reference). It is
//! not a simulation: the simulator (`spomp-sim`) moves bodies and sensors through it, `spomp
//! run` takes a real robot's operating area from it, and the `spomp world` commands build,
//! import and draw it. The crate may read and write world files; everything else is
//! deterministic (the city generator takes its seed).
//!
//! - [`World`]: the layers at 0.5 m, the class table and ground truth ([`WorldMeta`]);
//!   [`World::load`] / [`World::save`] read and write world folders ([`WorldFile`]),
//!   [`render_png`] draws one.
//! - [`generate_city`]: the procedural city ([`CityParams`]).
//! - [`UgvLimits`], [`ground_truth_traversability`], [`reachable_cells`]: what a ground robot
//!   can physically drive in the world; [`Obstacle`]: a moving body the world does not hold.
//! - [`world_for_mission`] and [`operating_area`]: a mission's world (its `sim.world`) and the
//!   operating area robots are set up over in it.

mod city;
mod error;
mod files;
mod mission;
pub mod mission_section;
pub mod operator_script;
mod terrain;
mod world;

pub use city::{CityParams, generate_city};
pub use error::WorldError;
pub use files::{
    AerialLayers, ClassTableSource, DerivedElevationParams, ElevationLayer, LayerFiles, MAX_DEPTH_PNG_BYTES,
    MAX_WORLD_CELLS, RESOLUTION_RANGE_M, WORLD_FILE, WorldFile, decode_depth_png, read_depth_png, render_png,
};
pub use mission::{operating_area, world_for_mission};
pub use mission_section::{CircleSpec, FaultSpec, GenerateSpec, SimSpec, WorldSpec};
pub use terrain::{
    FootprintHeights, Obstacle, StandError, UgvLimits, footprint_heights, ground_truth_traversability, reachable_cells,
};
pub use world::{World, WorldMeta};
