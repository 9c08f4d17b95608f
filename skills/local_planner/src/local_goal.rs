//! Local goal selection: uniform samples in the safe region, cost
//! C(x) = ‖x − G‖ + α·|x × g_old| / ‖g_old‖ (paper §Local Ground Planner, Controller).

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};
use spomp_core::Point2;

use crate::error::{ParamsError, non_negative};
use crate::region::SafeRegion;

/// Parameters of local goal selection.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct LocalGoalParams {
    /// Number of uniform samples drawn in the safe region.
    pub samples: u32,
    /// α: weight of the consistency term |x × g_old| / ‖g_old‖ (metres per metre).
    pub consistency_weight: f64,
    /// Also score the global goal itself when it lies inside the safe region, so that a goal in
    /// plain sight is taken exactly rather than approximated by the nearest sample.
    pub include_goal: bool,
}

impl Default for LocalGoalParams {
    fn default() -> Self {
        LocalGoalParams { samples: 1000, consistency_weight: 0.2, include_goal: true }
    }
}

impl LocalGoalParams {
    /// Checks every field's range.
    pub fn validate(&self) -> Result<(), ParamsError> {
        non_negative("consistency_weight", self.consistency_weight)
    }
}

/// C(x): distance to the global goal plus α times the distance of x from the line through the
/// robot along the previous local goal.
#[inline]
pub fn local_goal_cost(x: Point2, goal: Point2, previous: Option<Point2>, alpha: f64) -> f64 {
    let mut cost = x.distance(goal);
    if let Some(g_old) = previous {
        let norm = g_old.norm();
        if norm > 0.0 && norm.is_finite() {
            cost += alpha * x.cross(g_old).abs() / norm;
        }
    }
    cost
}

/// The new local goal g = argmin C(x) over `params.samples` uniform samples of `region`, all in
/// the region's (robot) frame. `goal` is the global goal G, `previous` the last local goal
/// g_old. `None` when the region has no area, the goal is not finite or no sample was drawn.
pub fn select_local_goal(
    region: &SafeRegion,
    goal: Point2,
    previous: Option<Point2>,
    params: &LocalGoalParams,
    rng: &mut impl rand::Rng,
) -> Option<Point2> {
    if !(goal.x.is_finite() && goal.y.is_finite()) {
        return None;
    }
    let previous = previous.filter(|p| p.x.is_finite() && p.y.is_finite());
    let alpha = if params.consistency_weight.is_finite() { params.consistency_weight } else { 0.0 };
    let mut best: Option<(f64, Point2)> = None;
    let mut consider = |x: Point2| {
        let c = local_goal_cost(x, goal, previous, alpha);
        if best.is_none_or(|(bc, _)| c < bc) {
            best = Some((c, x));
        }
    };
    if params.include_goal && region.area_m2() > 0.0 && region.contains(goal) {
        consider(goal);
    }
    for _ in 0..params.samples {
        match region.sample_uniform(rng) {
            Some(x) => consider(x),
            None => break,
        }
    }
    best.map(|(_, x)| x)
}
