//! What a run reports: per goal, per robot and for the mission (the paper's metrics).

use serde::{Deserialize, Serialize};

/// How a run ended.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Outcome {
    /// The mission's `complete_when` held.
    Complete,
    /// The time limit passed first.
    TimeLimit,
    /// Every robot died.
    AllDead,
    /// The run was stopped before it ended (Ctrl-C, SIGTERM, a dry run's wall-time cap): the
    /// summary covers what ran.
    Interrupted,
}

impl Outcome {
    /// Whether the mission succeeded.
    pub fn succeeded(self) -> bool {
        self == Outcome::Complete
    }
}

/// One goal as the team came to know it (earliest events over all robots).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct GoalSummary {
    /// Goal id (`ugv1/3`, `mission/0`).
    pub id: String,
    /// Map-frame position, metres.
    pub position: [f64; 2],
    /// `detected`, `mission` or `basestation`.
    pub origin: String,
    /// When it was first identified, seconds.
    pub identified_s: f64,
    /// Who identified it first.
    pub identified_by: String,
    /// When it was first claimed, seconds.
    pub claimed_s: Option<f64>,
    /// Who claimed it first.
    pub claimed_by: Option<String>,
    /// When it was first visited, seconds.
    pub visited_s: Option<f64>,
    /// Who visited it first.
    pub visited_by: Option<String>,
    /// Visits of this goal (or one within the deconfliction radius) after the first, by robots
    /// that were in radio contact (directly or relayed within the last 10 s) with the first
    /// visitor when they arrived; should be 0.
    pub revisits_in_contact: u32,
    /// When a robot first held the operator's cancel of it, seconds (issue 37); absent if never.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub cancelled_s: Option<f64>,
}

/// Median and maximum of an error series.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct ErrorStats {
    /// Median, metres.
    pub median: f64,
    /// Maximum, metres.
    pub max: f64,
    /// Samples (one per panorama).
    pub samples: usize,
}

impl ErrorStats {
    /// Stats of `values` (None when empty).
    pub fn of(values: &[f64]) -> Option<ErrorStats> {
        if values.is_empty() {
            return None;
        }
        let mut v = values.to_vec();
        v.sort_by(f64::total_cmp);
        let n = v.len();
        let median = if n % 2 == 1 { v[n / 2] } else { 0.5 * (v[n / 2 - 1] + v[n / 2]) };
        Some(ErrorStats { median, max: v[n - 1], samples: n })
    }
}

/// One robot's run.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RobotSummary {
    /// Robot id.
    pub id: String,
    /// `ugv`, `uav` or `basestation`.
    pub kind: String,
    /// Distance travelled (ground truth), metres.
    pub distance_m: f64,
    /// Fraction of the mission time spent holding a claim on a goal it eventually visited (the
    /// paper's "time heading to a goal").
    pub heading_to_goal_fraction: f64,
    /// Seconds from the first second in which it moved to the last (sampled once a simulated
    /// second; slower than 5 cm/s counts as still): for a robot sent on one trip, how long the
    /// trip took. `None` if it never moved.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub travel_time_s: Option<f64>,
    /// Times it drove into an obstacle.
    pub collisions: u64,
    /// Times the simulator refused its commanded motion for `STUCK_AFTER_S` (5 s) on end
    /// (wedged: every move collides), each also reported as a problem (UGVs).
    #[serde(default)]
    pub stuck_events: u64,
    /// Longest time it stood still (within 0.25 m, sampled once a second) while its tree was
    /// driving it (a velocity command in force, or a drive with a planned path running),
    /// seconds (UGVs).
    #[serde(default)]
    pub longest_motionless_driving_s: f64,
    /// Where its pose came from: `cross_view`, `ground_truth` or `gps`.
    pub localization: String,
    /// Localization error against ground truth, per panorama (UGVs).
    pub localization_error_m: Option<ErrorStats>,
    /// Goals it visited first.
    pub goals_visited: u32,
    /// When it was killed (fault injection), seconds.
    pub killed_s: Option<f64>,
    /// Root status of its tree at the end.
    pub tree_status: String,
    /// The navigation settings in force (UGVs): the profile's values with the mission's
    /// `navigation:` layers over them.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub navigation: Option<NavigationInForce>,
}

/// The navigation settings a UGV ran with, the ones the paper's ablations switch.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct NavigationInForce {
    /// Learned traversability on (MLP) or off (class ranks).
    pub learning: bool,
    /// Edge updates from reachability scans on or off.
    pub graph_updates: bool,
    /// Terrain-scan sharing: none, downsampled or all.
    pub sharing: String,
    /// Terrain slope threshold.
    pub slope_threshold: f64,
    /// Terrain inflation, metres.
    pub inflation_m: f64,
    /// DWA speed limit, m/s.
    pub max_speed_mps: f64,
    /// Driving nodes' default stuck timeout, seconds.
    pub stuck_timeout_s: f64,
}

/// Ground-truth clusters of the world against the goals the team found.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct ClusterSummary {
    /// Vehicle clusters in the world.
    pub total: usize,
    /// Clusters with an identified goal within `match_radius_m`.
    pub found: usize,
    /// Clusters with a visited goal within `match_radius_m`.
    pub visited: usize,
    /// How close a goal must be to a cluster centre to count for it, metres.
    pub match_radius_m: f64,
}

/// The summary of one simulated run.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RunSummary {
    /// Mission name.
    pub mission: String,
    /// Trial seed.
    pub seed: u64,
    /// How it ended.
    pub outcome: Outcome,
    /// Simulated time at the end, seconds.
    pub end_s: f64,
    /// The mission's time limit, seconds.
    pub time_limit_s: f64,
    /// Which navigation ran (always the real skills in this build).
    pub navigation: String,
    /// Goals, in order of identification.
    pub goals: Vec<GoalSummary>,
    /// Goals visited / known.
    pub goals_visited: usize,
    /// World clusters found and visited (generated worlds).
    pub clusters: Option<ClusterSummary>,
    /// Robots, in mission order.
    pub robots: Vec<RobotSummary>,
    /// Wall-clock seconds the run took (not part of the deterministic result).
    pub wall_s: f64,
    /// Simulated seconds per wall-clock second.
    pub speedup: f64,
    /// Nodes that were ticked at least once / nodes in all trees.
    pub nodes_exercised: usize,
    /// Total nodes in all trees.
    pub nodes_total: usize,
    /// Node paths (`robot: path`) never ticked.
    pub nodes_never_ticked: Vec<String>,
    /// Problems nodes and skills reported (first occurrences, with counts).
    pub problems: Vec<ProblemCount>,
    /// The operator's commands (`sim.operator`) and which robots applied them; absent without.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub operator: Vec<super::OperatorCommandSummary>,
    /// The team-state traffic over the operator's links (`sim.operator`); absent without one.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub operator_link: Option<super::OperatorTraffic>,
}

/// A reported problem and how often it came up.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ProblemCount {
    /// Robot id.
    pub robot: String,
    /// The message.
    pub message: String,
    /// How many times.
    pub count: u64,
    /// First time, seconds.
    pub first_s: f64,
}

impl RunSummary {
    /// The same summary without its wall-clock figures (for determinism checks).
    pub fn deterministic_part(&self) -> RunSummary {
        RunSummary { wall_s: 0.0, speedup: 0.0, ..self.clone() }
    }
}
