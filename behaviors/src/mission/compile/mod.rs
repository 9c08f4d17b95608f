//! Compiles behaviour trees written in a mission into an intermediate form, checking node
//! types, ports, literal types and ranges, children, state machines and subtree expansion
//! (stage "schema" for a node's own keys, "wiring" for how nodes connect), then checks the
//! blackboard wiring: every `{ref}` is written before it is read and has one type.

use std::collections::BTreeMap;
use std::time::Duration;

use crate::blackboard::{BbValue, PortType};
use crate::control::ControlType;
use crate::decorators::DecoratorType;
use crate::registry::{Category, NodeCatalog, NodeTypeSpec, PortSpec};
use crate::state_machine::Trigger;
use crate::status::Status;

use super::diagnostic::{Diagnostic, Stage};
use super::yaml::{Key, Loc, Node, Value};

mod control;
mod leaf;
mod state_machine;
mod subtree;
mod wiring;

use leaf::range_problem;
pub use wiring::check_wiring;

/// Index of a source file in the loaded mission.
pub type FileId = usize;

/// A compiled node.
#[derive(Debug, Clone)]
pub struct Ir {
    /// Node type name.
    pub type_name: String,
    /// Path from the role root.
    pub path: String,
    /// Where the node is written.
    pub loc: Loc,
    /// File it is written in.
    pub file: FileId,
    /// What it is.
    pub kind: IrKind,
}

/// The shape of a compiled node.
#[derive(Debug, Clone)]
pub enum IrKind {
    /// A control node.
    Control {
        /// Which.
        ty: ControlType,
        /// Children in order.
        children: Vec<Ir>,
        /// Parallel: successes needed.
        success_threshold: usize,
        /// Parallel: failures that fail it.
        failure_threshold: usize,
    },
    /// A decorator.
    Decorator {
        /// Which.
        ty: DecoratorType,
        /// The child.
        child: Box<Ir>,
        /// Duration for timeout/delay.
        duration: Duration,
        /// Count for retry/repeat (`None` = forever).
        count: Option<u32>,
        /// Rate for rate_limit.
        hz: f64,
        /// run_once: report Skipped after the first completion.
        then_skip: bool,
    },
    /// A state machine.
    StateMachine {
        /// States, initial first is not guaranteed.
        states: Vec<IrState>,
        /// Index of the initial state.
        initial: usize,
    },
    /// A leaf.
    Leaf {
        /// Bound ports.
        ports: Vec<IrPort>,
    },
}

/// A compiled state.
#[derive(Debug, Clone)]
pub struct IrState {
    /// Name.
    pub name: String,
    /// Subtree.
    pub run: Option<Ir>,
    /// Transitions (trigger, target index).
    pub transitions: Vec<(Trigger, usize)>,
    /// Terminal outcome.
    pub terminal: Option<Status>,
}

/// A bound port of a leaf.
#[derive(Debug, Clone)]
pub struct IrPort {
    /// The declaration.
    pub spec: PortSpec,
    /// How it is bound.
    pub binding: IrBinding,
    /// Where the binding is written (the node if defaulted).
    pub loc: Loc,
}

/// How a port is bound in the mission.
#[derive(Debug, Clone, PartialEq)]
pub enum IrBinding {
    /// A literal (or the port's default).
    Literal(BbValue),
    /// A `{name}` reference.
    Ref(String),
    /// An optional port left open.
    Unset,
}

/// A named subtree available to `subtree:` nodes.
#[derive(Debug, Clone)]
pub struct SubtreeDef {
    /// Its root node.
    pub node: Node,
    /// File it is written in.
    pub file: FileId,
}

/// The compiler for one mission.
pub struct Compiler<'a> {
    registry: &'a NodeCatalog,
    subtrees: &'a BTreeMap<String, SubtreeDef>,
    files: &'a [std::path::PathBuf],
    diags: Vec<Diagnostic>,
    expanding: Vec<String>,
}

/// If `s` is a `{name}` reference, the name.
pub fn parse_ref(s: &str) -> Option<&str> {
    let inner = s.strip_prefix('{')?.strip_suffix('}')?;
    let ok = !inner.is_empty()
        && inner.chars().next().is_some_and(|c| c.is_ascii_alphabetic() || c == '_')
        && inner.chars().all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '.');
    ok.then_some(inner)
}

const STRUCTURAL_KEYS_CONTROL: &[&str] = &["children", "name"];
const STRUCTURAL_KEYS_DECORATOR: &[&str] = &["child", "name"];

impl<'a> Compiler<'a> {
    /// A compiler over a registry and the mission's subtrees.
    pub fn new(
        registry: &'a NodeCatalog,
        subtrees: &'a BTreeMap<String, SubtreeDef>,
        files: &'a [std::path::PathBuf],
    ) -> Self {
        Compiler { registry, subtrees, files, diags: Vec::new(), expanding: Vec::new() }
    }

    /// Diagnostics so far.
    pub fn into_diagnostics(self) -> Vec<Diagnostic> {
        self.diags
    }

    pub(super) fn err(&mut self, file: FileId, loc: Loc, path: &str, stage: Stage, msg: impl Into<String>) {
        let f = self.files.get(file).cloned().unwrap_or_default();
        self.diags.push(Diagnostic::new(f, loc, path, stage, msg));
    }

    /// Compiles one tree rooted at `node`, whose path prefix is `path`.
    pub fn compile(&mut self, node: &Node, file: FileId, path: &str) -> Option<Ir> {
        let Some(entries) = node.as_map() else {
            self.err(
                file,
                node.loc,
                path,
                Stage::Schema,
                format!("expected a node (a mapping with one key, the node type), found {}", node.value.kind()),
            );
            return None;
        };
        if entries.len() != 1 {
            let keys: Vec<&str> = entries.iter().map(|(k, _)| k.name.as_str()).collect();
            self.err(
                file,
                node.loc,
                path,
                Stage::Schema,
                format!(
                    "expected exactly one key (the node type) in a node, found {}: {}",
                    entries.len(),
                    keys.join(", ")
                ),
            );
            return None;
        }
        let (key, body) = &entries[0];
        let Some(spec) = self.registry.get(&key.name) else {
            let hint = closest(&key.name, &self.registry.names())
                .map(|c| format!(" (did you mean `{c}`?)"))
                .unwrap_or_default();
            self.err(file, key.loc, path, Stage::Wiring, format!("unknown node type `{}`{hint}", key.name));
            return None;
        };
        let display = body.get("name").and_then(Node::as_str).unwrap_or(&spec.name);
        let my_path = if path.is_empty() { display.to_string() } else { format!("{path}/{display}") };
        match spec.category {
            Category::Control => self.control(spec, key, body, file, my_path),
            Category::Decorator => self.decorator(spec, key, body, file, my_path),
            Category::StateMachine => self.state_machine(spec, key, body, file, my_path),
            Category::Subtree => self.subtree(key, body, file, path, my_path),
            Category::Action | Category::Condition => self.leaf(spec, key, body, file, my_path),
        }
    }

    pub(super) fn params<'n>(
        &mut self,
        spec: &NodeTypeSpec,
        key: &Key,
        body: &'n Node,
        file: FileId,
        path: &str,
        structural: &[&str],
    ) -> Option<&'n [(Key, Node)]> {
        match &body.value {
            Value::Null => Some(&[]),
            Value::Map(m) => {
                for (k, _) in m {
                    if spec.port(&k.name).is_none() && !structural.contains(&k.name.as_str()) {
                        let mut expected: Vec<&str> = spec.ports.iter().map(|p| &*p.name).collect();
                        expected.extend(structural.iter().filter(|s| **s != "name"));
                        let list = if expected.is_empty() {
                            "it takes none".to_string()
                        } else {
                            format!("expected one of: {}", expected.join(", "))
                        };
                        self.err(
                            file,
                            k.loc,
                            path,
                            Stage::Schema,
                            format!("unknown port `{}` of node `{}`; {list}", k.name, spec.name),
                        );
                    }
                }
                Some(m)
            }
            other => {
                self.err(
                    file,
                    body.loc,
                    path,
                    Stage::Schema,
                    format!("expected the ports of `{}` as a mapping, found {}", key.name, other.kind()),
                );
                None
            }
        }
    }

    /// A literal value for a structural port (thresholds, durations): refs are not allowed.
    pub(super) fn literal_port(
        &mut self,
        spec: &NodeTypeSpec,
        body: &Node,
        name: &str,
        file: FileId,
        path: &str,
    ) -> Option<BbValue> {
        let port = spec.port(name)?;
        let Some(v) = body.get(name) else {
            return port.default.as_ref().and_then(|d| BbValue::from_json(port.ty, d).ok());
        };
        if v.as_str().and_then(parse_ref).is_some() {
            self.err(
                file,
                v.loc,
                path,
                Stage::Schema,
                format!("port `{name}` of `{}` must be a literal, not a blackboard reference", spec.name),
            );
            return None;
        }
        match BbValue::from_json(port.ty, &v.to_json()) {
            Ok(val) => {
                if let Some(msg) = range_problem(name, &val) {
                    self.err(file, v.loc, path, Stage::Schema, format!("port `{name}` of `{}`: {msg}", spec.name));
                    return None;
                }
                Some(val)
            }
            Err(e) => {
                self.err(file, v.loc, path, Stage::Schema, format!("port `{name}` of `{}`: {e}", spec.name));
                None
            }
        }
    }
}

/// The closest name by edit distance, if reasonably close.
pub fn closest<'n>(name: &str, candidates: &[&'n str]) -> Option<&'n str> {
    candidates
        .iter()
        .map(|c| (edit_distance(name, c), *c))
        .filter(|(d, c)| *d <= 2.max(c.len() / 3))
        .min()
        .map(|(_, c)| c)
}

fn edit_distance(a: &str, b: &str) -> usize {
    let a: Vec<char> = a.chars().collect();
    let b: Vec<char> = b.chars().collect();
    let mut prev: Vec<usize> = (0..=b.len()).collect();
    for i in 1..=a.len() {
        let mut cur = vec![i; b.len() + 1];
        for j in 1..=b.len() {
            let cost = usize::from(a[i - 1] != b[j - 1]);
            cur[j] = (prev[j] + 1).min(cur[j - 1] + 1).min(prev[j - 1] + cost);
        }
        prev = cur;
    }
    prev[b.len()]
}
