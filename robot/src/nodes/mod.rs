//! The domain nodes of the paper's missions, acting on a [`RobotRuntime`]: driving
//! (`navigate_to`, `navigate_local`, `return_home`), the UAV's time-sharing (`follow_waypoints`,
//! `seek_robot`, `wait_for_sync`), goal coordination (`detect_goals`, `claim_goal`, …), team-wide triggers
//! (`wait_for_robot_at`), the operator's orders (`operator_hold`, `operator_recall`).

mod aerial;
mod coordination;
mod navigation;
mod operator;
mod qgc_plan;
mod teammates;

use std::sync::Arc;

pub use aerial::register_aerial;
pub use coordination::register_coordination;
pub use navigation::register_navigation;
pub use operator::{OPERATOR_NODES, register_operator};
pub use qgc_plan::{PlanError, PlanProblem, plan_waypoints};
pub use teammates::register_teammates;

use spomp_behaviors::blackboard::{BbValue, Binding};
use spomp_behaviors::registry::{NodeError, PortBindings};
use spomp_behaviors::{NodeRegistry, TickContext, engine_registry};

use crate::checks::MissionRobotChecks;
use crate::runtime::RobotRuntime;

/// What a domain node sees during a tick: the robot runtime, typed, as `ctx.env`.
pub(crate) type Ctx<'a> = TickContext<'a, RobotRuntime>;

/// A literal number on a port, checked at build time (a bound entry is checked when ticked,
/// by [`number`]).
pub(crate) fn literal_number(p: &PortBindings, port: &'static str, positive: bool) -> Result<(), NodeError> {
    let v = match p.literal(port)? {
        Some(BbValue::Float(f)) => *f,
        Some(BbValue::Int(i)) => *i as f64,
        _ => return Ok(()),
    };
    if !v.is_finite() || (positive && v <= 0.0) {
        let what = if positive { "a positive number" } else { "a finite number" };
        return Err(NodeError::port(port, format!("`{port}` must be {what}, found {v}")));
    }
    Ok(())
}

/// Reads a number port at tick time; reports and returns None when it is missing or invalid.
pub(crate) fn number(b: &Binding, ctx: &mut Ctx<'_>, node: &str, port: &str, positive: bool) -> Option<f64> {
    match b.get::<f64>(ctx.blackboard) {
        Some(v) if v.is_finite() && (!positive || v > 0.0) => Some(v),
        Some(v) => {
            let what = if positive { "a positive number" } else { "a finite number" };
            ctx.blackboard.report(format!("{node}: `{port}` must be {what}, found {v}"));
            None
        }
        None => {
            ctx.blackboard.report(format!("{node}: no value on its `{port}` port"));
            None
        }
    }
}

/// Every node type of a robot: the engine's (structural, generic leaves) and the domain nodes,
/// with the robot layer's checks of robot settings. `spomp validate`, `sim`, `run`, `nodes` and
/// `schema` all use it; a lab's own binary adds its node types to it.
pub fn registry() -> NodeRegistry<RobotRuntime> {
    let mut r = engine_registry();
    register_navigation(&mut r);
    register_aerial(&mut r);
    register_coordination(&mut r);
    register_teammates(&mut r);
    register_operator(&mut r);
    r.set_robot_checks(Arc::new(MissionRobotChecks));
    r
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_node_is_documented_with_its_ports() {
        let r = registry();
        let md = r.reference_markdown();
        for spec in r.iter() {
            assert!(!spec.description.is_empty(), "{} has no description", spec.name);
            assert!(md.contains(&format!("### `{}`", spec.name)));
            for p in &spec.ports {
                assert!(!p.description.is_empty(), "{}.{} has no description", spec.name, p.name);
            }
        }
    }
}
