//! The mission's `comms:` section, owned by the robot layer: what a link between two robots
//! may carry is the team round's business ([`crate::team_round`]), which the simulator's radio
//! and a robot process's send round (ROS 2, Zenoh) both run, so the bandwidth has one home and
//! one meaning ([`CommsSpec::round_budget_bytes`]). The ranges and `ugv_to_ugv` describe the
//! simulated radio (`spomp-sim` reads them); a real radio decides its own reach.

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};
use spomp_behaviors::mission::{MissionSection, SectionContext};

/// Radio settings (the paper's simulation values by default).
#[derive(Debug, Clone, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct CommsSpec {
    /// Within this range robots exchange positions and claims, metres.
    #[serde(default = "default_pos_range")]
    pub position_range_m: f64,
    /// Within this range robots exchange everything, metres.
    #[serde(default = "default_data_range")]
    pub data_range_m: f64,
    /// Bytes per second per link, each way: what a link between two robots may carry. The
    /// simulator's radio gives a link `bandwidth × step` bytes per step; a robot process over
    /// ROS 2 gives each peer `bandwidth × period` bytes per round of team messages (one round
    /// a second). Unused bytes carry over while the link stays up, so an item larger than one
    /// round's budget (a map version) goes through after enough rounds.
    #[serde(default = "default_bandwidth")]
    pub bandwidth_bytes_per_s: f64,
    /// Disable direct UGV-to-UGV links (data only via the UAV and basestation).
    #[serde(default)]
    pub ugv_to_ugv: Option<bool>,
}

fn default_pos_range() -> f64 {
    50.0
}

fn default_data_range() -> f64 {
    30.0
}

fn default_bandwidth() -> f64 {
    1_000_000.0
}

impl Default for CommsSpec {
    fn default() -> Self {
        CommsSpec {
            position_range_m: default_pos_range(),
            data_range_m: default_data_range(),
            bandwidth_bytes_per_s: default_bandwidth(),
            ugv_to_ugv: None,
        }
    }
}

impl CommsSpec {
    /// What a link may carry in one round of `period_s` seconds, bytes: the bandwidth times the
    /// period, rounded down (0 for a period that is not positive). The simulator's radio (a
    /// step) and a robot process's send round (its team period) both take a link's budget
    /// here.
    pub fn round_budget_bytes(&self, period_s: f64) -> u64 {
        round_budget_bytes(self.bandwidth_bytes_per_s, period_s)
    }
}

/// `bytes_per_s × period_s` bytes, rounded down; 0 for a period that is not positive (the rule
/// of [`CommsSpec::round_budget_bytes`], for a rate given on its own, e.g. the radio's
/// small-tier rate).
pub fn round_budget_bytes(bytes_per_s: f64, period_s: f64) -> u64 {
    if period_s.is_finite() && period_s > 0.0 {
        (bytes_per_s * period_s).floor().min(u64::MAX as f64) as u64
    } else {
        0
    }
}

impl MissionSection for CommsSpec {
    const NAME: &'static str = "comms";
    // `comms: null` was never a way to leave the radio out.
    const NULLABLE: bool = false;

    fn check(&self, _: &SectionContext<'_>, bad: &mut dyn FnMut(&[&str], String)) {
        if self.position_range_m < 0.0 {
            bad(
                &["position_range_m"],
                format!("expected a non-negative distance in metres, found {}", self.position_range_m),
            );
        }
        if self.data_range_m < 0.0 {
            bad(&["data_range_m"], format!("expected a non-negative distance in metres, found {}", self.data_range_m));
        }
        if self.data_range_m > self.position_range_m {
            bad(
                &["data_range_m"],
                format!(
                    "the data range ({} m) cannot exceed the position range ({} m)",
                    self.data_range_m, self.position_range_m
                ),
            );
        }
        if self.bandwidth_bytes_per_s <= 0.0 {
            bad(&["bandwidth_bytes_per_s"], format!("expected a positive rate, found {}", self.bandwidth_bytes_per_s));
        }
    }
}
