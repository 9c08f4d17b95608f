//! Parameters of the mapping skill (docs/design.md §5 "Mapping").

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use crate::error::MappingError;

/// Goal detection in the aerial class map (paper §High-Level Coordination).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct GoalDetectionParams {
    /// Name of the class whose clusters are goals (from the class table).
    pub class: String,
    /// Clusters of the class closer than this merge into one (morphological close with a disk of
    /// half this radius), metres.
    pub merge_distance_m: f64,
    /// A cluster counts only if the larger side of its bounding box is at least this long,
    /// metres.
    pub min_size_m: f64,
    /// The goal is placed within this distance of its cluster, metres.
    pub placement_region_m: f64,
    /// Radius of the morphological open that removes specks before merging, metres (0 = off).
    pub open_radius_m: f64,
    /// Preferred clearance from obstacles at the goal: the easiest class offering a cell this
    /// far from obstacles wins; if none does, the clearest cell of any class is used, metres.
    pub min_clearance_m: f64,
    /// Detected goals within this distance of a known goal (or of each other) are dropped,
    /// metres.
    pub deconfliction_radius_m: f64,
}

impl Default for GoalDetectionParams {
    fn default() -> Self {
        GoalDetectionParams {
            class: "vehicle".into(),
            merge_distance_m: 15.0,
            min_size_m: 8.0,
            placement_region_m: 7.0,
            open_radius_m: 0.5,
            min_clearance_m: 1.0,
            deconfliction_radius_m: spomp_core::DEFAULT_DECONFLICTION_RADIUS_M,
        }
    }
}

impl GoalDetectionParams {
    /// Checks ranges.
    pub fn validate(&self) -> Result<(), MappingError> {
        let fields = [
            ("merge_distance_m", self.merge_distance_m),
            ("min_size_m", self.min_size_m),
            ("placement_region_m", self.placement_region_m),
            ("open_radius_m", self.open_radius_m),
            ("min_clearance_m", self.min_clearance_m),
            ("deconfliction_radius_m", self.deconfliction_radius_m),
        ];
        for (name, v) in fields {
            if !(v.is_finite() && v >= 0.0) {
                return Err(MappingError::InvalidParams { name, reason: format!("must be finite and ≥ 0, got {v}") });
            }
        }
        Ok(())
    }
}

/// PNG compression effort for map layers.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum PngLevel {
    /// Fastest, largest.
    Fast,
    /// zlib's default trade-off.
    #[default]
    Default,
    /// Smallest, slowest.
    Best,
}

/// Compression of map layers for transmission.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct CompressionParams {
    /// PNG compression effort.
    pub level: PngLevel,
}

/// All parameters of the mapping skill.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct MappingParams {
    /// Goal detection.
    pub detection: GoalDetectionParams,
    /// Layer compression.
    pub compression: CompressionParams,
}
