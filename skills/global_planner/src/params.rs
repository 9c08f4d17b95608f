//! Parameters of the global planner (docs/design.md §5 "Global planner", paper §Global Ground Planner).

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use crate::error::SetupError;

/// All parameters of the global planner, grouped as a mission file nests them.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct GlobalPlannerParams {
    /// Traversability graph construction over the aerial map.
    pub graph: GraphParams,
    /// Learned traversability (MLP over aerial features).
    pub learning: LearningParams,
    /// Edge updates from reachability scans.
    pub experience: ExperienceParams,
    /// Which reachability scans a robot shares with the team.
    pub sharing: SharingParams,
    /// Graph search and replanning.
    pub search: SearchParams,
}

impl GlobalPlannerParams {
    /// Checks every field's range. Bounds keep every buffer and loop sized sensibly whatever a
    /// mission file says; `graph.class_order` is checked against the class table when the
    /// planner is built.
    pub fn validate(&self) -> Result<(), SetupError> {
        let params = self;
        let g = &params.graph;
        let l = &params.learning;
        let x = &params.experience;
        let in_range = |v: f64, lo: f64, hi: f64| v.is_finite() && v >= lo && v <= hi;
        // Bounds keep every buffer and loop sized sensibly whatever a mission file says.
        let checks: [(&'static str, bool, &str); 15] = [
            ("graph.visibility_range_m", in_range(g.visibility_range_m, 0.1, 500.0), "must be in [0.1, 500] m"),
            ("graph.edge_sample_spacing_m", in_range(g.edge_sample_spacing_m, 0.05, 100.0), "must be in [0.05, 100] m"),
            ("graph.attach_radius_m", in_range(g.attach_radius_m, 0.0, 200.0), "must be in [0, 200] m"),
            ("learning.hidden_units", (1..=1024).contains(&l.hidden_units), "must be in 1..=1024"),
            ("learning.rmsprop_decay", in_range(l.rmsprop_decay, 0.0, 0.999_999), "must be in [0, 1)"),
            ("learning.step_size", in_range(l.step_size, 1e-9, 10.0), "must be in (0, 10]"),
            ("learning.rmsprop_epsilon", in_range(l.rmsprop_epsilon, 0.0, 1.0), "must be in [0, 1]"),
            ("learning.l2_regularization", in_range(l.l2_regularization, 0.0, 100.0), "must be in [0, 100]"),
            ("learning.not_trav_depth_m", in_range(l.not_trav_depth_m, 0.0, 50.0), "must be in [0, 50] m"),
            ("learning.max_scan_range_m", in_range(l.max_scan_range_m, 0.1, 500.0), "must be in [0.1, 500] m"),
            ("experience.on_edge_radius_m", in_range(x.on_edge_radius_m, 0.0, 50.0), "must be in [0, 50] m"),
            ("experience.min_crossing_range_m", in_range(x.min_crossing_range_m, 0.0, 50.0), "must be in [0, 50] m"),
            ("experience.teammate_clearance_m", in_range(x.teammate_clearance_m, 0.0, 20.0), "must be in [0, 20] m"),
            ("experience.teammate_max_age_s", in_range(x.teammate_max_age_s, 0.0, 600.0), "must be in [0, 600] s"),
            (
                "experience.crossing_window_rad",
                in_range(x.crossing_window_rad, 0.0, std::f64::consts::PI),
                "must be in [0, π] rad",
            ),
        ];
        if let Some((name, _, reason)) = checks.iter().find(|c| !c.1) {
            return Err(SetupError::InvalidParameter { name, reason: (*reason).into() });
        }
        if let Some(step) = g.max_step_m
            && !(step.is_finite() && step > 0.0 && step <= 100.0)
        {
            return Err(SetupError::InvalidParameter {
                name: "graph.max_step_m",
                reason: "must be in (0, 100] m, or null to keep every edge straight".into(),
            });
        }
        Ok(())
    }
}

/// Graph construction: greedy farthest-point coverage with ray-traced visibility regions.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct GraphParams {
    /// Radius of the region ray traced around each node, metres.
    pub visibility_range_m: f64,
    /// Class names covered one after the other (easiest first). Empty: the class table's
    /// `easiest_first()` order, keeping classes with rank ≤ `max_class_rank`.
    pub class_order: Vec<String>,
    /// Hardest class rank the graph covers when `class_order` is empty (5 = impassable).
    pub max_class_rank: u8,
    /// How far from a start or goal point to look for a covered cell to attach to, metres.
    pub attach_radius_m: f64,
    /// Spacing of the samples along an edge at which traversability is evaluated, metres.
    pub edge_sample_spacing_m: f64,
    /// Highest elevation step between neighbouring aerial-map cells a UGV drives over, metres.
    /// An edge whose straight line crosses a higher step (a curb, the side of a parked vehicle)
    /// follows a step-free route through the two nodes' regions instead, when there is one (a
    /// curb ramp; the route rises at most half this much from cell to cell, what terrain
    /// analysis does not flag); otherwise it stays straight for experience to judge. `null`: edges are
    /// always straight (for aerial maps whose elevation cannot resolve curbs).
    pub max_step_m: Option<f64>,
    /// Make an edge that stays straight up a curb (a step above `max_step_m` and at most 0.5 m
    /// high, with no route round it) a last resort: 10⁹ is added to its cost until a scan finds
    /// it traversable, so a path climbs such a curb only when nothing else joins the two sides.
    /// Scans seldom judge a curb before the robot is at its foot, where it is wedged. With graph
    /// updates off it has no effect. Off by default: it sends robots up far ramps instead of to
    /// the curb's foot, which pays where goals lie up on sidewalks and costs a little where they
    /// do not (ten-seed comparisons in the global planner README).
    pub curbs_last_resort: bool,
}

impl Default for GraphParams {
    fn default() -> Self {
        GraphParams {
            visibility_range_m: 15.0,
            class_order: Vec::new(),
            max_class_rank: 4,
            attach_radius_m: 5.0,
            edge_sample_spacing_m: 1.0,
            max_step_m: Some(0.1),
            curbs_last_resort: false,
        }
    }
}

/// Learned traversability T(p) = f(C(p), S(p), h(p)): an MLP trained online from scans.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct LearningParams {
    /// Learn traversability; when off, edges use the class-rank cost W = 100^T_cls − 1 + D.
    pub enabled: bool,
    /// Hidden-layer width (sigmoid units).
    pub hidden_units: usize,
    /// L2 regularisation factor on the weights.
    pub l2_regularization: f64,
    /// RMSProp step size.
    pub step_size: f64,
    /// RMSProp decay of the squared-gradient average.
    pub rmsprop_decay: f64,
    /// RMSProp denominator epsilon.
    pub rmsprop_epsilon: f64,
    /// Samples per mini-batch.
    pub batch_size: usize,
    /// Samples drawn (with replacement) per training round.
    pub samples_per_round: usize,
    /// Minimum simulated time between training rounds, seconds.
    pub train_period_s: f64,
    /// Net votes a cell needs before it becomes a training label.
    pub votes_to_label: u8,
    /// Depth beyond a known obstacle whose cells vote "not traversable", metres.
    pub not_trav_depth_m: f64,
    /// Scan ranges are clipped to this, metres (bounds the work per scan).
    pub max_scan_range_m: f64,
    /// Distance-to-class features saturate at this distance, metres.
    pub class_distance_cap_m: f64,
    /// Labels needed before the first training round.
    pub min_labels: usize,
    /// Probabilities are clamped to at least this before taking −log.
    pub probability_floor: f64,
}

impl Default for LearningParams {
    fn default() -> Self {
        LearningParams {
            enabled: true,
            hidden_units: 10,
            l2_regularization: 0.01,
            step_size: 0.01,
            rmsprop_decay: 0.99,
            rmsprop_epsilon: 1e-8,
            batch_size: 32,
            samples_per_round: 8192,
            train_period_s: 10.0,
            votes_to_label: 3,
            not_trav_depth_m: 3.0,
            max_scan_range_m: 30.0,
            class_distance_cap_m: 25.0,
            min_labels: 20,
            probability_floor: 1e-4,
        }
    }
}

/// Edge state updates from reachability scans (trav / not_trav / unk_trav).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct ExperienceParams {
    /// Update edge states from scans; when off, edges never change state (paper ablation).
    pub graph_updates: bool,
    /// Consistent observations needed to mark an edge trav or not_trav.
    pub observations_to_mark: u32,
    /// Consistent not_trav observations needed to overturn an edge marked trav.
    pub observations_to_overturn_trav: u32,
    /// Δφ: half-width of the window around a single crossing searched for unknown bins, radians.
    pub crossing_window_rad: f64,
    /// An edge passing within this distance of a scan's origin (the robot driving it) is judged
    /// from the origin's projection onto the edge to each end, as the authors' implementation
    /// judges the edge being driven from the robot's position; a blockage mid-edge is then seen
    /// although both ends lie beyond the safe region. 0 judges every edge end to end only, metres.
    pub on_edge_radius_m: f64,
    /// A single crossing of the safe region's boundary nearer to the robot than this says
    /// unknown, not blocked: so near, the boundary is the robot's own clearance from an
    /// obstacle beside it (the local planner's inflation), not what lies along the edge, metres.
    pub min_crossing_range_m: f64,
    /// Traversal probability per sample assumed along an edge marked trav.
    pub trav_sample_probability: f64,
    /// Traversal probability per sample charged (in addition) along an edge marked not_trav
    /// that is not removed (marked from other robots' scans).
    pub not_trav_sample_probability: f64,
    /// A scan bin whose obstacle lies within this distance of a ground teammate's last known
    /// position ends at the teammate ([`bins_ending_at_teammates`](crate::bins_ending_at_teammates)),
    /// and an edge the robot's own scan judges not_trav where it crosses the boundary at such a
    /// bin is marked, never removed ([`GlobalPlanner::add_own_scan_among`](crate::GlobalPlanner::add_own_scan_among)):
    /// a teammate standing in the road is not terrain. Covers the teammate's body, the safe region's
    /// inflation in front of it and both robots' localization error. 0 turns this off, metres.
    pub teammate_clearance_m: f64,
    /// Teammate positions older than this are not used for that test, seconds.
    pub teammate_max_age_s: f64,
}

impl Default for ExperienceParams {
    fn default() -> Self {
        ExperienceParams {
            graph_updates: true,
            observations_to_mark: 2,
            observations_to_overturn_trav: 4,
            crossing_window_rad: 0.3,
            on_edge_radius_m: 3.0,
            min_crossing_range_m: 1.0,
            trav_sample_probability: 0.99,
            not_trav_sample_probability: 0.01,
            teammate_clearance_m: 2.0,
            teammate_max_age_s: 2.0,
        }
    }
}

/// The paper's three terrain communication modes.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum SharingMode {
    /// Share no scans.
    None,
    /// Share a scan only if it is far enough from every scan shared before.
    #[default]
    Downsampled,
    /// Share every scan.
    All,
}

/// Scan sharing filter.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct SharingParams {
    /// Communication mode.
    pub mode: SharingMode,
    /// In `downsampled` mode, minimum distance to every scan shared before, metres.
    pub min_separation_m: f64,
}

impl Default for SharingParams {
    fn default() -> Self {
        SharingParams { mode: SharingMode::Downsampled, min_separation_m: 2.0 }
    }
}

/// Search and replanning.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct SearchParams {
    /// A path needs replanning when its cost rose by more than this fraction.
    pub replan_cost_rise_ratio: f64,
}

impl Default for SearchParams {
    fn default() -> Self {
        SearchParams { replan_cost_rise_ratio: 0.2 }
    }
}
