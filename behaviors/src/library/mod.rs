//! The node library: built-in structural nodes, generic leaves and the domain nodes of the
//! paper's missions, all registered by name with their ports.

mod domain;
mod generic;
mod structural;

pub use domain::{DOMAIN_NODE_NAMES, register_domain_declarations};
pub use generic::register_generic;
pub use structural::{ControlType, DecoratorType, register_structural};

use crate::registry::NodeRegistry;

/// Every node type of this build: structural, generic leaves, and the domain nodes (declared
/// with their ports; those whose skill is not in this build are marked unimplemented).
pub fn builtin_registry() -> NodeRegistry {
    let mut r = NodeRegistry::empty();
    register_structural(&mut r);
    register_generic(&mut r);
    register_domain_declarations(&mut r);
    r
}
