//! Trees from code: a tree written in the mission language loaded from a string
//! ([`load_tree_str`]), and a small builder whose names are the mission language's
//! ([`TreeNode`]). Both go through the mission compiler, so a tree built from code gets the
//! same checks (node types, ports, literal ranges, children, blackboard wiring) and the same
//! node ids, type names and paths as one loaded from a mission.

use std::collections::BTreeMap;
use std::path::PathBuf;

use serde_json::{Map, Value, json};

use crate::blackboard::{BbValue, Blackboard};
use crate::executor::TreeExecutor;
use crate::registry::{Category, NodeRegistry};

use super::build::{BuildError, BuildOptions, build_tree};
use super::compile::{Compiler, check_wiring};
use super::diagnostic::{Diagnostic, Stage};
use super::yaml::{Loc, parse};

/// The file name diagnostics of a tree loaded from a string carry.
pub const STRING_SOURCE: &str = "<tree>";

/// Loads one behaviour tree written in the mission language (a node: `sequence: [...]`,
/// `parallel: {...}`, …) from `text`, checks it as the mission loader checks a role's tree and
/// builds its executor. `blackboard` gives the entries the tree may read before any node writes
/// them (a role's `blackboard:`), typed by their values; they are set before the first tick.
///
/// Every problem comes back as a located [`Diagnostic`] (file [`STRING_SOURCE`]).
pub fn load_tree_str<E: 'static>(
    text: &str,
    registry: &NodeRegistry<E>,
    blackboard: &[(&str, BbValue)],
) -> Result<TreeExecutor<E>, Vec<Diagnostic>> {
    let file = PathBuf::from(STRING_SOURCE);
    let files = [file.clone()];
    let root = parse(text).map_err(|e| vec![Diagnostic::new(&file, e.loc, "", Stage::Parse, e.message)])?;
    let subtrees = BTreeMap::new();
    let mut compiler = Compiler::new(registry.catalog(), &subtrees, &files);
    let ir = compiler.compile(&root, 0, "");
    let mut diags = compiler.into_diagnostics();
    let Some(ir) = ir else { return Err(diags) };
    let initial =
        blackboard.iter().map(|(name, v)| ((*name).to_string(), (Some(v.port_type()), Loc::default(), 0))).collect();
    check_wiring(&ir, &initial, &files, &mut diags);
    if !diags.is_empty() {
        return Err(diags);
    }
    let mut bb = Blackboard::new();
    let tree = build_tree(&ir, registry, &mut bb, BuildOptions::default()).map_err(|e| match e {
        BuildError::Node { path, error } => {
            vec![Diagnostic::new(&file, ir.loc, path, Stage::Wiring, error.to_string())]
        }
    })?;
    for (name, value) in blackboard {
        bb.set_by_name(name, value.clone());
    }
    Ok(TreeExecutor::from_root(tree, bb))
}

/// A node of a tree being built from code, named as in the mission language:
///
/// ```
/// use spomp_behaviors::engine_registry;
/// use spomp_behaviors::mission::tree::TreeNode;
///
/// let tree = TreeNode::new("reactive_sequence")
///     .child(TreeNode::new("check_flag").port("flag", "{armed}"))
///     .child(TreeNode::new("retry").port("max_attempts", 3).child(TreeNode::new("wait").port("duration_s", 2.0)));
/// let mut executor = tree.build(&engine_registry::<()>(), &[("armed", true.into())]).expect("valid tree");
/// # let _ = executor.tick(spomp_core::Time::ZERO, &mut (), None);
/// ```
///
/// `child` adds a child: the one `child:` of a decorator or the next of a control node's
/// `children:`. Ports take literals or `"{entry}"` references, as in a mission.
#[derive(Debug, Clone, PartialEq)]
pub struct TreeNode {
    type_name: String,
    ports: Map<String, Value>,
    children: Vec<TreeNode>,
}

impl TreeNode {
    /// A node of the named type (`sequence`, `retry`, `wait`, a lab's own type, …).
    pub fn new(type_name: impl Into<String>) -> Self {
        TreeNode { type_name: type_name.into(), ports: Map::new(), children: Vec::new() }
    }

    /// Sets a port (or a structural key such as `name`, or a state machine's `states`).
    #[must_use]
    pub fn port(mut self, name: impl Into<String>, value: impl Into<Value>) -> Self {
        self.ports.insert(name.into(), value.into());
        self
    }

    /// Adds a child.
    #[must_use]
    pub fn child(mut self, node: TreeNode) -> Self {
        self.children.push(node);
        self
    }

    /// Adds children in order.
    #[must_use]
    pub fn children(mut self, nodes: impl IntoIterator<Item = TreeNode>) -> Self {
        self.children.extend(nodes);
        self
    }

    /// The tree in the mission language, as JSON (a YAML document too): the text a mission
    /// would hold. A decorator's single child goes under `child:`, anything else's under
    /// `children:`, as the registry's category of the type says.
    pub fn to_json<E>(&self, registry: &NodeRegistry<E>) -> Value {
        let mut body = self.ports.clone();
        let decorator = registry.get(&self.type_name).is_some_and(|s| s.category == Category::Decorator);
        match (decorator, self.children.as_slice()) {
            (_, []) => {}
            (true, [one]) => {
                body.insert("child".into(), one.to_json(registry));
            }
            (_, many) => {
                body.insert("children".into(), Value::Array(many.iter().map(|c| c.to_json(registry)).collect()));
            }
        }
        let body = if body.is_empty() { Value::Null } else { Value::Object(body) };
        json!({ self.type_name.clone(): body })
    }

    /// Checks and builds the tree over `registry` (see [`load_tree_str`] for `blackboard`).
    pub fn build<E: 'static>(
        &self,
        registry: &NodeRegistry<E>,
        blackboard: &[(&str, BbValue)],
    ) -> Result<TreeExecutor<E>, Vec<Diagnostic>> {
        let text = serde_json::to_string_pretty(&self.to_json(registry)).unwrap_or_default();
        load_tree_str(&text, registry, blackboard)
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::expect_used)]

    use std::path::Path;
    use std::sync::Arc;
    use std::sync::atomic::{AtomicU32, Ordering};

    use spomp_core::Time;

    use super::*;
    use crate::blackboard::PortType;
    use crate::library::engine_registry;
    use crate::mission::{LoadOptions, load_mission_str};
    use crate::node::{Behavior, TickContext};
    use crate::registry::{NodeError, NodeTypeSpec, PortSpec, RegistrationError};
    use crate::status::Status;

    /// A node type whose factory captures a counter shared with the test (a lab's service
    /// handle, in miniature): each tick adds `step` to it.
    fn counting_registry(counter: &Arc<AtomicU32>) -> NodeRegistry<()> {
        struct Count(Arc<AtomicU32>, u32);
        impl Behavior for Count {
            fn tick(&mut self, _prev: Status, _ctx: &mut TickContext<'_>) -> Status {
                self.0.fetch_add(self.1, Ordering::Relaxed);
                Status::Success
            }
        }
        let mut r = engine_registry::<()>();
        let counter = Arc::clone(counter);
        r.try_register(NodeTypeSpec::leaf(
            "count",
            Category::Action,
            "Adds `step` to the shared counter.",
            vec![PortSpec::input("step", PortType::Int, "How much.")],
            move |p| match p.literal("step")? {
                Some(BbValue::Int(n)) if *n >= 0 => Ok(Box::new(Count(Arc::clone(&counter), *n as u32))),
                _ => Err(NodeError::port("step", "step must be a literal count")),
            },
        ))
        .unwrap();
        r
    }

    #[test]
    fn a_tree_loads_from_a_string_with_closure_nodes() {
        let counter = Arc::new(AtomicU32::new(0));
        let r = counting_registry(&counter);
        let mut ex = load_tree_str("sequence: [{count: {step: 2}}, {count: {step: 5}}]", &r, &[]).unwrap();
        assert_eq!(ex.tick(Time::ZERO, &mut (), None), Status::Success);
        assert_eq!(counter.load(Ordering::Relaxed), 7);
        // Node ids and paths as a mission's.
        let mut seen = Vec::new();
        ex.root().visit(0, &mut |s, _| seen.push((s.info().id, s.info().path.to_string())));
        assert_eq!(seen, [(0, "sequence".into()), (1, "sequence[0]/count".into()), (2, "sequence[1]/count".into())]);
    }

    #[test]
    fn a_string_tree_is_checked_like_a_mission() {
        let r = counting_registry(&Arc::new(AtomicU32::new(0)));
        let d = load_tree_str("sequence: [{count: {step: 2}}, {cuont: {step: 1}}]", &r, &[]).err().unwrap();
        assert_eq!(d.len(), 1);
        assert_eq!((d[0].line, d[0].column, d[0].node_path.as_str()), (1, 33, "sequence[1]"));
        assert!(d[0].message.contains("did you mean `count`"), "{}", d[0].message);
        // A reference read before anything writes it, unless the caller provides it.
        let d = load_tree_str("check_flag: { flag: \"{ok}\" }", &r, &[]).err().unwrap();
        assert!(d[0].message.contains("before any node writes it"), "{}", d[0].message);
        let mut ex = load_tree_str("check_flag: { flag: \"{ok}\" }", &r, &[("ok", true.into())]).unwrap();
        assert_eq!(ex.tick(Time::ZERO, &mut (), None), Status::Success);
        // A factory's refusal is located at its node.
        let d = load_tree_str("sequence: [{count: {step: -1}}]", &r, &[]).err().unwrap();
        assert_eq!(d[0].node_path, "sequence[0]/count");
    }

    #[test]
    fn the_builder_uses_the_mission_language_names() {
        let counter = Arc::new(AtomicU32::new(0));
        let r = counting_registry(&counter);
        let tree = TreeNode::new("sequence")
            .child(TreeNode::new("run_once").port("then_skip", true).child(TreeNode::new("count").port("step", 1)))
            .child(TreeNode::new("repeat").port("times", 2).child(TreeNode::new("count").port("step", 10)));
        assert_eq!(
            tree.to_json(&r),
            json!({"sequence": {"children": [
                {"run_once": {"then_skip": true, "child": {"count": {"step": 1}}}},
                {"repeat": {"times": 2, "child": {"count": {"step": 10}}}}
            ]}})
        );
        let mut ex = tree.build(&r, &[]).unwrap();
        let statuses: Vec<Status> = (0..4).map(|i| ex.tick(Time::from_millis(i * 100), &mut (), None)).collect();
        // run_once then repeat ×2 (one cycle per tick); the second run skips run_once.
        assert_eq!(statuses, [Status::Running, Status::Success, Status::Running, Status::Success]);
        assert_eq!(counter.load(Ordering::Relaxed), 1 + 10 + 10 + 10 + 10);
        assert_eq!(ex.root().info().type_name.as_ref(), "sequence");
        // Out-of-range thresholds are errors, not clamped.
        let bad = TreeNode::new("parallel").port("success_threshold", 3).child(TreeNode::new("succeed"));
        let d = bad.build(&r, &[]).err().unwrap();
        assert!(d[0].message.contains("success_threshold must be between 1 and the number of children (1)"));
    }

    #[test]
    fn a_mission_loads_from_a_string() {
        let r = engine_registry::<()>();
        let text = "mission: from_text\nteam:\n  - { id: base, kind: basestation, role: base, start: { x_m: 0, y_m: 0 } }\nroles:\n  base:\n    tree: { wait: { duration_s: 1 } }\ncomplete_when: all_trees_done\ntime_limit_s: 60\n";
        let loaded = load_mission_str(text, Path::new("virtual/m.yaml"), &r, &LoadOptions::default());
        assert!(loaded.is_valid(), "{:#?}", loaded.diagnostics);
        assert!(loaded.roles.contains_key("base"));
        let broken = text.replace("duration_s: 1", "duration_s: -1");
        let loaded = load_mission_str(&broken, Path::new("virtual/m.yaml"), &r, &LoadOptions::default());
        assert_eq!(loaded.diagnostics.len(), 1, "{:#?}", loaded.diagnostics);
        assert_eq!(
            (loaded.diagnostics[0].file.as_path(), loaded.diagnostics[0].line),
            (Path::new("virtual/m.yaml"), 6)
        );
    }

    #[test]
    fn registering_a_taken_name_is_an_error() {
        let mut r = engine_registry::<()>();
        let again = NodeTypeSpec::leaf("wait", Category::Action, "Another wait.", vec![], |_| {
            Err(NodeError::Invalid("unused".into()))
        });
        assert_eq!(r.try_register(again).err(), Some(RegistrationError::Duplicate("wait".into())));
        assert!(r.get("wait").is_some_and(|s| s.description.starts_with("Runs for")));
    }

    /// A node type whose code reads a port it did not declare (a misspelling): the registry
    /// refuses it when it is built, naming the type and the port, instead of the node reading
    /// an unset port for ever.
    #[test]
    fn a_factory_reading_an_undeclared_port_fails_at_registry_build() {
        struct Idle;
        impl Behavior for Idle {
            fn tick(&mut self, _prev: Status, _ctx: &mut TickContext<'_>) -> Status {
                Status::Success
            }
        }
        let mut r = engine_registry::<()>();
        let misspelled = NodeTypeSpec::leaf(
            "hover",
            Category::Action,
            "Hovers.",
            vec![PortSpec::input("altitude_m", PortType::Float, "Height.").with_default(serde_json::json!(10.0))],
            |p| {
                let _height = p.get("altitude")?; // the declared port is `altitude_m`
                Ok(Box::new(Idle))
            },
        );
        let e = r.try_register(misspelled).unwrap_err();
        assert_eq!(e, RegistrationError::UndeclaredPort { node: "hover".into(), port: "altitude".into() });
        assert_eq!(e.to_string(), "node type `hover`: its factory reads port `altitude`, which it does not declare");
        assert!(r.get("hover").is_none(), "a refused type is not registered");
        // Literals are checked the same way.
        let by_literal = NodeTypeSpec::leaf("hover2", Category::Action, "Hovers.", vec![], |p| {
            p.literal("speed")?;
            Ok(Box::new(Idle))
        });
        assert!(matches!(r.try_register(by_literal), Err(RegistrationError::UndeclaredPort { .. })));
        // The correct spelling registers.
        let right = NodeTypeSpec::leaf(
            "hover",
            Category::Action,
            "Hovers.",
            vec![PortSpec::input("altitude_m", PortType::Float, "Height.").with_default(serde_json::json!(10.0))],
            |p| {
                let _height = p.get("altitude_m")?;
                Ok(Box::new(Idle))
            },
        );
        assert_eq!(r.try_register(right), Ok(()));
    }

    #[test]
    fn a_default_that_is_no_value_of_its_port_type_is_refused() {
        let mut r = engine_registry::<()>();
        let bad = NodeTypeSpec::leaf(
            "bad_default",
            Category::Action,
            "A default of the wrong type.",
            vec![PortSpec::input("tolerance_m", PortType::Float, "Radius.").with_default(serde_json::json!("two"))],
            |_| Err(NodeError::Invalid("unused".into())),
        );
        assert!(matches!(r.try_register(bad), Err(RegistrationError::BadDefault { .. })));
    }

    /// A lab that reads its node types from configuration: names, descriptions and ports are
    /// strings built at run time, each factory captures its own entry.
    #[test]
    fn node_types_register_from_configuration() {
        struct Constant(Status);
        impl Behavior for Constant {
            fn tick(&mut self, _prev: Status, _ctx: &mut TickContext<'_>) -> Status {
                self.0
            }
        }
        let config = "lab_ok: success\nlab_broken: failure\nwait: success\n";
        let mut r = engine_registry::<()>();
        let mut refused = Vec::new();
        for line in config.lines() {
            let Some((name, outcome)) = line.split_once(": ") else { continue };
            let status = if outcome == "success" { Status::Success } else { Status::Failure };
            let port = format!("{name}_note");
            let spec = NodeTypeSpec::leaf(
                name.to_string(),
                Category::Condition,
                format!("Reports {outcome} (from the lab's configuration)."),
                vec![PortSpec::optional(port, PortType::String, format!("A note for {name}."))],
                move |_| Ok(Box::new(Constant(status))),
            );
            if let Err(e) = r.try_register(spec) {
                refused.push(e.to_string());
            }
        }
        // A configured name that a built-in type holds is refused, the built-in kept.
        assert_eq!(refused, ["node type `wait` is registered twice"]);
        assert!(r.get("wait").is_some_and(|s| s.category == Category::Action));
        let spec = r.get("lab_broken").unwrap();
        assert_eq!(
            (spec.description.as_ref(), spec.ports[0].name.as_ref()),
            ("Reports failure (from the lab's configuration).", "lab_broken_note")
        );
        let mut ex = load_tree_str("fallback: [{lab_broken: {lab_broken_note: x}}, {lab_ok: {}}]", &r, &[]).unwrap();
        assert_eq!(ex.tick(Time::ZERO, &mut (), None), Status::Success);
        // Ports declared at run time are checked like the built-in ones.
        let d = load_tree_str("lab_ok: {lab_broken_note: x}", &r, &[]).err().unwrap();
        assert!(d[0].message.contains("expected one of: lab_ok_note"), "{}", d[0].message);
    }
}
