//! The node library: built-in structural nodes, generic leaves and the domain nodes of the
//! paper's missions, all registered by name with their ports.

mod coordination;
mod domain;
mod generic;
mod structural;

pub use coordination::register_coordination;
pub use domain::{DOMAIN_NODE_NAMES, register_domain_declarations};
pub use generic::register_generic;
pub use structural::{ControlType, DecoratorType, register_structural};

use crate::registry::NodeRegistry;

/// Every node type of this build: structural, generic leaves, goal coordination, and the other
/// domain nodes (declared with their ports; those whose skill is not wired yet are marked
/// unimplemented).
pub fn builtin_registry() -> NodeRegistry {
    let mut r = NodeRegistry::empty();
    register_structural(&mut r);
    register_generic(&mut r);
    register_domain_declarations(&mut r);
    register_coordination(&mut r);
    r
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::registry::Category;

    #[test]
    fn every_node_is_documented_with_its_ports() {
        let r = builtin_registry();
        let md = r.reference_markdown();
        for spec in r.iter() {
            assert!(!spec.description.is_empty(), "{} has no description", spec.name);
            assert!(md.contains(&format!("### `{}`", spec.name)));
            for p in &spec.ports {
                assert!(!p.description.is_empty(), "{}.{} has no description", spec.name, p.name);
            }
        }
        for name in DOMAIN_NODE_NAMES {
            let spec = r.get(name).expect("declared");
            assert!(matches!(spec.category, Category::Action | Category::Condition));
            assert!(!spec.implemented, "{name} has no implementation in this build yet");
        }
    }
}
