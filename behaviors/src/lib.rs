//! The behaviour engine of spomp and the mission language. Robots, and the domain nodes that
//! act on them, are one layer up (`spomp-robot`).
//!
//! - [`node`], [`control`], [`decorators`], [`state_machine`]: the engine. Nodes report
//!   [`Status`]; control nodes own their children's [`Slot`]s; halting is explicit and recursive.
//!   Trees are generic over the environment `E` their leaves act on (a robot runtime), so a
//!   leaf gets it typed in its [`TickContext`].
//! - [`blackboard`]: the typed per-robot blackboard, keys interned at build time.
//! - [`registry`] and [`library`]: node types registered by name with their ports declared once;
//!   the manifest feeds `spomp nodes`, the docs and the JSON schema. [`library`] holds the
//!   engine's own types (structural and generic leaves).
//! - [`mission`]: YAML missions, staged validation, compilation into trees; it builds engine
//!   trees, the engine knows nothing of YAML.
//! - [`executor`]: a tree and its blackboard, ticked against a clock.
//! - [`job`]: long work started by a node and polled on later ticks.
//! - [`trace`]: observers that print or record transitions.

pub mod blackboard;
pub mod control;
pub mod decorators;
pub mod duration;
pub mod executor;
pub mod job;
pub mod library;
pub mod mission;
pub mod node;
pub mod registry;
pub mod state_machine;
pub mod status;
pub mod trace;

pub use blackboard::{BbValue, Binding, Blackboard, PortType};
pub use executor::TreeExecutor;
pub use library::engine_registry;
pub use node::{Behavior, NodeInfo, Slot, TickContext, TreeObserver};
pub use registry::{
    Category, LeafType, NodeCatalog, NodeError, NodeRegistry, NodeTypeSpec, PortSpec, RegistrationError,
};
pub use status::Status;
