//! Aerial orthomap layers, PNG compression for transmission, goal detection and placement.
//!
//! - [`Orthomap`]: the UAV's growing, versioned [`spomp_core::AerialMap`]; each layer is
//!   PNG-compressed for transmission ([`encode_layers`], [`encode_region`], [`decode_region`],
//!   [`decode_map`], [`CompressedMap`]).
//! - [`GoalDetector`]: clusters of a class (vehicles) in the class layer become goals, placed
//!   at the clearest cell of the easiest class near each cluster (paper §High-Level
//!   Coordination, docs/design.md §5 "Mapping").

mod detect;
mod error;
mod orthomap;
mod params;

pub use detect::{DetectedGoal, Detection, GoalDetector};
pub use error::MappingError;
pub use orthomap::{
    CompressedMap, MAX_REGION_CELLS, Orthomap, decode_map, decode_region, encode_layers, encode_region,
};
pub use params::{CompressionParams, GoalDetectionParams, MappingParams, PngLevel};
