//! Node types: their ports declared once, registration by name, and the manifest that the docs
//! and the JSON schema are generated from.

use std::any::{Any, TypeId};
use std::borrow::Cow;
use std::collections::BTreeMap;
use std::sync::Arc;

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

/// A name or description: borrowed for the built-in node types, owned for types a lab
/// registers from its own configuration.
pub type Text = Cow<'static, str>;

/// One declared port.
#[derive(Clone, Debug, Serialize)]
pub struct PortSpec {
    /// Name as written in the mission.
    pub name: Text,
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
    pub description: Text,
}

impl PortSpec {
    fn new(name: Text, direction: PortDirection, ty: PortType, optional: bool, description: Text) -> Self {
        PortSpec { name, direction, ty, default: None, optional, description }
    }

    /// A required input.
    pub fn input(name: impl Into<Text>, ty: PortType, description: impl Into<Text>) -> Self {
        Self::new(name.into(), PortDirection::Input, ty, false, description.into())
    }

    /// An optional input with no default.
    pub fn optional(name: impl Into<Text>, ty: PortType, description: impl Into<Text>) -> Self {
        Self::new(name.into(), PortDirection::Input, ty, true, description.into())
    }

    /// An output (optional to connect).
    pub fn output(name: impl Into<Text>, ty: PortType, description: impl Into<Text>) -> Self {
        Self::new(name.into(), PortDirection::Output, ty, true, description.into())
    }

    /// An input/output.
    pub fn in_out(name: impl Into<Text>, ty: PortType, description: impl Into<Text>) -> Self {
        Self::new(name.into(), PortDirection::InOut, ty, false, description.into())
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

/// The ports of a node instance, bound and ready for its factory: every port its type
/// declares, bound to the mission's value, the declared default, or [`Binding::Unset`] (an
/// optional port left open). Reading a port the type does not declare is an error
/// ([`NodeError::UndeclaredPort`]), which [`NodeRegistry::try_register`] finds when the type is
/// registered: a misspelled port name in a factory fails when the registry is built, never
/// silently reads as unset.
#[derive(Debug, Clone, Default)]
pub struct PortBindings {
    bindings: BTreeMap<Text, Binding>,
    map_origin: Option<spomp_core::GeoPoint>,
}

impl PortBindings {
    /// The declared ports of `spec`, each bound as the mission language binds a port a mission
    /// leaves out: to its declared default, or unset. What the registry probes a factory with,
    /// and a start for code that builds a node by hand (tests, tools).
    pub fn declared(spec: &NodeTypeSpec) -> Self {
        let mut p = PortBindings::default();
        for port in &spec.ports {
            let binding = match &port.default {
                Some(d) => BbValue::from_json(port.ty, d).map_or(Binding::Unset, Binding::Literal),
                None => Binding::Unset,
            };
            p.insert(port.name.clone(), binding);
        }
        p
    }

    /// Where the map frame's origin lies on the Earth, when the tree is built for a
    /// georeferenced operating area (`BuildOptions::map_origin`); `None` otherwise.
    pub fn map_origin(&self) -> Option<spomp_core::GeoPoint> {
        self.map_origin
    }

    /// Sets the map origin factories see.
    pub fn set_map_origin(&mut self, origin: Option<spomp_core::GeoPoint>) {
        self.map_origin = origin;
    }

    /// Binds a port (the loader binds every declared port; a test may bind some by hand).
    pub fn insert(&mut self, name: impl Into<Text>, b: Binding) {
        self.bindings.insert(name.into(), b);
    }

    /// The binding of a declared port ([`Binding::Unset`] when the mission left an optional port
    /// open); an undeclared name is an error.
    pub fn get(&self, name: &str) -> Result<Binding, NodeError> {
        self.bindings.get(name).cloned().ok_or_else(|| NodeError::UndeclaredPort(Text::Owned(name.to_string())))
    }

    /// A literal value of a declared port known at build time (no blackboard), e.g. parameter
    /// blocks; `None` when it is bound to an entry or unset. An undeclared name is an error.
    pub fn literal(&self, name: &str) -> Result<Option<&BbValue>, NodeError> {
        match self.bindings.get(name) {
            Some(Binding::Literal(v)) => Ok(Some(v)),
            Some(_) => Ok(None),
            None => Err(NodeError::UndeclaredPort(Text::Owned(name.to_string()))),
        }
    }
}

/// Why a node type's factory refused to build a node.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum NodeError {
    /// The factory read a port its type does not declare: a bug in the node type's code,
    /// found when the type is registered ([`RegistrationError::UndeclaredPort`]).
    #[error("reads port `{0}`, which its node type does not declare")]
    UndeclaredPort(Text),
    /// A port's value cannot be used (a bad literal, a file that does not parse).
    #[error("{message}")]
    InvalidPort {
        /// The port.
        port: Text,
        /// What is wrong, naming the port.
        message: String,
    },
    /// The node cannot be built for another reason, in the factory's words.
    #[error("{0}")]
    Invalid(String),
}

impl NodeError {
    /// A port's value cannot be used; `message` names the port (it is shown as it is).
    pub fn port(port: impl Into<Text>, message: impl Into<String>) -> Self {
        NodeError::InvalidPort { port: port.into(), message: message.into() }
    }
}

/// Builds a leaf's behaviour from its bound ports; errors name what is wrong with the
/// parameters. A closure, so a node type can carry configuration or handles to the
/// services it calls. The registry calls it once when the type is registered, with the
/// declared defaults ([`PortBindings::declared`]), to find reads of undeclared ports: a factory
/// builds, it does not act (no I/O but reading files its ports name, no threads).
pub type LeafFactory<E> = Arc<dyn Fn(&PortBindings) -> Result<Box<dyn Behavior<E>>, NodeError> + Send + Sync>;

/// A registered node type: what the mission language and the docs know of it. Leaves also
/// have a factory, kept beside the spec in the [`NodeRegistry`].
#[derive(Clone, Serialize)]
pub struct NodeTypeSpec {
    /// Name used as the key in missions.
    pub name: Text,
    /// Kind.
    pub category: Category,
    /// One paragraph for the catalogue.
    pub description: Text,
    /// Declared ports.
    pub ports: Vec<PortSpec>,
    /// Robot kinds that can run it (empty = any).
    pub robot_kinds: Vec<RobotKind>,
    /// Skills it calls (`local_planner`, `global_planner`, `mapping`, `teamstate`,
    /// `localization`).
    pub skills: Vec<&'static str>,
}

impl std::fmt::Debug for NodeTypeSpec {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("NodeTypeSpec").field("name", &self.name).field("category", &self.category).finish()
    }
}

impl NodeTypeSpec {
    /// A leaf type (action or condition) with its factory; register it with
    /// [`NodeRegistry::try_register`]. The name and description may be built at run time (a
    /// lab that registers node types from its configuration); the factory is any closure.
    pub fn leaf<E, F>(
        name: impl Into<Text>,
        category: Category,
        description: impl Into<Text>,
        ports: Vec<PortSpec>,
        factory: F,
    ) -> LeafType<E>
    where
        F: Fn(&PortBindings) -> Result<Box<dyn Behavior<E>>, NodeError> + Send + Sync + 'static,
    {
        LeafType { spec: Self::structural(name, category, description, ports), factory: Arc::new(factory) }
    }

    /// A built-in structural type (control, decorator, state machine, subtree).
    pub fn structural(
        name: impl Into<Text>,
        category: Category,
        description: impl Into<Text>,
        ports: Vec<PortSpec>,
    ) -> Self {
        NodeTypeSpec {
            name: name.into(),
            category,
            description: description.into(),
            ports,
            robot_kinds: Vec::new(),
            skills: Vec::new(),
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

    /// A port by name.
    pub fn port(&self, name: &str) -> Option<&PortSpec> {
        self.ports.iter().find(|p| p.name == name)
    }
}

/// A leaf node type ready to register: its spec and its factory.
pub struct LeafType<E> {
    /// What the mission language and the docs know of it.
    pub spec: NodeTypeSpec,
    factory: LeafFactory<E>,
}

impl<E> LeafType<E> {
    /// Restricts the robot kinds.
    pub fn for_kinds(mut self, kinds: &[RobotKind]) -> Self {
        self.spec = self.spec.for_kinds(kinds);
        self
    }

    /// Declares the skills it calls.
    pub fn using_skills(mut self, skills: &[&'static str]) -> Self {
        self.spec = self.spec.using_skills(skills);
        self
    }
}

/// What can be registered: a structural spec (built by the mission language itself) or a leaf
/// type with its factory.
pub enum Registration<E> {
    /// Control, decorator, state machine or subtree.
    Structural(NodeTypeSpec),
    /// An action or condition.
    Leaf(LeafType<E>),
}

impl<E> From<NodeTypeSpec> for Registration<E> {
    fn from(spec: NodeTypeSpec) -> Self {
        Registration::Structural(spec)
    }
}

impl<E> From<LeafType<E>> for Registration<E> {
    fn from(leaf: LeafType<E>) -> Self {
        Registration::Leaf(leaf)
    }
}

/// The node types of a build as the mission language sees them: specs only, whatever the
/// robot type the trees will run on.
#[derive(Clone, Default)]
pub struct NodeCatalog {
    types: BTreeMap<Text, NodeTypeSpec>,
    extensions: Extensions,
}

impl std::fmt::Debug for NodeCatalog {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("NodeCatalog").field("types", &self.types.keys()).finish()
    }
}

/// What layers above registered beside the node types for the code that reads missions (the
/// robot layer's checks of robot settings, for the mission language), one value per type.
/// The engine carries them without knowing what they are, so it depends on no such layer.
#[derive(Clone, Default)]
struct Extensions(BTreeMap<TypeId, Arc<dyn Any + Send + Sync>>);

/// All node types known to a build, by name, with the factories that build leaves for trees
/// acting on `E` (the robot runtime; `()` for engine-only trees). Derefs to its
/// [`NodeCatalog`], which is all the mission language needs.
pub struct NodeRegistry<E> {
    catalog: NodeCatalog,
    factories: BTreeMap<Text, LeafFactory<E>>,
}

impl<E> Clone for NodeRegistry<E> {
    fn clone(&self) -> Self {
        NodeRegistry { catalog: self.catalog.clone(), factories: self.factories.clone() }
    }
}

impl<E> Default for NodeRegistry<E> {
    fn default() -> Self {
        NodeRegistry { catalog: NodeCatalog::default(), factories: BTreeMap::new() }
    }
}

impl<E> std::fmt::Debug for NodeRegistry<E> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("NodeRegistry").field("types", &self.catalog.types.keys()).finish()
    }
}

impl<E> std::ops::Deref for NodeRegistry<E> {
    type Target = NodeCatalog;
    fn deref(&self) -> &NodeCatalog {
        &self.catalog
    }
}

/// Why a node type cannot be registered: a programming error of the code that declares it.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum RegistrationError {
    /// A second registration under a name already taken.
    #[error("node type `{0}` is registered twice")]
    Duplicate(Text),
    /// The factory reads a port the type does not declare (a misspelled name in its code).
    #[error("node type `{node}`: its factory reads port `{port}`, which it does not declare")]
    UndeclaredPort {
        /// The node type.
        node: Text,
        /// The port read.
        port: Text,
    },
    /// A declared default is not a value of the port's type.
    #[error("node type `{node}`: the default of port `{port}` is not a {ty}: {message}")]
    BadDefault {
        /// The node type.
        node: Text,
        /// The port.
        port: Text,
        /// Its declared type.
        ty: PortType,
        /// What is wrong.
        message: String,
    },
    /// Two ports of one type share a name.
    #[error("node type `{node}` declares port `{port}` twice")]
    DuplicatePort {
        /// The node type.
        node: Text,
        /// The port.
        port: Text,
    },
}

/// Checks a type's declarations and probes its factory for reads of undeclared ports.
fn check_declarations<E>(spec: &NodeTypeSpec, factory: Option<&LeafFactory<E>>) -> Result<(), RegistrationError> {
    for (i, port) in spec.ports.iter().enumerate() {
        if spec.ports[..i].iter().any(|p| p.name == port.name) {
            return Err(RegistrationError::DuplicatePort { node: spec.name.clone(), port: port.name.clone() });
        }
        if let Some(d) = &port.default
            && let Err(message) = BbValue::from_json(port.ty, d)
        {
            return Err(RegistrationError::BadDefault {
                node: spec.name.clone(),
                port: port.name.clone(),
                ty: port.ty,
                message,
            });
        }
    }
    if let Some(factory) = factory
        && let Err(NodeError::UndeclaredPort(port)) = factory(&PortBindings::declared(spec))
    {
        return Err(RegistrationError::UndeclaredPort { node: spec.name.clone(), port });
    }
    Ok(())
}

impl<E> NodeRegistry<E> {
    /// An empty registry.
    pub fn empty() -> Self {
        Self::default()
    }

    /// Registers a node type. A name registered twice, a port declared twice, a default that is
    /// no value of its port's type, or a factory that reads a port the type does not declare
    /// (the factory is called once, with [`PortBindings::declared`]) is a programming error of
    /// the code that declares the type, reported rather than left to a mission to find.
    pub fn try_register(&mut self, r: impl Into<Registration<E>>) -> Result<(), RegistrationError> {
        let (spec, factory) = match r.into() {
            Registration::Structural(spec) => (spec, None),
            Registration::Leaf(LeafType { spec, factory }) => (spec, Some(factory)),
        };
        if self.catalog.types.contains_key(&spec.name) {
            return Err(RegistrationError::Duplicate(spec.name));
        }
        check_declarations(&spec, factory.as_ref())?;
        if let Some(f) = factory {
            self.factories.insert(spec.name.clone(), f);
        }
        self.catalog.types.insert(spec.name.clone(), spec);
        Ok(())
    }

    /// Registers a node type of the built-in libraries.
    ///
    /// # Panics
    /// On a [`RegistrationError`]: the built-in libraries register distinct names and read only
    /// the ports they declare, which their tests check by building the registry; a lab's own
    /// types go through [`NodeRegistry::try_register`].
    #[allow(clippy::panic)]
    pub fn register(&mut self, r: impl Into<Registration<E>>) {
        if let Err(e) = self.try_register(r) {
            panic!("{e}");
        }
    }

    /// The factory of a leaf type.
    pub fn factory(&self, name: &str) -> Option<&LeafFactory<E>> {
        self.factories.get(name)
    }

    /// The specs, for the mission language.
    pub fn catalog(&self) -> &NodeCatalog {
        &self.catalog
    }

    /// Keeps `value` beside the node types, replacing one of the same type: how a layer above
    /// hands the code that reads missions what it needs (see `mission::RobotChecks`).
    pub fn set_extension<T: Any + Send + Sync>(&mut self, value: T) {
        self.catalog.extensions.0.insert(TypeId::of::<T>(), Arc::new(value));
    }
}

impl NodeCatalog {
    /// A type by name.
    pub fn get(&self, name: &str) -> Option<&NodeTypeSpec> {
        self.types.get(name)
    }

    /// All types, sorted by name.
    pub fn iter(&self) -> impl Iterator<Item = &NodeTypeSpec> {
        self.types.values()
    }

    /// All names.
    pub fn names(&self) -> Vec<&str> {
        self.types.keys().map(|name| &**name).collect()
    }

    /// The value of type `T` kept by [`NodeRegistry::set_extension`], if any.
    pub fn extension<T: Any + Send + Sync>(&self) -> Option<&T> {
        self.extensions.0.get(&TypeId::of::<T>()).and_then(|v| v.downcast_ref::<T>())
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
