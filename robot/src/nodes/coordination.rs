//! Goal coordination among UGVs (paper §High-Level Coordination), as behaviour nodes over the
//! replicated team state: claim the nearest claimable goal, keep it while no higher-priority
//! robot claims it and nobody visits it, mark it visited, release it (marking it unreachable
//! after a failure), retry unreachable goals when nothing else is left.
//!
//! The deconfliction radius is the team state's (`goals.deconfliction_radius_m` in the mission):
//! one value for claims, preemption and detection.

use spomp_core::{GoalId, RobotKind};

use spomp_behaviors::blackboard::{BbValue, Binding, PortType};
use spomp_behaviors::node::Behavior;
use spomp_behaviors::registry::{Category, LeafType, NodeRegistry, NodeTypeSpec, PortSpec};

use super::Ctx;
use crate::runtime::RobotRuntime;
use spomp_behaviors::Status;

/// Registers the coordination nodes.
pub fn register_coordination(r: &mut NodeRegistry<RobotRuntime>) {
    use Category::{Action, Condition};
    use PortType::{Bool, Goal, Point};
    let ugv = |spec: LeafType<RobotRuntime>| spec.for_kinds(&[RobotKind::Ugv]).using_skills(&["teamstate"]);
    r.register(
        NodeTypeSpec::leaf(
            "detect_goals",
            Action,
            "Brings this robot's copy of the aerial map up to date with the map versions received in the team state, then, if it changed, detects clusters of the mission's `goals.detect.class` in it (open, then close with `merge_distance_m`, components of at least `min_size_m`), places one goal per cluster at the point farthest from obstacles within `placement_region_m`, trying easier classes first, and adds the new ones (deduplicated within the deconfliction radius) to the team state. Succeeds after one pass, also when there is no map yet; writes the number of new goals.",
            vec![PortSpec::output("new_goals", PortType::Int, "Goals added by this pass.")],
            |p| Ok(Box::new(DetectGoals { new_goals: p.get("new_goals")? })),
        )
        .for_kinds(&[RobotKind::Ugv, RobotKind::Basestation])
        .using_skills(&["mapping", "teamstate"]),
    );
    r.register(ugv(NodeTypeSpec::leaf(
        "claim_goal",
        Action,
        "Picks the nearest goal (Euclidean, from the robot's pose) that is not visited, not unreachable for this robot and not claimed by another robot, and claims it in the team state (releasing any other claim of this robot). Fails when there is none.",
        vec![
            PortSpec::output("goal", Goal, "The claimed goal."),
            PortSpec::output("goal_position", Point, "Where it is (map frame)."),
        ],
        |p| Ok(Box::new(ClaimGoal { goal: p.get("goal")?, position: p.get("goal_position")? })),
    )));
    r.register(ugv(NodeTypeSpec::leaf(
        "goal_still_mine",
        Condition,
        "Succeeds while this robot holds `goal`; fails as soon as it learns that a higher-priority robot claims it, or anyone visited it (goals within the deconfliction radius are the same goal). Guard `navigate_to` with it in a `reactive_sequence` for preemption.",
        vec![PortSpec::input("goal", Goal, "The goal held.")],
        |p| Ok(Box::new(GoalStillMine { goal: p.get("goal")? })),
    )));
    r.register(ugv(NodeTypeSpec::leaf(
        "has_claimable_goal",
        Condition,
        "Succeeds if some goal is neither visited, nor claimed by another robot, nor unreachable for this robot.",
        vec![],
        |_| Ok(Box::new(HasClaimable)),
    )));
    r.register(ugv(NodeTypeSpec::leaf(
        "mark_visited",
        Action,
        "Marks `goal` visited by this robot in the team state (visited is final) and releases the claim.",
        vec![PortSpec::input("goal", Goal, "The goal reached.")],
        |p| Ok(Box::new(MarkVisited { goal: p.get("goal")? })),
    )));
    r.register(ugv(NodeTypeSpec::leaf(
        "release_goal",
        Action,
        "Releases this robot's claim on `goal` so others may take it; with `mark_unreachable` (after a failure or time-out) it is also marked unreachable for this robot — unless the goal was taken over by a higher-priority robot or visited meanwhile, in which case it is only released.",
        vec![
            PortSpec::input("goal", Goal, "The goal to release."),
            PortSpec::input("mark_unreachable", Bool, "Also mark it unreachable for this robot.").with_default(serde_json::json!(true)),
        ],
        |p| Ok(Box::new(ReleaseGoal { goal: p.get("goal")?, unreachable: p.get("mark_unreachable")? })),
    )));
    r.register(ugv(NodeTypeSpec::leaf(
        "clear_unreachable",
        Action,
        "Clears this robot's unreachable marks so its failed goals are retried (use when nothing else is left).",
        vec![],
        |_| Ok(Box::new(ClearUnreachable)),
    )));
}

struct DetectGoals {
    new_goals: Binding,
}

impl Behavior<RobotRuntime> for DetectGoals {
    fn tick(&mut self, _prev: Status, ctx: &mut Ctx<'_>) -> Status {
        let pass = ctx.env.detect_goals(ctx.now);
        for p in pass.problems {
            ctx.blackboard.report(format!("detect_goals: {p}"));
        }
        self.new_goals.set(ctx.blackboard, BbValue::Int(pass.added as i64));
        Status::Success
    }
}

/// Reads a goal port, reporting when it is unset.
fn goal_of(binding: &Binding, ctx: &mut Ctx<'_>, node: &str) -> Option<GoalId> {
    let g = binding.get::<GoalId>(ctx.blackboard);
    if g.is_none() {
        ctx.blackboard.report(format!("{node}: no goal on its `goal` port"));
    }
    g
}

struct ClaimGoal {
    goal: Binding,
    position: Binding,
}

impl Behavior<RobotRuntime> for ClaimGoal {
    fn tick(&mut self, _prev: Status, ctx: &mut Ctx<'_>) -> Status {
        let now = ctx.now;
        let rt = &mut *ctx.env;
        let Some(pose) = rt.pose() else {
            ctx.blackboard.report("claim_goal: the robot has no pose yet");
            return Status::Failure;
        };
        let Some(best) =
            rt.team().claimable_goals_for(rt.id(), pose.pose.position()).first().map(|v| (v.id.clone(), v.position))
        else {
            return Status::Failure;
        };
        match rt.team_mut().claim(&best.0, now) {
            Ok(outcome) => {
                self.goal.set(ctx.blackboard, BbValue::Goal(outcome.goal));
                self.position.set(ctx.blackboard, BbValue::Point(best.1));
                Status::Success
            }
            Err(e) => {
                ctx.blackboard.report(format!("claim_goal: {e}"));
                Status::Failure
            }
        }
    }
}

struct GoalStillMine {
    goal: Binding,
}

impl Behavior<RobotRuntime> for GoalStillMine {
    fn tick(&mut self, _prev: Status, ctx: &mut Ctx<'_>) -> Status {
        let Some(goal) = goal_of(&self.goal, ctx, "goal_still_mine") else { return Status::Failure };
        let rt = &*ctx.env;
        match rt.team().goal(&goal) {
            Some(view) if view.visited.is_none() && view.is_held_by(rt.id()) => Status::Success,
            _ => Status::Failure,
        }
    }
}

struct HasClaimable;

impl Behavior<RobotRuntime> for HasClaimable {
    fn tick(&mut self, _prev: Status, ctx: &mut Ctx<'_>) -> Status {
        let rt = &*ctx.env;
        if rt.team().claimable_goals_for(rt.id(), rt.position_or_start()).is_empty() {
            Status::Failure
        } else {
            Status::Success
        }
    }
}

struct MarkVisited {
    goal: Binding,
}

impl Behavior<RobotRuntime> for MarkVisited {
    fn tick(&mut self, _prev: Status, ctx: &mut Ctx<'_>) -> Status {
        let now = ctx.now;
        let Some(goal) = goal_of(&self.goal, ctx, "mark_visited") else { return Status::Failure };
        let mut team = ctx.env.team_mut();
        let result = team.mark_visited(&goal, now).and_then(|()| team.release(&goal, now));
        match result {
            Ok(()) => Status::Success,
            Err(e) => {
                ctx.blackboard.report(format!("mark_visited: {e}"));
                Status::Failure
            }
        }
    }
}

struct ReleaseGoal {
    goal: Binding,
    unreachable: Binding,
}

impl Behavior<RobotRuntime> for ReleaseGoal {
    fn tick(&mut self, _prev: Status, ctx: &mut Ctx<'_>) -> Status {
        let now = ctx.now;
        // Always bound (the declared default when the mission leaves it out).
        let Some(mark) = self.unreachable.get::<bool>(ctx.blackboard) else {
            ctx.blackboard.report("release_goal: no value on its `mark_unreachable` port".to_string());
            return Status::Failure;
        };
        let Some(goal) = goal_of(&self.goal, ctx, "release_goal") else { return Status::Failure };
        let rt = &mut *ctx.env;
        // Preempted or visited meanwhile: the goal is not unreachable, someone else has it.
        let still_ours = rt.team().goal(&goal).is_some_and(|v| v.visited.is_none() && v.is_held_by(rt.id()));
        let mut result = rt.team_mut().release(&goal, now);
        if mark && still_ours && result.is_ok() {
            result = rt.team_mut().mark_unreachable(&goal, now);
        }
        match result {
            Ok(()) => Status::Success,
            Err(e) => {
                ctx.blackboard.report(format!("release_goal: {e}"));
                Status::Failure
            }
        }
    }
}

struct ClearUnreachable;

impl Behavior<RobotRuntime> for ClearUnreachable {
    fn tick(&mut self, _prev: Status, ctx: &mut Ctx<'_>) -> Status {
        ctx.env.team_mut().clear_unreachable();
        Status::Success
    }
}
