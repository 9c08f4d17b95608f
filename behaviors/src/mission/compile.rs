//! Compiles behaviour trees written in a mission into an intermediate form, checking node
//! types, ports, literal types and ranges, children, state machines and subtree expansion
//! (stage "schema" for a node's own keys, "wiring" for how nodes connect), then checks the
//! blackboard wiring: every `{ref}` is written before it is read and has one type.

use std::collections::{BTreeMap, HashMap, HashSet, VecDeque};
use std::time::Duration;

use crate::blackboard::{BbValue, PortType};
use crate::control::ControlType;
use crate::decorators::DecoratorType;
use crate::registry::{Category, NodeCatalog, NodeTypeSpec, PortSpec};
use crate::state_machine::Trigger;
use crate::status::Status;

use super::diagnostic::{Diagnostic, Stage};
use super::yaml::{Key, Loc, Node, Value};

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

    fn err(&mut self, file: FileId, loc: Loc, path: &str, stage: Stage, msg: impl Into<String>) {
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
        let display = body.get("name").and_then(Node::as_str).unwrap_or(spec.name);
        let my_path = if path.is_empty() { display.to_string() } else { format!("{path}/{display}") };
        match spec.category {
            Category::Control => self.control(spec, key, body, file, my_path),
            Category::Decorator => self.decorator(spec, key, body, file, my_path),
            Category::StateMachine => self.state_machine(spec, key, body, file, my_path),
            Category::Subtree => self.subtree(key, body, file, path, my_path),
            Category::Action | Category::Condition => self.leaf(spec, key, body, file, my_path),
        }
    }

    fn params<'n>(
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
                        let mut expected: Vec<&str> = spec.ports.iter().map(|p| p.name).collect();
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
    fn literal_port(
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

    fn control(&mut self, spec: &NodeTypeSpec, key: &Key, body: &Node, file: FileId, path: String) -> Option<Ir> {
        let ty = ControlType::from_name(spec.name)?;
        // Short form: `sequence: [a, b]`.
        let (children_node, params_ok) = match &body.value {
            Value::Seq(_) => (Some(body), true),
            _ => {
                let ok = self.params(spec, key, body, file, &path, STRUCTURAL_KEYS_CONTROL).is_some();
                (body.get("children"), ok)
            }
        };
        let Some(children_node) = children_node else {
            if params_ok {
                self.err(
                    file,
                    key.loc,
                    &path,
                    Stage::Schema,
                    format!("`{}` needs `children:` (a list of nodes)", spec.name),
                );
            }
            return None;
        };
        let Some(items) = children_node.as_seq() else {
            self.err(
                file,
                children_node.loc,
                &path,
                Stage::Schema,
                format!("`children` of `{}` must be a list of nodes, found {}", spec.name, children_node.value.kind()),
            );
            return None;
        };
        if items.is_empty() {
            self.err(
                file,
                children_node.loc,
                &path,
                Stage::Schema,
                format!("`{}` needs at least one child", spec.name),
            );
            return None;
        }
        let mut children = Vec::new();
        let mut ok = params_ok;
        for (i, item) in items.iter().enumerate() {
            let child_path = format!("{path}[{i}]");
            match self.compile(item, file, &child_path) {
                Some(c) => children.push(c),
                None => ok = false,
            }
        }
        let n = items.len();
        let (mut success_threshold, mut failure_threshold) = (n, 1);
        if ty == ControlType::Parallel && matches!(body.value, Value::Map(_)) {
            if let Some(BbValue::Int(s)) = self.literal_port(spec, body, "success_threshold", file, &path) {
                if s < 1 || s as usize > n {
                    let loc = body.get("success_threshold").map_or(key.loc, |v| v.loc);
                    self.err(
                        file,
                        loc,
                        &path,
                        Stage::Schema,
                        format!("success_threshold must be between 1 and the number of children ({n}), found {s}"),
                    );
                    ok = false;
                }
                success_threshold = s.max(1) as usize;
            }
            if let Some(BbValue::Int(f)) = self.literal_port(spec, body, "failure_threshold", file, &path) {
                if f < 1 || f as usize > n {
                    let loc = body.get("failure_threshold").map_or(key.loc, |v| v.loc);
                    self.err(
                        file,
                        loc,
                        &path,
                        Stage::Schema,
                        format!("failure_threshold must be between 1 and the number of children ({n}), found {f}"),
                    );
                    ok = false;
                }
                failure_threshold = f.max(1) as usize;
            }
        }
        ok.then(|| Ir {
            type_name: spec.name.into(),
            path,
            loc: key.loc,
            file,
            kind: IrKind::Control { ty, children, success_threshold, failure_threshold },
        })
    }

    fn decorator(&mut self, spec: &NodeTypeSpec, key: &Key, body: &Node, file: FileId, path: String) -> Option<Ir> {
        let ty = DecoratorType::from_name(spec.name)?;
        self.params(spec, key, body, file, &path, STRUCTURAL_KEYS_DECORATOR)?;
        let Some(child_node) = body.get("child") else {
            self.err(file, key.loc, &path, Stage::Schema, format!("`{}` needs `child:` (one node)", spec.name));
            return None;
        };
        let child = self.compile(child_node, file, &path);
        let mut ok = true;
        let mut duration = Duration::ZERO;
        let mut count = None;
        let mut hz = 0.0;
        let required = |c: &mut Self, name: &str| -> Option<BbValue> {
            let v = c.literal_port(spec, body, name, file, &path);
            if v.is_none() && body.get(name).is_none() {
                c.err(file, key.loc, &path, Stage::Schema, format!("missing port `{name}` of `{}`", spec.name));
            }
            v
        };
        match ty {
            DecoratorType::Timeout | DecoratorType::Delay => {
                let name = if ty == DecoratorType::Timeout { "duration_s" } else { "delay_s" };
                match required(self, name) {
                    Some(BbValue::Float(s)) => match super::limits::duration_from_secs(s) {
                        Ok(d) => duration = d,
                        Err(e) => {
                            let loc = body.get(name).map_or(key.loc, |v| v.loc);
                            self.err(file, loc, &path, Stage::Schema, format!("`{name}`: {e}"));
                            ok = false;
                        }
                    },
                    _ => ok = false,
                }
            }
            DecoratorType::Retry => match required(self, "max_attempts") {
                Some(BbValue::Int(n)) if n >= 1 => count = Some(n as u32),
                Some(BbValue::Int(n)) => {
                    let loc = body.get("max_attempts").map_or(key.loc, |v| v.loc);
                    self.err(file, loc, &path, Stage::Schema, format!("max_attempts must be at least 1, found {n}"));
                    ok = false;
                }
                _ => ok = false,
            },
            DecoratorType::Repeat => {
                if body.get("times").is_some() {
                    match self.literal_port(spec, body, "times", file, &path) {
                        Some(BbValue::Int(n)) if n >= 1 => count = Some(n as u32),
                        Some(BbValue::Int(n)) => {
                            let loc = body.get("times").map_or(key.loc, |v| v.loc);
                            self.err(
                                file,
                                loc,
                                &path,
                                Stage::Schema,
                                format!("times must be at least 1 (leave it out to repeat forever), found {n}"),
                            );
                            ok = false;
                        }
                        _ => ok = false,
                    }
                }
            }
            DecoratorType::RateLimit => match required(self, "hz") {
                Some(BbValue::Float(h)) if h > 0.0 => hz = h,
                Some(BbValue::Float(h)) => {
                    let loc = body.get("hz").map_or(key.loc, |v| v.loc);
                    self.err(file, loc, &path, Stage::Schema, format!("hz must be positive, found {h}"));
                    ok = false;
                }
                _ => ok = false,
            },
            DecoratorType::Inverter
            | DecoratorType::ForceSuccess
            | DecoratorType::ForceFailure
            | DecoratorType::RunOnce => {}
        }
        let child = child?;
        ok.then(|| Ir {
            type_name: spec.name.into(),
            path,
            loc: key.loc,
            file,
            kind: IrKind::Decorator { ty, child: Box::new(child), duration, count, hz },
        })
    }

    fn state_machine(&mut self, spec: &NodeTypeSpec, key: &Key, body: &Node, file: FileId, path: String) -> Option<Ir> {
        self.params(spec, key, body, file, &path, &["states", "name"])?;
        let Some(states_node) = body.get("states") else {
            self.err(
                file,
                key.loc,
                &path,
                Stage::Schema,
                "`state_machine` needs `states:` (a mapping of state names to states)",
            );
            return None;
        };
        let Some(state_entries) = states_node.as_map() else {
            self.err(
                file,
                states_node.loc,
                &path,
                Stage::Schema,
                format!("`states` must be a mapping of state names to states, found {}", states_node.value.kind()),
            );
            return None;
        };
        if state_entries.is_empty() {
            self.err(file, states_node.loc, &path, Stage::Schema, "`states` is empty");
            return None;
        }
        let index: HashMap<&str, usize> =
            state_entries.iter().enumerate().map(|(i, (k, _))| (k.name.as_str(), i)).collect();
        let names: Vec<&str> = state_entries.iter().map(|(k, _)| k.name.as_str()).collect();
        let mut ok = true;
        let initial = match body.get("initial") {
            None => {
                self.err(
                    file,
                    key.loc,
                    &path,
                    Stage::Schema,
                    "missing port `initial` of `state_machine` (the first state)",
                );
                return None;
            }
            Some(n) => match n.as_str() {
                Some(s) => match index.get(s) {
                    Some(&i) => i,
                    None => {
                        self.err(
                            file,
                            n.loc,
                            &path,
                            Stage::Wiring,
                            format!("initial state `{s}` is not defined; states are: {}", names.join(", ")),
                        );
                        return None;
                    }
                },
                None => {
                    self.err(
                        file,
                        n.loc,
                        &path,
                        Stage::Schema,
                        format!("`initial` must be a state name, found {}", n.value.kind()),
                    );
                    return None;
                }
            },
        };
        let mut states = Vec::new();
        for (k, snode) in state_entries {
            let spath = format!("{path}.{}", k.name);
            let mut st = IrState { name: k.name.clone(), run: None, transitions: Vec::new(), terminal: None };
            let Some(fields) = snode.as_map() else {
                self.err(
                    file,
                    snode.loc,
                    &spath,
                    Stage::Schema,
                    format!(
                        "a state must be a mapping with `run`, `transitions` or `terminal`, found {}",
                        snode.value.kind()
                    ),
                );
                ok = false;
                continue;
            };
            for (fk, fv) in fields {
                match fk.name.as_str() {
                    "run" => match self.compile(fv, file, &spath) {
                        Some(ir) => st.run = Some(ir),
                        None => ok = false,
                    },
                    "terminal" => match fv.as_str() {
                        Some("success") => st.terminal = Some(Status::Success),
                        Some("failure") => st.terminal = Some(Status::Failure),
                        _ => {
                            self.err(file, fv.loc, &spath, Stage::Schema, "`terminal` must be `success` or `failure`");
                            ok = false;
                        }
                    },
                    "transitions" => {
                        let Some(list) = fv.as_seq() else {
                            self.err(
                                file,
                                fv.loc,
                                &spath,
                                Stage::Schema,
                                format!("`transitions` must be a list, found {}", fv.value.kind()),
                            );
                            ok = false;
                            continue;
                        };
                        for (ti, t) in list.iter().enumerate() {
                            let tpath = format!("{spath}.transitions[{ti}]");
                            match self.transition(t, file, &tpath, &index, &names) {
                                Some(tr) => st.transitions.push(tr),
                                None => ok = false,
                            }
                        }
                    }
                    "description" => {}
                    other => {
                        self.err(
                            file,
                            fk.loc,
                            &spath,
                            Stage::Schema,
                            format!(
                                "unknown key `{other}` in a state; expected run, transitions, terminal or description"
                            ),
                        );
                        ok = false;
                    }
                }
            }
            if st.terminal.is_some() && (st.run.is_some() || !st.transitions.is_empty()) {
                self.err(
                    file,
                    k.loc,
                    &spath,
                    Stage::Wiring,
                    "a terminal state ends the machine: it cannot have `run` or `transitions`",
                );
                ok = false;
            }
            if st.terminal.is_none()
                && st.run.is_none()
                && !st.transitions.iter().any(|(t, _)| matches!(t, Trigger::Timer(_) | Trigger::Event(_)))
                && fields.iter().all(|(fk, _)| fk.name != "run")
            {
                self.err(file, k.loc, &spath, Stage::Wiring, "a state without `run` must have a timer or event transition, or be `terminal`; otherwise it waits forever");
                ok = false;
            }
            states.push(st);
        }
        if ok {
            // Every state must be reachable from the initial one.
            let mut seen = vec![false; states.len()];
            let mut queue = VecDeque::from([initial]);
            seen[initial] = true;
            while let Some(s) = queue.pop_front() {
                for &(_, t) in &states[s].transitions {
                    if !seen[t] {
                        seen[t] = true;
                        queue.push_back(t);
                    }
                }
            }
            for (i, (k, _)) in state_entries.iter().enumerate() {
                if !seen[i] {
                    self.err(
                        file,
                        k.loc,
                        &format!("{path}.{}", k.name),
                        Stage::Wiring,
                        format!(
                            "state `{}` is unreachable: no transition from `{}` leads to it",
                            k.name, names[initial]
                        ),
                    );
                    ok = false;
                }
            }
        }
        ok.then(|| Ir {
            type_name: spec.name.into(),
            path,
            loc: key.loc,
            file,
            kind: IrKind::StateMachine { states, initial },
        })
    }

    fn transition(
        &mut self,
        t: &Node,
        file: FileId,
        path: &str,
        index: &HashMap<&str, usize>,
        names: &[&str],
    ) -> Option<(Trigger, usize)> {
        let Some(fields) = t.as_map() else {
            self.err(
                file,
                t.loc,
                path,
                Stage::Schema,
                format!("a transition must be a mapping like `{{on: success, to: next}}`, found {}", t.value.kind()),
            );
            return None;
        };
        for (k, _) in fields {
            if !["on", "to", "after_s", "event"].contains(&k.name.as_str()) {
                self.err(
                    file,
                    k.loc,
                    path,
                    Stage::Schema,
                    format!("unknown key `{}` in a transition; expected on, to, after_s or event", k.name),
                );
                return None;
            }
        }
        let on = t.get("on").and_then(Node::as_str);
        let trigger = match on {
            Some("success") => Trigger::Success,
            Some("failure") => Trigger::Failure,
            Some("timer") => match t.get("after_s") {
                Some(v) => match v.as_f64() {
                    Some(s) => match super::limits::duration_from_secs(s) {
                        Ok(d) => Trigger::Timer(d),
                        Err(e) => {
                            self.err(file, v.loc, path, Stage::Schema, format!("`after_s`: {e}"));
                            return None;
                        }
                    },
                    None => {
                        self.err(
                            file,
                            v.loc,
                            path,
                            Stage::Schema,
                            format!("`after_s` must be a number of seconds, found {}", v.value.kind()),
                        );
                        return None;
                    }
                },
                None => {
                    self.err(file, t.loc, path, Stage::Schema, "a timer transition needs `after_s`");
                    return None;
                }
            },
            Some("event") => match t.get("event").and_then(Node::as_str) {
                Some(e) => Trigger::Event(e.to_string()),
                None => {
                    self.err(file, t.loc, path, Stage::Schema, "an event transition needs `event: <name>`");
                    return None;
                }
            },
            Some(other) => {
                let loc = t.get("on").map_or(t.loc, |n| n.loc);
                self.err(
                    file,
                    loc,
                    path,
                    Stage::Schema,
                    format!("unknown trigger `{other}`; expected success, failure, timer or event"),
                );
                return None;
            }
            None => {
                self.err(
                    file,
                    t.loc,
                    path,
                    Stage::Schema,
                    "a transition needs `on:` (success, failure, timer or event)",
                );
                return None;
            }
        };
        let Some(to_node) = t.get("to") else {
            self.err(file, t.loc, path, Stage::Schema, "a transition needs `to:` (the target state)");
            return None;
        };
        let Some(to) = to_node.as_str() else {
            self.err(
                file,
                to_node.loc,
                path,
                Stage::Schema,
                format!("`to` must be a state name, found {}", to_node.value.kind()),
            );
            return None;
        };
        match index.get(to) {
            Some(&i) => Some((trigger, i)),
            None => {
                self.err(
                    file,
                    to_node.loc,
                    path,
                    Stage::Wiring,
                    format!("transition to undefined state `{to}`; states are: {}", names.join(", ")),
                );
                None
            }
        }
    }

    fn subtree(&mut self, key: &Key, body: &Node, file: FileId, parent_path: &str, path: String) -> Option<Ir> {
        let name_node = match &body.value {
            Value::Str(_) => body,
            Value::Map(m) => {
                for (k, _) in m {
                    if k.name != "name" {
                        self.err(
                            file,
                            k.loc,
                            &path,
                            Stage::Schema,
                            format!("unknown port `{}` of node `subtree`; expected one of: name", k.name),
                        );
                        return None;
                    }
                }
                let Some(n) = body.get("name") else {
                    self.err(file, key.loc, &path, Stage::Schema, "missing port `name` of `subtree`");
                    return None;
                };
                n
            }
            other => {
                self.err(
                    file,
                    body.loc,
                    &path,
                    Stage::Schema,
                    format!("`subtree` takes a name, found {}", other.kind()),
                );
                return None;
            }
        };
        let Some(name) = name_node.as_str() else {
            self.err(
                file,
                name_node.loc,
                &path,
                Stage::Schema,
                format!("subtree name must be a string, found {}", name_node.value.kind()),
            );
            return None;
        };
        let Some(def) = self.subtrees.get(name) else {
            let known: Vec<&str> = self.subtrees.keys().map(String::as_str).collect();
            let list = if known.is_empty() {
                "none are defined".to_string()
            } else {
                format!("defined: {}", known.join(", "))
            };
            self.err(file, name_node.loc, &path, Stage::Wiring, format!("unknown subtree `{name}`; {list}"));
            return None;
        };
        if self.expanding.iter().any(|n| n == name) {
            let mut cycle = self.expanding.clone();
            cycle.push(name.to_string());
            self.err(file, name_node.loc, &path, Stage::Wiring, format!("subtree cycle: {}", cycle.join(" → ")));
            return None;
        }
        self.expanding.push(name.to_string());
        let sub_path = if parent_path.is_empty() { name.to_string() } else { format!("{parent_path}/{name}") };
        let ir = self.compile(&def.node, def.file, &sub_path);
        self.expanding.pop();
        ir
    }

    fn leaf(&mut self, spec: &NodeTypeSpec, key: &Key, body: &Node, file: FileId, path: String) -> Option<Ir> {
        let params = self.params(spec, key, body, file, &path, &["name"])?;
        let mut ok = true;
        let mut ports = Vec::new();
        for port in &spec.ports {
            let written = params.iter().find(|(k, _)| k.name == port.name);
            let (binding, loc) = match written {
                Some((_, v)) => {
                    let as_ref = v.as_str().and_then(parse_ref);
                    match (as_ref, port.ty) {
                        (Some(r), PortType::Params) => {
                            self.err(
                                file,
                                v.loc,
                                &path,
                                Stage::Schema,
                                format!(
                                    "port `{}` of `{}` takes a parameter block, not a reference `{{{r}}}`",
                                    port.name, spec.name
                                ),
                            );
                            ok = false;
                            continue;
                        }
                        (Some(r), _) => (IrBinding::Ref(r.to_string()), v.loc),
                        (None, _)
                            if port.direction == crate::registry::PortDirection::Output
                                || port.direction == crate::registry::PortDirection::InOut =>
                        {
                            self.err(
                                file,
                                v.loc,
                                &path,
                                Stage::Wiring,
                                format!(
                                    "output port `{}` of `{}` must name a blackboard entry like \"{{{}}}\", found {}",
                                    port.name,
                                    spec.name,
                                    port.name,
                                    v.value.kind()
                                ),
                            );
                            ok = false;
                            continue;
                        }
                        (None, _) => match BbValue::from_json(port.ty, &v.to_json()) {
                            Ok(val) => {
                                if let Some(msg) = range_problem(port.name, &val) {
                                    self.err(
                                        file,
                                        v.loc,
                                        &path,
                                        Stage::Schema,
                                        format!("port `{}` of `{}`: {msg}", port.name, spec.name),
                                    );
                                    ok = false;
                                    continue;
                                }
                                (IrBinding::Literal(val), v.loc)
                            }
                            Err(e) => {
                                self.err(
                                    file,
                                    v.loc,
                                    &path,
                                    Stage::Schema,
                                    format!("port `{}` of `{}` ({}): {e}", port.name, spec.name, port.ty),
                                );
                                ok = false;
                                continue;
                            }
                        },
                    }
                }
                None => match &port.default {
                    Some(d) => match BbValue::from_json(port.ty, d) {
                        Ok(v) => (IrBinding::Literal(v), key.loc),
                        Err(_) => (IrBinding::Unset, key.loc),
                    },
                    None if port.optional => (IrBinding::Unset, key.loc),
                    None => {
                        self.err(
                            file,
                            key.loc,
                            &path,
                            Stage::Wiring,
                            format!(
                                "missing port `{}` ({}) of `{}`: {}",
                                port.name, port.ty, spec.name, port.description
                            ),
                        );
                        ok = false;
                        continue;
                    }
                },
            };
            ports.push(IrPort { spec: port.clone(), binding, loc });
        }
        ok.then(|| Ir { type_name: spec.name.into(), path, loc: key.loc, file, kind: IrKind::Leaf { ports } })
    }
}

/// A unit-suffix range rule: durations, distances, rates and speeds cannot be negative.
fn range_problem(name: &str, v: &BbValue) -> Option<String> {
    let x = match v {
        BbValue::Float(f) => *f,
        BbValue::Int(i) => *i as f64,
        _ => return None,
    };
    let unit = [("_s", "seconds"), ("_m", "metres"), ("_hz", "per second"), ("_mps", "metres per second")]
        .into_iter()
        .find(|(suffix, _)| name.ends_with(suffix))
        .map(|(_, u)| u);
    match unit {
        Some(u) if x < 0.0 => Some(format!("expected a non-negative value in {u}, found {x}")),
        _ => None,
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

/// One use of a blackboard entry, in execution order.
#[derive(Debug, Clone)]
struct Use {
    name: String,
    ty: PortType,
    reads: bool,
    writes: bool,
    file: FileId,
    loc: Loc,
    path: String,
    port: &'static str,
    node: String,
}

fn collect_uses(ir: &Ir, out: &mut Vec<Use>) {
    match &ir.kind {
        IrKind::Leaf { ports } => {
            for p in ports {
                if let IrBinding::Ref(name) = &p.binding {
                    out.push(Use {
                        name: name.clone(),
                        ty: p.spec.ty,
                        reads: p.spec.reads(),
                        writes: p.spec.writes(),
                        file: ir.file,
                        loc: p.loc,
                        path: ir.path.clone(),
                        port: p.spec.name,
                        node: ir.type_name.clone(),
                    });
                }
            }
        }
        IrKind::Control { children, .. } => children.iter().for_each(|c| collect_uses(c, out)),
        IrKind::Decorator { child, .. } => collect_uses(child, out),
        IrKind::StateMachine { states, initial } => {
            // States in the order they can first run: breadth-first from the initial state.
            let mut order = Vec::new();
            let mut seen = HashSet::new();
            let mut queue = VecDeque::from([*initial]);
            while let Some(s) = queue.pop_front() {
                if !seen.insert(s) {
                    continue;
                }
                order.push(s);
                for &(_, t) in &states[s].transitions {
                    queue.push_back(t);
                }
            }
            for s in order {
                if let Some(run) = &states[s].run {
                    collect_uses(run, out);
                }
            }
        }
    }
}

/// Checks the blackboard wiring of a compiled role tree: every reference read is written
/// earlier (in execution order) or given in `initial` (role blackboard and executor-provided
/// entries), and every entry has one type. Returns the type of every entry.
pub fn check_wiring(
    ir: &Ir,
    initial: &BTreeMap<String, (Option<PortType>, Loc, FileId)>,
    files: &[std::path::PathBuf],
    diags: &mut Vec<Diagnostic>,
) -> BTreeMap<String, PortType> {
    let mut uses = Vec::new();
    collect_uses(ir, &mut uses);
    let mut types: BTreeMap<String, (PortType, String)> = BTreeMap::new();
    for (name, (ty, _, _)) in initial {
        if let Some(t) = ty {
            types.insert(name.clone(), (*t, "the role's blackboard".into()));
        }
    }
    let mut written: HashSet<String> = initial.keys().cloned().collect();
    let file_of = |f: FileId| files.get(f).cloned().unwrap_or_default();
    for u in &uses {
        let here = format!("port `{}` of `{}`", u.port, u.node);
        match types.get(&u.name) {
            Some((t, by)) if !t.accepts(u.ty) && !u.ty.accepts(*t) => {
                diags.push(Diagnostic::new(
                    file_of(u.file),
                    u.loc,
                    &u.path,
                    Stage::Wiring,
                    format!("`{{{}}}` is a {t} (from {by}) but {here} expects a {}", u.name, u.ty),
                ));
            }
            Some(_) => {}
            None => {
                types.insert(u.name.clone(), (u.ty, here.clone()));
            }
        }
        if u.reads && !u.writes && !written.contains(&u.name) {
            diags.push(Diagnostic::new(
                file_of(u.file),
                u.loc,
                &u.path,
                Stage::Wiring,
                format!("`{{{}}}` is read by {here} before any node writes it (write it earlier, or give it in the role's `blackboard:`)", u.name),
            ));
        }
        if u.writes {
            written.insert(u.name.clone());
        }
    }
    types.into_iter().map(|(k, (t, _))| (k, t)).collect()
}
