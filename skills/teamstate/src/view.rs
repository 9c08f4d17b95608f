//! The deduplicated goal view derived from the goal records.
//!
//! Robots identify goals independently, so the same vehicle cluster may be entered twice under
//! different ids. The records keep every id (nothing is ever lost or rewritten); the view groups
//! them deterministically: goals are taken in order of (identification time, id); a goal within
//! the deconfliction radius of an earlier *canonical* goal becomes an alias of the first such
//! goal, otherwise it is canonical itself. Canonical goals are therefore more than one radius
//! apart, and the grouping is a pure function of the set of goal records, so robots holding the
//! same records see the same goals. Claims, visits and unreachable marks on any alias count for
//! the canonical goal.

use std::collections::HashMap;

use spomp_core::{GoalId, Point2, RobotId, Time};

use crate::record::{GoalOrigin, RecordBody, RecordKey, RecordSet};

/// Status of a goal as the team sees it.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum GoalStatus {
    /// Known, nobody heading there.
    Identified,
    /// Some robot is en route.
    Claimed,
    /// Some robot reached it.
    Visited,
}

/// An active claim.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ClaimInfo {
    /// Claimant.
    pub robot: RobotId,
    /// Its priority (lower = higher).
    pub priority: u32,
    /// When it claimed.
    pub stamp: Time,
}

/// A goal as the team sees it, with its aliases merged in (serialisable: a robot publishes its
/// view for operators and the simulator farm).
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct GoalView {
    /// Canonical id (the earliest identified goal of the group).
    pub id: GoalId,
    /// Other ids identified within the deconfliction radius of this goal.
    pub aliases: Vec<GoalId>,
    /// Map-frame position (of the canonical goal).
    pub position: Point2,
    /// Where the canonical goal came from.
    pub origin: GoalOrigin,
    /// When it was first identified.
    pub identified_at: Time,
    /// Who identified it first.
    pub identified_by: RobotId,
    /// Identified, claimed or visited.
    pub status: GoalStatus,
    /// The claim that wins: highest priority (lowest number), ties by robot id.
    pub claimant: Option<ClaimInfo>,
    /// Every active claim, winner first.
    pub claims: Vec<ClaimInfo>,
    /// First visit: when and by whom.
    pub visited: Option<(Time, RobotId)>,
    /// Robots for which the goal is currently marked unreachable.
    pub unreachable_for: Vec<RobotId>,
    /// Its priority set by the operator (issue 37): 0 for an ordinary goal, higher is more
    /// urgent.
    // Always serialised: the view also travels in non-self-describing encodings (the lockstep
    // farm's CDR answers), where a field left out shifts every later one.
    #[serde(default)]
    pub priority: i32,
    /// The operator command that cancelled it, if it is cancelled (never claimed again).
    #[serde(default)]
    pub cancelled: Option<crate::operator::CommandId>,
    /// The name an operator gave it.
    #[serde(default)]
    pub name: Option<String>,
    /// The class an operator gave it.
    #[serde(default)]
    pub class: Option<String>,
}

impl GoalView {
    /// Whether `id` is this goal or one of its aliases.
    pub fn includes(&self, id: &GoalId) -> bool {
        &self.id == id || self.aliases.contains(id)
    }

    /// Whether the goal is marked unreachable for `robot`.
    pub fn is_unreachable_for(&self, robot: &RobotId) -> bool {
        self.unreachable_for.contains(robot)
    }

    /// Whether `robot` is the winning claimant.
    pub fn is_held_by(&self, robot: &RobotId) -> bool {
        self.claimant.as_ref().is_some_and(|c| &c.robot == robot)
    }
}

/// The goal view plus an index from every goal id (canonical or alias) to its view.
#[derive(Clone, Debug, Default)]
pub(crate) struct GoalIndex {
    pub views: Vec<GoalView>,
    pub by_id: HashMap<GoalId, usize>,
}

/// Builds the deduplicated goal view from the records.
/// Claims of robots other than `me` whose latest record is more than `lease_s` older than
/// `now` are left out of the views (expired leases).
pub(crate) struct Lease<'a> {
    pub me: &'a RobotId,
    pub now: Time,
    pub lease_s: f64,
}

impl Lease<'_> {
    fn live(&self, robot: &RobotId, stamp: Time) -> bool {
        robot == self.me || self.now.secs_since(stamp) <= self.lease_s
    }
}

pub(crate) fn build_goal_index(records: &RecordSet, radius_m: f64, lease: &Lease<'_>) -> GoalIndex {
    // Goal records, and the goals operator commands add (owned: derived from the command).
    let added = crate::operator::operator_goals(records);
    let mut goals: Vec<(&GoalId, &crate::record::GoalRecord)> = records
        .values()
        .filter_map(|r| match (&r.key, &r.body) {
            (RecordKey::Goal(id), RecordBody::Goal(g)) => Some((id, g)),
            _ => None,
        })
        .chain(added.iter().map(|(id, g)| (id, g)))
        .collect();
    goals.sort_by(|a, b| a.1.identified_at.cmp(&b.1.identified_at).then_with(|| a.0.cmp(b.0)));

    let mut index = GoalIndex::default();
    for (id, g) in goals {
        let home = index.views.iter().position(|v| v.position.distance(g.position) <= radius_m);
        match home {
            Some(i) => {
                if let Some(v) = index.views.get_mut(i) {
                    v.aliases.push(id.clone());
                }
                index.by_id.insert(id.clone(), i);
            }
            None => {
                index.by_id.insert(id.clone(), index.views.len());
                index.views.push(GoalView {
                    id: id.clone(),
                    aliases: Vec::new(),
                    position: g.position,
                    origin: g.origin,
                    identified_at: g.identified_at,
                    identified_by: id.origin.clone(),
                    status: GoalStatus::Identified,
                    claimant: None,
                    claims: Vec::new(),
                    visited: None,
                    unreachable_for: Vec::new(),
                    priority: 0,
                    cancelled: None,
                    name: None,
                    class: None,
                });
            }
        }
    }

    // Current retry epoch of every robot.
    let epochs: HashMap<&RobotId, u64> = records
        .values()
        .filter_map(|r| match (&r.key, &r.body) {
            (RecordKey::RetryEpoch(robot), RecordBody::RetryEpoch(e)) => Some((robot, *e)),
            _ => None,
        })
        .collect();

    // Per goal group and claimant, the claimant's latest claim record over all aliases.
    let mut latest_claims: HashMap<(usize, &RobotId), (u64, &crate::record::ClaimRecord)> = HashMap::new();
    for r in records.values() {
        let Some(&gi) = r.key.goal().and_then(|g| index.by_id.get(g)) else {
            continue;
        };
        let Some(view) = index.views.get_mut(gi) else {
            continue;
        };
        match (&r.key, &r.body) {
            (RecordKey::Claim { claimant, .. }, RecordBody::Claim(c)) => {
                let slot = latest_claims.entry((gi, claimant)).or_insert((r.dot, c));
                if r.dot > slot.0 {
                    *slot = (r.dot, c);
                }
            }
            (RecordKey::Visit { robot, .. }, RecordBody::Visit(v)) => {
                let candidate = (v.stamp, robot.clone());
                if view.visited.as_ref().is_none_or(|cur| candidate < *cur) {
                    view.visited = Some(candidate);
                }
            }
            (RecordKey::Unreachable { robot, .. }, RecordBody::Unreachable(u)) => {
                let current = epochs.get(robot).copied().unwrap_or(0);
                if u.epoch == current && !view.unreachable_for.contains(robot) {
                    view.unreachable_for.push(robot.clone());
                }
            }
            _ => {}
        }
    }
    for ((gi, robot), (_, c)) in latest_claims {
        if let (true, true, Some(view)) = (c.active, lease.live(robot, c.stamp), index.views.get_mut(gi)) {
            view.claims.push(ClaimInfo { robot: robot.clone(), priority: c.priority, stamp: c.stamp });
        }
    }
    crate::operator::apply_goal_commands(records, &mut index);
    for v in &mut index.views {
        v.claims.sort_by(|a, b| a.priority.cmp(&b.priority).then_with(|| a.robot.cmp(&b.robot)));
        v.unreachable_for.sort();
        v.claimant = v.claims.first().cloned();
        v.status = if v.visited.is_some() {
            GoalStatus::Visited
        } else if v.claimant.is_some() {
            GoalStatus::Claimed
        } else {
            GoalStatus::Identified
        };
    }
    index
}
