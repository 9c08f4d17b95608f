//! The behaviour engine of spomp, its node library, and the mission language.
//!
//! - [`node`], [`control`], [`decorators`], [`state_machine`]: the engine. Nodes report
//!   [`Status`]; control nodes own their children's [`Slot`]s; halting is explicit and recursive.
//! - [`blackboard`]: the typed per-robot blackboard, keys interned at build time.
//! - [`registry`] and [`library`]: node types registered by name with their ports declared once;
//!   the manifest feeds `spomp nodes`, the docs and the JSON schema.
//! - [`mission`]: YAML missions, staged validation, compilation into trees.
//! - [`executor`]: one robot's tree, ticked against a clock.
//! - [`job`]: long work started by a node and polled on later ticks.
//! - [`trace`]: observers that print or record transitions.

pub mod blackboard;
pub mod control;
pub mod decorators;
pub mod executor;
pub mod job;
pub mod library;
pub mod mission;
pub mod node;
pub mod registry;
pub mod runtime;
pub mod state_machine;
pub mod status;
pub mod trace;

pub use blackboard::{BbValue, Binding, Blackboard, PortType};
pub use executor::RobotExecutor;
pub use library::builtin_registry;
pub use node::{Behavior, NodeInfo, Slot, TickContext, TreeObserver};
pub use registry::{Category, NodeRegistry, NodeTypeSpec, PortSpec};
pub use runtime::RobotRuntime;
pub use status::Status;
