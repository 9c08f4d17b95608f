//! A lab's own node type for spomp, registered beside the built-in ones.
//!
//! `teammates_heard` is a condition that asks the robot's team-state skill which teammates it
//! has heard from recently; it succeeds once at least `at_least` of them have been, and writes
//! how many to `count`. Its factory is a closure that captures the lab's own settings
//! ([`LabSettings`], shared by `Arc`): a lab's services are handed to its nodes the same way.

use std::sync::Arc;

use serde_json::json;
use spomp_behaviors::Status;
use spomp_behaviors::blackboard::{BbValue, Binding, PortType};
use spomp_behaviors::node::{Behavior, TickContext};
use spomp_behaviors::registry::{Category, NodeRegistry, NodeTypeSpec, PortSpec, RegistrationError};
use spomp_robot::RobotRuntime;

/// The lab's settings its node types are built with.
#[derive(Debug, Clone)]
pub struct LabSettings {
    /// A teammate counts as heard if its last pose is at most this old, seconds, unless the
    /// node's `within_s` says otherwise.
    pub freshness_s: f64,
}

impl Default for LabSettings {
    fn default() -> Self {
        LabSettings { freshness_s: 10.0 }
    }
}

/// Adds the lab's node types to `registry`; a name already taken (or a port the factory reads
/// but does not declare) is an error.
pub fn register(
    registry: &mut NodeRegistry<RobotRuntime>,
    settings: Arc<LabSettings>,
) -> Result<(), RegistrationError> {
    registry.try_register(
        NodeTypeSpec::leaf(
            "teammates_heard",
            Category::Condition,
            "Succeeds when the team state has heard at least `at_least` teammates within `within_s` (the lab's freshness setting when left out); writes how many to `count`. A lab's own node type (examples/custom-node).",
            vec![
                PortSpec::input("at_least", PortType::Int, "Teammates needed.").with_default(json!(1)),
                PortSpec::optional("within_s", PortType::Float, "Freshness of a teammate's last pose, seconds (default: the lab's setting)."),
                PortSpec::output("count", PortType::Int, "Teammates heard."),
            ],
            move |ports| {
                Ok(Box::new(TeammatesHeard {
                    at_least: ports.get("at_least")?,
                    within_s: ports.get("within_s")?,
                    count: ports.get("count")?,
                    settings: Arc::clone(&settings),
                }))
            },
        )
        .using_skills(&["teamstate"]),
    )
}

/// The registry of the lab's binary: the built-in node types and the lab's.
pub fn lab_registry(settings: LabSettings) -> Result<NodeRegistry<RobotRuntime>, RegistrationError> {
    let mut registry = spomp::registry();
    register(&mut registry, Arc::new(settings))?;
    Ok(registry)
}

struct TeammatesHeard {
    at_least: Binding,
    within_s: Binding,
    count: Binding,
    settings: Arc<LabSettings>,
}

impl Behavior<RobotRuntime> for TeammatesHeard {
    fn tick(&mut self, _prev: Status, ctx: &mut TickContext<'_, RobotRuntime>) -> Status {
        // Always bound (the declared default when the mission leaves it out); an entry never
        // written is a mistake of the mission, reported.
        let Some(at_least) = self.at_least.get::<i64>(ctx.blackboard) else {
            ctx.blackboard.report("teammates_heard: no value on its `at_least` port".to_string());
            return Status::Failure;
        };
        let within_s = self.within_s.get::<f64>(ctx.blackboard).unwrap_or(self.settings.freshness_s);
        let now = ctx.now;
        let team = ctx.env.team();
        let me = team.self_id().clone();
        let heard = team
            .robots()
            .into_iter()
            .filter(|(id, _)| **id != me)
            .filter(|(id, _)| team.robot_pose(id).is_some_and(|(_, stamp)| (now - stamp).as_secs_f64() <= within_s))
            .count();
        self.count.set(ctx.blackboard, BbValue::Int(heard as i64));
        if heard as i64 >= at_least { Status::Success } else { Status::Failure }
    }
}
