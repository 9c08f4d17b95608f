//! Nodes that wait on what a robot knows of its teammates through the replicated team state:
//! a team-wide trigger such as "set off once the first UGV is at the goal" (the paper's
//! experience-sharing trial sends the second UGV when the first arrives).

use serde_json::json;
use spomp_core::{Point2, RobotId, RobotKind, Time};

use spomp_behaviors::Status;
use spomp_behaviors::blackboard::{Binding, PortType};
use spomp_behaviors::node::Behavior;
use spomp_behaviors::registry::{Category, NodeError, NodeRegistry, NodeTypeSpec, PortBindings, PortSpec};

use super::{Ctx, literal_number, number};
use crate::runtime::RobotRuntime;

const WAIT_AT: &str = "wait_for_robot_at";

/// Registers the teammate nodes.
pub fn register_teammates(r: &mut NodeRegistry<RobotRuntime>) {
    use PortType::{Float, Point, Robot};
    r.register(
        NodeTypeSpec::leaf(
            WAIT_AT,
            Category::Action,
            "Runs until this robot's team state places `robot` within `within_m` of `target` (its latest pose record, as far as the radio carried it), then succeeds; with `timeout_s`, fails after that long. A team-wide trigger: e.g. a second UGV sets off once the first is at the goal.",
            vec![
                PortSpec::input("robot", Robot, "The teammate to wait for (not this robot)."),
                PortSpec::input("target", Point, "Where it should be (map frame)."),
                PortSpec::input("within_m", Float, "How close counts as there, metres.").with_default(json!(3.0)),
                PortSpec::optional("timeout_s", Float, "Give up after this long, seconds; waits for ever if absent."),
            ],
            build_wait_at,
        )
        .for_kinds(&[RobotKind::Ugv, RobotKind::Uav, RobotKind::Basestation])
        .using_skills(&["teamstate"]),
    );
}

struct WaitForRobotAt {
    robot: Binding,
    target: Binding,
    within: Binding,
    timeout: Binding,
    started: Time,
}

fn build_wait_at(p: &PortBindings) -> Result<Box<dyn Behavior<RobotRuntime>>, NodeError> {
    literal_number(p, "within_m", true)?;
    literal_number(p, "timeout_s", true)?;
    Ok(Box::new(WaitForRobotAt {
        robot: p.get("robot")?,
        target: p.get("target")?,
        within: p.get("within_m")?,
        timeout: p.get("timeout_s")?,
        started: Time::ZERO,
    }))
}

impl Behavior<RobotRuntime> for WaitForRobotAt {
    fn tick(&mut self, prev: Status, ctx: &mut Ctx<'_>) -> Status {
        let now = ctx.now;
        if prev != Status::Running {
            self.started = now;
        }
        let Some(robot) = self.robot.get::<RobotId>(ctx.blackboard) else {
            ctx.blackboard.report(format!("{WAIT_AT}: no robot on its `robot` port"));
            return Status::Failure;
        };
        let target = match self.target.get::<Point2>(ctx.blackboard) {
            Some(p) if p.x.is_finite() && p.y.is_finite() => p,
            _ => {
                ctx.blackboard.report(format!("{WAIT_AT}: no finite point on its `target` port"));
                return Status::Failure;
            }
        };
        let Some(within_m) = number(&self.within, ctx, WAIT_AT, "within_m", true) else { return Status::Failure };
        let timeout_s = match self.timeout {
            Binding::Unset => None,
            _ => match number(&self.timeout, ctx, WAIT_AT, "timeout_s", true) {
                Some(t) => Some(t),
                None => return Status::Failure,
            },
        };
        let rt = &*ctx.env;
        if &robot == rt.id() {
            ctx.blackboard.report(format!("{WAIT_AT}: `{robot}` is this robot"));
            return Status::Failure;
        }
        let there = rt.team().robot_pose(&robot).is_some_and(|(pose, _)| pose.position().distance(target) <= within_m);
        if there {
            Status::Success
        } else if timeout_s.is_some_and(|t| now.secs_since(self.started) >= t) {
            Status::Failure
        } else {
            Status::Running
        }
    }
}
