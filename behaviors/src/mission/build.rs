//! Turns a compiled tree into live nodes bound to a robot's blackboard.

use std::path::PathBuf;
use std::sync::Arc;

use crate::blackboard::{BbValue, Binding, Blackboard};
use crate::control::ControlType;
use crate::control::{IfThenElse, Ordered, Parallel, Reactive, WhileDoElse};
use crate::decorators::DecoratorType;
use crate::decorators::{
    Delay, KeepRunningUntilFailure, MapResult, RateLimit, Repeat, ResultMap, Retry, RunOnce, Timeout,
};
use crate::executor::TreeExecutor;
use crate::node::{Behavior, NodeInfo, Slot};
use crate::registry::{NodeError, NodeRegistry, PortBindings};
use crate::state_machine::{State, StateMachine, Transition};

use spomp_core::{Point2, Pose2, RobotId};

use super::compile::{Ir, IrBinding, IrKind};
use super::load::CompiledRole;

/// Why a tree could not be built.
#[derive(Debug, thiserror::Error)]
pub enum BuildError {
    /// A node's factory refused its parameters.
    #[error("{path}: {error}")]
    Node {
        /// Node path.
        path: String,
        /// What the factory said.
        #[source]
        error: NodeError,
    },
}

/// Options for building.
#[derive(Debug, Clone, Default)]
pub struct BuildOptions {
    /// Folder relative file paths in the mission start from (`LoadedMission::base_dir`): a
    /// literal string on a port whose name ends in `_file` (e.g. `follow_waypoints.plan_file`)
    /// is resolved against it before the node's factory sees it. `None`: the process's working
    /// directory.
    pub base_dir: Option<PathBuf>,
    /// Where the map frame's origin lies on the Earth, when the robot's operating area is
    /// georeferenced: factories that read geographic files (QGroundControl plans) place them
    /// through it ([`PortBindings::map_origin`]).
    pub map_origin: Option<spomp_core::GeoPoint>,
}

/// A literal on a `*_file` port, resolved against the mission's folder.
fn resolve_file_port(port: &str, value: &BbValue, opts: &BuildOptions) -> BbValue {
    match (value, &opts.base_dir) {
        (BbValue::Str(s), Some(base)) if port.ends_with("_file") && std::path::Path::new(&**s).is_relative() => {
            BbValue::Str(Arc::from(base.join(&**s).to_string_lossy().as_ref()))
        }
        _ => value.clone(),
    }
}

/// Builds live nodes for `ir`, declaring the blackboard entries it uses.
pub fn build_tree<E: 'static>(
    ir: &Ir,
    registry: &NodeRegistry<E>,
    bb: &mut Blackboard,
    opts: BuildOptions,
) -> Result<Slot<E>, BuildError> {
    let mut next_id = 0;
    build(ir, registry, bb, &opts, &mut next_id)
}

fn build<E: 'static>(
    ir: &Ir,
    registry: &NodeRegistry<E>,
    bb: &mut Blackboard,
    opts: &BuildOptions,
    next_id: &mut u32,
) -> Result<Slot<E>, BuildError> {
    let info = NodeInfo { id: *next_id, type_name: ir.type_name.as_str().into(), path: ir.path.as_str().into() };
    *next_id += 1;
    let behavior: Box<dyn Behavior<E>> = match &ir.kind {
        IrKind::Control { ty, children, success_threshold, failure_threshold } => {
            let kids = children.iter().map(|c| build(c, registry, bb, opts, next_id)).collect::<Result<Vec<_>, _>>()?;
            match ty {
                ControlType::Sequence => Box::new(Ordered::sequence(kids)),
                ControlType::SequenceWithMemory => Box::new(Ordered::sequence_with_memory(kids)),
                ControlType::Fallback => Box::new(Ordered::fallback(kids)),
                ControlType::ReactiveSequence => Box::new(Reactive::sequence(kids)),
                ControlType::ReactiveFallback => Box::new(Reactive::fallback(kids)),
                ControlType::Parallel => {
                    Box::new(Parallel::new(kids, *success_threshold, *failure_threshold).map_err(|e| {
                        BuildError::Node { path: ir.path.clone(), error: NodeError::Invalid(e.to_string()) }
                    })?)
                }
                ControlType::IfThenElse => Box::new(IfThenElse::new(kids)),
                ControlType::WhileDoElse => Box::new(WhileDoElse::new(kids)),
            }
        }
        IrKind::Decorator { ty, child, duration, count, hz, then_skip } => {
            let c = build(child, registry, bb, opts, next_id)?;
            match ty {
                DecoratorType::Timeout => Box::new(Timeout::new(c, *duration)),
                DecoratorType::Delay => Box::new(Delay::new(c, *duration)),
                DecoratorType::Retry => Box::new(Retry::new(c, count.unwrap_or(1))),
                DecoratorType::Repeat => Box::new(Repeat::new(c, *count)),
                DecoratorType::Inverter => Box::new(MapResult::new(c, ResultMap::Invert)),
                DecoratorType::ForceSuccess => Box::new(MapResult::new(c, ResultMap::ForceSuccess)),
                DecoratorType::ForceFailure => Box::new(MapResult::new(c, ResultMap::ForceFailure)),
                DecoratorType::RunOnce if *then_skip => Box::new(RunOnce::then_skip(c)),
                DecoratorType::RunOnce => Box::new(RunOnce::new(c)),
                DecoratorType::KeepRunningUntilFailure => Box::new(KeepRunningUntilFailure::new(c)),
                DecoratorType::RateLimit => Box::new(RateLimit::new(c, *hz)),
            }
        }
        IrKind::StateMachine { states, initial } => {
            let mut children = Vec::new();
            let mut built = Vec::new();
            for s in states {
                let run = match &s.run {
                    Some(r) => {
                        children.push(build(r, registry, bb, opts, next_id)?);
                        Some(children.len() - 1)
                    }
                    None => None,
                };
                built.push(State {
                    name: s.name.clone(),
                    run,
                    transitions: s
                        .transitions
                        .iter()
                        .map(|(t, target)| Transition { trigger: t.clone(), target: *target })
                        .collect(),
                    terminal: s.terminal,
                });
            }
            Box::new(StateMachine::new(built, children, *initial))
        }
        IrKind::Leaf { ports } => {
            let spec = registry.get(&ir.type_name).ok_or_else(|| BuildError::Node {
                path: ir.path.clone(),
                error: NodeError::Invalid(format!("unknown node type `{}`", ir.type_name)),
            })?;
            let mut bindings = PortBindings::default();
            bindings.set_map_origin(opts.map_origin);
            for p in ports {
                let b = match &p.binding {
                    IrBinding::Literal(v) => Binding::Literal(resolve_file_port(&p.spec.name, v, opts)),
                    IrBinding::Ref(name) => Binding::Entry(bb.declare(name, p.spec.ty)),
                    IrBinding::Unset => Binding::Unset,
                };
                bindings.insert(p.spec.name.clone(), b);
            }
            let factory = registry.factory(&spec.name).ok_or_else(|| BuildError::Node {
                path: ir.path.clone(),
                error: NodeError::Invalid("node type has no factory".into()),
            })?;
            factory(&bindings).map_err(|error| BuildError::Node { path: ir.path.clone(), error })?
        }
    };
    Ok(Slot::new(info, behavior))
}

/// A robot's executor for its compiled role: the tree built over a fresh blackboard, with the
/// provided entries (`robot_id`, `start_pose`, `home`) and the role's initial values set.
pub fn build_executor<E: 'static>(
    role: &CompiledRole,
    registry: &NodeRegistry<E>,
    robot: &RobotId,
    start: Pose2,
    opts: BuildOptions,
) -> Result<TreeExecutor<E>, BuildError> {
    let mut blackboard = Blackboard::new();
    let root = build_tree(&role.tree, registry, &mut blackboard, opts)?;
    blackboard.set_by_name("robot_id", BbValue::Robot(robot.clone()));
    blackboard.set_by_name("start_pose", BbValue::Pose(start));
    blackboard.set_by_name("home", BbValue::Point(Point2::new(start.x, start.y)));
    for (name, value) in &role.initial {
        blackboard.set_by_name(name, value.clone());
    }
    Ok(TreeExecutor::from_root(root, blackboard))
}
