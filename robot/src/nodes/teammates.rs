//! Nodes that wait on what a robot knows of its teammates through the replicated team state:
//! a team-wide trigger such as "set off once the first UGV is at the goal" (the paper's
//! experience-sharing trial sends the second UGV when the first arrives).

use serde_json::json;
use spomp_core::{Point2, RobotId, RobotKind, Time};

use spomp_behaviors::Status;
use spomp_behaviors::blackboard::{BbValue, Binding, PortType};
use spomp_behaviors::node::Behavior;
use spomp_behaviors::registry::{Category, NodeRegistry, NodeTypeSpec, PortBindings, PortSpec};

use super::Ctx;
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

fn build_wait_at(p: &PortBindings) -> Result<Box<dyn Behavior<RobotRuntime>>, String> {
    for port in ["within_m", "timeout_s"] {
        if let Some(v) = literal_f64(p, port)
            && !(v.is_finite() && v > 0.0)
        {
            return Err(format!("`{port}` must be a positive number, got {v}"));
        }
    }
    Ok(Box::new(WaitForRobotAt {
        robot: p.get("robot"),
        target: p.get("target"),
        within: p.get("within_m"),
        timeout: p.get("timeout_s"),
        started: Time::ZERO,
    }))
}

fn literal_f64(p: &PortBindings, port: &str) -> Option<f64> {
    match p.literal(port) {
        Some(BbValue::Float(f)) => Some(*f),
        Some(BbValue::Int(i)) => Some(*i as f64),
        _ => None,
    }
}

/// An optional positive-number port: `Ok(default)` when unset, `Ok(Some(v))` for a positive
/// finite value; anything else is reported on the blackboard and is `Err`.
fn optional_positive(
    binding: &Binding,
    ctx: &mut Ctx<'_>,
    port: &str,
    default: Option<f64>,
) -> Result<Option<f64>, ()> {
    if matches!(binding, Binding::Unset) {
        return Ok(default);
    }
    match binding.get::<f64>(ctx.blackboard) {
        Some(v) if v.is_finite() && v > 0.0 => Ok(Some(v)),
        Some(v) => {
            ctx.blackboard.report(format!("{WAIT_AT}: `{port}` must be a positive number, got {v}"));
            Err(())
        }
        None => {
            ctx.blackboard.report(format!("{WAIT_AT}: `{port}` is not set"));
            Err(())
        }
    }
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
        let Ok(Some(within_m)) = optional_positive(&self.within, ctx, "within_m", Some(3.0)) else {
            return Status::Failure;
        };
        let Ok(timeout_s) = optional_positive(&self.timeout, ctx, "timeout_s", None) else { return Status::Failure };
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
