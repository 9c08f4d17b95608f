//! The node library: built-in structural nodes, generic leaves and the domain nodes of the
//! paper's missions, all registered by name with their ports.

mod aerial;
mod coordination;
mod generic;
mod navigation;
mod qgc_plan;
mod structural;

pub use aerial::register_aerial;
pub use coordination::register_coordination;
pub use generic::register_generic;
pub use navigation::register_navigation;
pub use structural::{ControlType, DecoratorType, register_structural};

use crate::registry::NodeRegistry;

/// Every node type of this build: structural, generic leaves, and the domain nodes of the
/// paper's missions (navigation, UAV time-sharing, goal coordination).
pub fn builtin_registry() -> NodeRegistry {
    let mut r = NodeRegistry::empty();
    register_structural(&mut r);
    register_generic(&mut r);
    register_navigation(&mut r);
    register_aerial(&mut r);
    register_coordination(&mut r);
    r
}

#[cfg(test)]
mod tests {
    use super::*;

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
    }
}
