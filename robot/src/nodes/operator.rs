//! How a mission reacts to the operator (issue 37): conditions on the operator's orders for this
//! robot, which the team state derives from the operator commands it holds (see
//! `spomp_teamstate`'s operator module). The shipped roles put them first in a
//! `reactive_fallback` above the mission (`missions/subtrees/operator.yaml`), so a hold or a
//! recall halts the mission's nodes and a resume starts them again.

use serde_json::json;
use spomp_behaviors::Status;
use spomp_behaviors::blackboard::{Binding, PortType};
use spomp_behaviors::node::Behavior;
use spomp_behaviors::registry::{Category, NodeRegistry, NodeTypeSpec, PortSpec};
use spomp_core::{FlightCommand, RobotKind};
use spomp_teamstate::OperatorMode;

use super::{Ctx, literal_number, number};
use crate::runtime::RobotRuntime;

/// Node types a role of a moving robot uses to obey holds and recalls (`spomp validate` warns
/// about a UGV's or UAV's role without either of them).
pub const OPERATOR_NODES: [&str; 2] = ["operator_hold", "operator_recall"];

/// Registers the operator nodes.
pub fn register_operator(r: &mut NodeRegistry<RobotRuntime>) {
    let moving = [RobotKind::Ugv, RobotKind::Uav];
    r.register(
        NodeTypeSpec::leaf(
            "operator_hold",
            Category::Condition,
            "Succeeds while the operator holds this robot (`hold ROBOT|all`, until a later `resume`). Put it first in a `reactive_fallback` above the mission, with a branch that keeps running while it holds: the mission's nodes are halted, and start again after the resume. Whatever the tree does, a held robot's command output is zero (a UAV hovers) from the tick that sees the hold.",
            vec![],
            |_| Ok(Box::new(ModeIs(OperatorMode::Hold))),
        )
        .for_kinds(&moving)
        .using_skills(&["teamstate"]),
    );
    r.register(
        NodeTypeSpec::leaf(
            "operator_recall",
            Category::Condition,
            "Succeeds while the operator recalls this robot (`recall ROBOT|all`, until a later `resume`); the robot has released its claims when the recall arrived. Guard a branch that returns home (`return_home`) and stays, first in a `reactive_fallback` above the mission.",
            vec![],
            |_| Ok(Box::new(ModeIs(OperatorMode::Recall))),
        )
        .for_kinds(&moving)
        .using_skills(&["teamstate"]),
    );
    r.register(
        NodeTypeSpec::leaf(
            "fly_home",
            Category::Action,
            "Flies the UAV back over its start position at `altitude_m` and `speed_mps`; succeeds once it is within `tolerance_m` of it (horizontally), hovering there. A recalled UAV's branch: `operator_recall`, then `fly_home`.",
            vec![
                PortSpec::input("altitude_m", PortType::Float, "Altitude above the take-off point, metres.").with_default(json!(60.0)),
                PortSpec::input("speed_mps", PortType::Float, "Cruise speed cap, m/s.").with_default(json!(10.0)),
                PortSpec::input("tolerance_m", PortType::Float, "Arrival radius, metres.").with_default(json!(3.0)),
            ],
            |p| {
                for port in ["altitude_m", "speed_mps", "tolerance_m"] {
                    literal_number(p, port, true)?;
                }
                Ok(Box::new(FlyHome {
                    altitude_m: p.get("altitude_m")?,
                    speed_mps: p.get("speed_mps")?,
                    tolerance_m: p.get("tolerance_m")?,
                }))
            },
        )
        .for_kinds(&[RobotKind::Uav]),
    );
}

struct FlyHome {
    altitude_m: Binding,
    speed_mps: Binding,
    tolerance_m: Binding,
}

impl Behavior<RobotRuntime> for FlyHome {
    fn tick(&mut self, _prev: Status, ctx: &mut Ctx<'_>) -> Status {
        const NODE: &str = "fly_home";
        let (Some(altitude_m), Some(speed_mps), Some(tolerance_m)) = (
            number(&self.altitude_m, ctx, NODE, "altitude_m", true),
            number(&self.speed_mps, ctx, NODE, "speed_mps", true),
            number(&self.tolerance_m, ctx, NODE, "tolerance_m", true),
        ) else {
            return Status::Failure;
        };
        let rt = &mut *ctx.env;
        let home = rt.start().position();
        if rt.position_or_start().distance(home) <= tolerance_m {
            rt.hover();
            return Status::Success;
        }
        rt.command_flight(FlightCommand { target: home, altitude_m, speed_mps });
        Status::Running
    }
}

/// Succeeds while the operator's orders for this robot are the given mode.
struct ModeIs(OperatorMode);

impl Behavior<RobotRuntime> for ModeIs {
    fn tick(&mut self, _prev: Status, ctx: &mut Ctx<'_>) -> Status {
        match ctx.env.operator_orders().mode == self.0 {
            true => Status::Success,
            false => Status::Failure,
        }
    }
}
