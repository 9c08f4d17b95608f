//! Parameters of the team database (docs/design.md §5 "Team state", "Goal coordination").

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use crate::error::TeamStateError;

/// Parameters of the replicated team database.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct TeamStateParams {
    /// Goals closer than this to each other are one goal for deconfliction (paper: 10 m), metres.
    pub deconfliction_radius_m: f64,
    /// A robot shares a new reachability scan only if it lies at least this far from every scan
    /// it shared before (paper §Communication: 2 m); 0 shares every scan, metres.
    pub scan_min_spacing_m: f64,
    /// Largest encoded sync message `apply_bytes` accepts, bytes.
    pub max_message_bytes: usize,
    /// Most bins a reachability scan may have to be accepted.
    pub max_scan_bins: usize,
    /// Largest aerial-map blob accepted, bytes.
    pub max_map_blob_bytes: usize,
    /// Sent messages kept per peer awaiting acknowledgement before the oldest is presumed lost
    /// (at most 64, the width of the acknowledgement window).
    pub max_in_flight_messages: usize,
    /// A claim is a lease: its holder renews it every half lease while it holds the goal
    /// ([`crate::TeamState::advance_clock`]); a claim of another robot not renewed for this long
    /// no longer counts (a dead robot, or one out of contact that long, gives up its goals).
    /// Seconds.
    pub claim_lease_s: f64,
    /// A peer's record stamped further than this ahead of this robot's clock is left out
    /// (counted): robots' clocks differ a little, but a claim stamped far in the future would
    /// stay unclaimable long past its lease. Seconds.
    pub max_clock_ahead_s: f64,
}

impl Default for TeamStateParams {
    fn default() -> Self {
        TeamStateParams {
            deconfliction_radius_m: spomp_core::DEFAULT_DECONFLICTION_RADIUS_M,
            scan_min_spacing_m: 2.0,
            max_message_bytes: 16 * 1024 * 1024,
            max_scan_bins: 8192,
            max_map_blob_bytes: 8 * 1024 * 1024,
            max_in_flight_messages: 64,
            claim_lease_s: 300.0,
            max_clock_ahead_s: 30.0,
        }
    }
}

impl TeamStateParams {
    /// Checks ranges; returns the first problem found.
    pub fn validate(&self) -> Result<(), TeamStateError> {
        let bad = |name, reason| Err(TeamStateError::InvalidParams { name, reason });
        if !(self.deconfliction_radius_m.is_finite() && self.deconfliction_radius_m >= 0.0) {
            return bad("deconfliction_radius_m", "must be finite and ≥ 0");
        }
        if !(self.scan_min_spacing_m.is_finite() && self.scan_min_spacing_m >= 0.0) {
            return bad("scan_min_spacing_m", "must be finite and ≥ 0");
        }
        if self.max_message_bytes == 0 || self.max_scan_bins == 0 || self.max_map_blob_bytes == 0 {
            return bad("max_message_bytes", "max_message_bytes, max_scan_bins and max_map_blob_bytes must be > 0");
        }
        if !(self.claim_lease_s.is_finite() && self.claim_lease_s > 0.0) {
            return bad("claim_lease_s", "must be finite and > 0");
        }
        if !(self.max_clock_ahead_s.is_finite() && self.max_clock_ahead_s >= 0.0) {
            return bad("max_clock_ahead_s", "must be finite and ≥ 0");
        }
        if !(1..=64).contains(&self.max_in_flight_messages) {
            return bad("max_in_flight_messages", "must be in 1..=64");
        }
        Ok(())
    }
}
