//! The engine's own node types: the structural ones (control nodes, decorators, the state
//! machine, subtree references) and generic leaves (waits, flags, events, the mission clock)
//! that work on any robot. Domain nodes (navigation, UAV time-sharing, goal coordination) live
//! in `spomp-robot`, which adds them to a registry built here.

mod generic;
mod structural;

pub use generic::register_generic;
pub use structural::register_structural;

use crate::registry::NodeRegistry;

/// A registry with the engine's node types (structural and generic leaves), for trees acting
/// on any environment `E`.
pub fn engine_registry<E>() -> NodeRegistry<E> {
    let mut r = NodeRegistry::empty();
    register_structural(&mut r);
    register_generic(&mut r);
    r
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_node_is_documented_with_its_ports() {
        let r = engine_registry::<()>();
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
