//! Node types: their ports declared once, registration by name, and the manifest that the docs
//! and the JSON schema are generated from.

use std::collections::BTreeMap;

use serde::Serialize;
use spomp_core::RobotKind;

use crate::blackboard::{BbValue, Binding, PortType};
use crate::node::Behavior;

/// Direction of a port.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum PortDirection {
    /// The node reads it.
    Input,
    /// The node writes it (must be a `{ref}`).
    Output,
    /// Both.
    InOut,
}

/// One declared port.
#[derive(Clone, Debug, Serialize)]
pub struct PortSpec {
    /// Name as written in the mission.
    pub name: &'static str,
    /// Direction.
    pub direction: PortDirection,
    /// Type.
    #[serde(rename = "type")]
    pub ty: PortType,
    /// Default value (JSON) when the mission leaves the port out; `None` = required unless
    /// `optional`.
    pub default: Option<serde_json::Value>,
    /// May be left unconnected with no default.
    pub optional: bool,
    /// What it means (units in the name).
    pub description: &'static str,
}

impl PortSpec {
    /// A required input.
    pub const fn input(name: &'static str, ty: PortType, description: &'static str) -> Self {
        PortSpec { name, direction: PortDirection::Input, ty, default: None, optional: false, description }
    }

    /// An optional input with no default.
    pub const fn optional(name: &'static str, ty: PortType, description: &'static str) -> Self {
        PortSpec { name, direction: PortDirection::Input, ty, default: None, optional: true, description }
    }

    /// An output (optional to connect).
    pub const fn output(name: &'static str, ty: PortType, description: &'static str) -> Self {
        PortSpec { name, direction: PortDirection::Output, ty, default: None, optional: true, description }
    }

    /// An input/output.
    pub const fn in_out(name: &'static str, ty: PortType, description: &'static str) -> Self {
        PortSpec { name, direction: PortDirection::InOut, ty, default: None, optional: false, description }
    }

    /// Sets a default (making the port optional).
    pub fn with_default(mut self, v: serde_json::Value) -> Self {
        self.default = Some(v);
        self.optional = true;
        self
    }

    /// Whether the node reads this port.
    pub fn reads(&self) -> bool {
        matches!(self.direction, PortDirection::Input | PortDirection::InOut)
    }

    /// Whether the node writes this port.
    pub fn writes(&self) -> bool {
        matches!(self.direction, PortDirection::Output | PortDirection::InOut)
    }
}

/// Kind of node, for the catalogue and the loader.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Category {
    /// Has a list of children.
    Control,
    /// Has one child.
    Decorator,
    /// States with subtrees.
    StateMachine,
    /// Does something.
    Action,
    /// Checks something; never Running.
    Condition,
    /// Refers to a named subtree.
    Subtree,
}

/// The ports of a node instance, bound and ready for its factory.
#[derive(Debug, Clone, Default)]
pub struct PortBindings {
    bindings: BTreeMap<&'static str, Binding>,
}

impl PortBindings {
    /// Adds a binding.
    pub fn insert(&mut self, name: &'static str, b: Binding) {
        self.bindings.insert(name, b);
    }

    /// The binding of a port (Unset if the mission left an optional port open).
    pub fn get(&self, name: &str) -> Binding {
        self.bindings.get(name).cloned().unwrap_or(Binding::Unset)
    }

    /// A literal value of a port known at build time (no blackboard), e.g. parameter blocks.
    pub fn literal(&self, name: &str) -> Option<&BbValue> {
        match self.bindings.get(name) {
            Some(Binding::Literal(v)) => Some(v),
            _ => None,
        }
    }
}

/// Builds a leaf's behaviour from its bound ports. Errors name what is wrong with the
/// parameters.
pub type LeafFactory = fn(&PortBindings) -> Result<Box<dyn Behavior>, String>;

/// A registered node type.
#[derive(Clone, Serialize)]
pub struct NodeTypeSpec {
    /// Name used as the key in missions.
    pub name: &'static str,
    /// Kind.
    pub category: Category,
    /// One paragraph for the catalogue.
    pub description: &'static str,
    /// Declared ports.
    pub ports: Vec<PortSpec>,
    /// Robot kinds that can run it (empty = any).
    pub robot_kinds: Vec<RobotKind>,
    /// Skills it calls (`local_planner`, `global_planner`, `mapping`, `teamstate`,
    /// `localization`).
    pub skills: Vec<&'static str>,
    /// Whether this build can run it; ticking an unimplemented node fails loudly.
    pub implemented: bool,
    #[serde(skip)]
    pub(crate) factory: Option<LeafFactory>,
}

impl std::fmt::Debug for NodeTypeSpec {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("NodeTypeSpec").field("name", &self.name).field("category", &self.category).finish()
    }
}

impl NodeTypeSpec {
    /// A leaf type (action or condition) with its factory.
    pub fn leaf(
        name: &'static str,
        category: Category,
        description: &'static str,
        ports: Vec<PortSpec>,
        factory: LeafFactory,
    ) -> Self {
        NodeTypeSpec { factory: Some(factory), ..Self::structural(name, category, description, ports) }
    }

    /// A built-in structural type (control, decorator, state machine, subtree).
    pub fn structural(name: &'static str, category: Category, description: &'static str, ports: Vec<PortSpec>) -> Self {
        NodeTypeSpec {
            name,
            category,
            description,
            ports,
            robot_kinds: Vec::new(),
            skills: Vec::new(),
            implemented: true,
            factory: None,
        }
    }

    /// Restricts the robot kinds.
    pub fn for_kinds(mut self, kinds: &[RobotKind]) -> Self {
        self.robot_kinds = kinds.to_vec();
        self
    }

    /// Declares the skills it calls.
    pub fn using_skills(mut self, skills: &[&'static str]) -> Self {
        self.skills = skills.to_vec();
        self
    }

    /// Marks it as not implemented in this build.
    pub fn unimplemented(mut self) -> Self {
        self.implemented = false;
        self
    }

    /// A port by name.
    pub fn port(&self, name: &str) -> Option<&PortSpec> {
        self.ports.iter().find(|p| p.name == name)
    }

    /// The factory (leaves only).
    pub fn factory(&self) -> Option<LeafFactory> {
        self.factory
    }
}

/// All node types known to a build, by name.
#[derive(Clone, Default, Debug)]
pub struct NodeRegistry {
    types: BTreeMap<&'static str, NodeTypeSpec>,
}

impl NodeRegistry {
    /// An empty registry.
    pub fn empty() -> Self {
        Self::default()
    }

    /// Registers a type; a later registration of the same name replaces the earlier one (so an
    /// adapter can supply the real implementation of a declared node).
    pub fn register(&mut self, spec: NodeTypeSpec) {
        self.types.insert(spec.name, spec);
    }

    /// A type by name.
    pub fn get(&self, name: &str) -> Option<&NodeTypeSpec> {
        self.types.get(name)
    }

    /// All types, sorted by name.
    pub fn iter(&self) -> impl Iterator<Item = &NodeTypeSpec> {
        self.types.values()
    }

    /// All names.
    pub fn names(&self) -> Vec<&'static str> {
        self.types.keys().copied().collect()
    }

    /// The manifest: every node type with its ports, as JSON.
    pub fn manifest(&self) -> serde_json::Value {
        serde_json::to_value(self.types.values().collect::<Vec<_>>()).unwrap_or_default()
    }

    /// The node reference as Markdown (`docs/nodes.md` is generated from it).
    pub fn reference_markdown(&self) -> String {
        let mut out = String::from(
            "# Node reference\n\nGenerated by `spomp nodes --markdown` from the node manifest; do not edit by hand.\n",
        );
        let sections = [
            (Category::Control, "Control nodes"),
            (Category::Decorator, "Decorators"),
            (Category::StateMachine, "State machine"),
            (Category::Subtree, "Subtrees"),
            (Category::Condition, "Conditions"),
            (Category::Action, "Actions"),
        ];
        for (category, title) in sections {
            out.push_str(&format!("\n## {title}\n"));
            for spec in self.types.values().filter(|s| s.category == category) {
                out.push_str(&format!("\n### `{}`\n\n{}\n", spec.name, spec.description));
                let kinds = if spec.robot_kinds.is_empty() {
                    "any".to_string()
                } else {
                    spec.robot_kinds.iter().map(|k| k.as_str()).collect::<Vec<_>>().join(", ")
                };
                out.push_str(&format!("\nRobots: {kinds}."));
                if !spec.skills.is_empty() {
                    out.push_str(&format!(" Skills: {}.", spec.skills.join(", ")));
                }
                if !spec.implemented {
                    out.push_str(" *Declared; not implemented in this build.*");
                }
                out.push('\n');
                if spec.ports.is_empty() {
                    continue;
                }
                out.push_str("\n| port | direction | type | default | description |\n|---|---|---|---|---|\n");
                for p in &spec.ports {
                    let dir = match p.direction {
                        PortDirection::Input => "in",
                        PortDirection::Output => "out",
                        PortDirection::InOut => "in/out",
                    };
                    let default = match (&p.default, p.optional) {
                        (Some(d), _) => format!("`{d}`"),
                        (None, true) => "optional".into(),
                        (None, false) => "required".into(),
                    };
                    out.push_str(&format!("| `{}` | {dir} | {} | {default} | {} |\n", p.name, p.ty, p.description));
                }
            }
        }
        out
    }
}
