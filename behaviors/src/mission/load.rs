//! Loading a mission: read and parse every file (stage parse), check keys, types and ranges
//! (schema), compile the trees and check how nodes connect (wiring), then check the team
//! (team). Every stage reports all the problems it finds; later stages run on whatever the
//! earlier ones could make sense of.

use std::collections::{BTreeMap, HashMap, HashSet};
use std::path::{Path, PathBuf};

use spomp_core::{ClassTable, RobotKind};

use crate::blackboard::{BbValue, PortType};
use crate::registry::{NodeCatalog, NodeRegistry};

use super::compile::{Compiler, FileId, Ir, IrKind, SubtreeDef, check_wiring};
use super::diagnostic::{Diagnostic, Stage};
use super::limits;
use super::schema::{IncludeFile, MissionFile, RobotSpec};
use super::yaml::{DeError, Loc, Node, parse};

/// Blackboard entries every robot's executor provides before the first tick.
pub const PROVIDED_ENTRIES: &[(&str, PortType)] =
    &[("robot_id", PortType::Robot), ("start_pose", PortType::Pose), ("home", PortType::Point)];

/// Skills each robot kind carries.
pub fn skills_of(kind: RobotKind) -> &'static [&'static str] {
    match kind {
        RobotKind::Ugv => &["local_planner", "global_planner", "localization", "mapping", "teamstate"],
        RobotKind::Uav => &["mapping", "teamstate"],
        RobotKind::Basestation => &["mapping", "teamstate"],
    }
}

/// A compiled role.
#[derive(Debug, Clone)]
pub struct CompiledRole {
    /// The tree.
    pub tree: Ir,
    /// Type of every blackboard entry the tree uses.
    pub entry_types: BTreeMap<String, PortType>,
    /// Initial blackboard values from the role.
    pub initial: Vec<(String, BbValue)>,
    /// Entries kept across reboots (`persist`).
    pub persist: Vec<String>,
    /// Tick rate.
    pub tick_hz: f64,
}

/// The result of loading a mission: what could be understood, and every problem found.
#[derive(Debug, Default)]
pub struct LoadedMission {
    /// Files read: the mission first, then includes.
    pub files: Vec<PathBuf>,
    /// Their text, same order.
    pub sources: Vec<String>,
    /// The typed mission, if the schema stage passed.
    pub mission: Option<MissionFile>,
    /// Compiled roles (those that compiled).
    pub roles: BTreeMap<String, CompiledRole>,
    /// Problems, sorted by file and position.
    pub diagnostics: Vec<Diagnostic>,
}

impl LoadedMission {
    /// Whether the mission is valid: it has no error (warnings allowed).
    pub fn is_valid(&self) -> bool {
        self.mission.is_some() && !self.diagnostics.iter().any(Diagnostic::is_error)
    }

    /// The source text of a diagnostic's file.
    pub fn source_of(&self, file: &Path) -> Option<&str> {
        self.files.iter().position(|f| f == file).and_then(|i| self.sources.get(i)).map(String::as_str)
    }

    /// Folder of the mission file (where relative paths in it start).
    pub fn base_dir(&self) -> PathBuf {
        self.files.first().and_then(|f| f.parent()).map(Path::to_path_buf).unwrap_or_default()
    }
}

fn de_diag(file: &Path, prefix: &str, e: &DeError, fallback: Loc) -> Diagnostic {
    let sub = e.path_string();
    let path = match (prefix.is_empty(), sub.is_empty()) {
        (true, _) => sub,
        (false, true) => prefix.to_string(),
        (false, false) if sub.starts_with('[') => format!("{prefix}{sub}"),
        (false, false) => format!("{prefix}.{sub}"),
    };
    Diagnostic::new(file, e.loc.unwrap_or(fallback), path, Stage::Schema, e.message.clone())
}

/// How to load a mission.
#[derive(Debug, Clone, Default)]
pub struct LoadOptions {
    /// Folders besides the mission's own that its includes, plan files and world folder may be
    /// in (the command line's `--allow-dir`). Without them, every file a mission names must be
    /// inside the mission's folder.
    pub allowed_dirs: Vec<PathBuf>,
}

/// Loads and validates a mission file against a node registry.
pub fn load_mission<E: 'static>(path: &Path, nodes: &NodeRegistry<E>) -> LoadedMission {
    load_mission_with(path, nodes, &LoadOptions::default())
}

/// Loads and validates a mission file against a node registry, with options.
pub fn load_mission_with<E: 'static>(path: &Path, nodes: &NodeRegistry<E>, options: &LoadOptions) -> LoadedMission {
    match limits::read_text(path, limits::MAX_SOURCE_BYTES) {
        Ok(text) => load_mission_str(&text, path, nodes, options),
        Err(e) => {
            let mut out = LoadedMission::default();
            out.files.push(path.to_path_buf());
            out.sources.push(String::new());
            let (line, column) = e.position().unwrap_or((1, 1));
            let loc = Loc { line, column, offset: None, len: 0 };
            out.diagnostics.push(Diagnostic::new(path, loc, "", Stage::Parse, format!("cannot read the mission: {e}")));
            out
        }
    }
}

/// Loads and validates a mission held in a string. `path` names it in diagnostics and places
/// it: its includes, plan files and world are looked up from `path`'s folder (and
/// `options.allowed_dirs`) as for a mission read from `path`, which need not exist.
///
/// The stages, each a function of its own reporting its problems as diagnostics of its
/// [`Stage`]: [`parse_stage`], [`schema_stage`], [`include_stage`], [`wiring_stage`] (with the
/// limits on literals), [`team_stage`], then, when all of them passed, [`build_stage`]. A later
/// stage runs on whatever the earlier ones could make sense of.
pub fn load_mission_str<E: 'static>(
    text: &str,
    path: &Path,
    nodes: &NodeRegistry<E>,
    options: &LoadOptions,
) -> LoadedMission {
    let registry = nodes.catalog();
    let mut out = LoadedMission::default();
    let roots: Vec<PathBuf> = std::iter::once(path.parent().map(Path::to_path_buf).unwrap_or_default())
        .chain(options.allowed_dirs.iter().cloned())
        .collect();
    out.files.push(path.to_path_buf());
    let root = match parse_stage(text, path) {
        Ok(root) => {
            out.sources.push(text.to_string());
            root
        }
        Err(failure) => {
            let ParseFailure { source, diagnostic } = *failure;
            out.sources.push(source);
            out.diagnostics.push(diagnostic);
            return out;
        }
    };
    let mut diags = Vec::new();
    let Some(mission) = schema_stage(&root, path, &roots, &mut diags) else {
        if root.as_map().is_none() {
            // Not even a mapping: nothing later stages could read.
            out.diagnostics = diags;
            return out;
        }
        return finish_without_mission(out, &root, path, registry, &roots, diags);
    };
    let subtrees = include_stage(&root, path, &roots, &mut out, &mut diags);
    wiring_stage(&root, path, registry, &subtrees, &roots, &mut out, &mut diags);
    team_stage(&mission, &root, path, registry, &out.roles, &mut diags);
    // Warnings (a role that ignores the operator) do not stop the node factories' checks.
    if !diags.iter().any(Diagnostic::is_error) {
        build_stage(nodes, path, &out, &mut diags);
    }
    finish(out, Some(mission), diags)
}

/// The stages that do not need a typed mission, for a mission whose schema stage failed: its
/// trees are still compiled and checked, so every broken part is reported in one pass.
fn finish_without_mission(
    mut out: LoadedMission,
    root: &Node,
    path: &Path,
    registry: &NodeCatalog,
    roots: &[PathBuf],
    mut diags: Vec<Diagnostic>,
) -> LoadedMission {
    let subtrees = include_stage(root, path, roots, &mut out, &mut diags);
    wiring_stage(root, path, registry, &subtrees, roots, &mut out, &mut diags);
    finish(out, None, diags)
}

fn finish(mut out: LoadedMission, mission: Option<MissionFile>, mut diags: Vec<Diagnostic>) -> LoadedMission {
    diags.sort_by_key(|d| (d.file.clone(), d.line, d.column));
    diags.dedup();
    out.diagnostics = diags;
    out.mission = mission;
    out
}

/// Why the parse stage stopped.
#[derive(Debug)]
pub struct ParseFailure {
    /// The source to keep for the mission (empty when it was too big to keep).
    pub source: String,
    /// The problem.
    pub diagnostic: Diagnostic,
}

/// Stage parse: the mission's text within the size limit, parsed into a span-carrying tree.
pub fn parse_stage(text: &str, path: &Path) -> Result<Node, Box<ParseFailure>> {
    if text.len() as u64 > limits::MAX_SOURCE_BYTES {
        let message = format!(
            "the mission is {} bytes, more than the {} a mission may have",
            text.len(),
            limits::MAX_SOURCE_BYTES
        );
        let at = Loc { line: 1, column: 1, offset: None, len: 0 };
        let diagnostic = Diagnostic::new(path, at, "", Stage::Parse, message);
        return Err(Box::new(ParseFailure { source: String::new(), diagnostic }));
    }
    parse(text).map_err(|e| {
        let diagnostic = Diagnostic::new(path, e.loc, "", Stage::Parse, e.message);
        Box::new(ParseFailure { source: text.to_string(), diagnostic })
    })
}

/// The mission's top-level sections, in the order the docs list them.
const SECTIONS: &[&str] = &[
    "mission",
    "description",
    "include",
    "team",
    "goals",
    "roles",
    "subtrees",
    "complete_when",
    "time_limit_s",
    "comms",
    "sim",
    "classes",
];

/// Stage schema: each section on its own, so every broken section is reported; then the whole
/// typed mission and the ranges of its values. `None` when any section is broken.
pub fn schema_stage(root: &Node, path: &Path, roots: &[PathBuf], diags: &mut Vec<Diagnostic>) -> Option<MissionFile> {
    let Some(entries) = root.as_map() else {
        diags.push(Diagnostic::new(
            path,
            root.loc,
            "",
            Stage::Schema,
            format!("a mission is a mapping with `mission`, `team`, `roles`, …; found {}", root.value.kind()),
        ));
        return None;
    };
    let mut section_ok = true;
    for (k, v) in entries {
        if !SECTIONS.contains(&k.name.as_str()) {
            let other = k.name.as_str();
            let hint =
                super::compile::closest(other, SECTIONS).map(|c| format!(" (did you mean `{c}`?)")).unwrap_or_default();
            diags.push(Diagnostic::new(
                path,
                k.loc,
                other,
                Stage::Schema,
                format!("unknown key `{other}`{hint}; expected one of: {}", SECTIONS.join(", ")),
            ));
            section_ok = false;
            continue;
        }
        match check_section(&k.name, v, path, diags) {
            Ok(()) => {}
            Err(Some(e)) => {
                diags.push(de_diag(path, &k.name, &e, v.loc));
                section_ok = false;
            }
            Err(None) => section_ok = false,
        }
    }
    if !section_ok {
        return None;
    }
    match root.deserialize::<MissionFile>() {
        Ok(m) => {
            check_ranges(&m, root, path, roots, diags);
            Some(m)
        }
        Err(e) => {
            diags.push(de_diag(path, "", &e, root.loc));
            None
        }
    }
}

/// One known section against its type. `Err(None)`: the problems are in `diags` already (a
/// list or mapping whose items were checked one by one).
fn check_section(name: &str, v: &Node, path: &Path, diags: &mut Vec<Diagnostic>) -> Result<(), Option<DeError>> {
    let not_a = |what: &str| {
        Err(Some(DeError {
            message: format!("expected {what}, found {}", v.value.kind()),
            loc: Some(v.loc),
            path: vec![],
        }))
    };
    match name {
        "team" => {
            let Some(items) = v.as_seq() else { return not_a("a list of robots") };
            let mut ok = true;
            for (i, item) in items.iter().enumerate() {
                if let Err(e) = item.deserialize::<RobotSpec>() {
                    diags.push(de_diag(path, &format!("team[{i}]"), &e, item.loc));
                    ok = false;
                }
            }
            if ok { Ok(()) } else { Err(None) }
        }
        "roles" => {
            let Some(roles) = v.as_map() else { return not_a("a mapping of role names to roles") };
            let mut ok = true;
            for (rk, rv) in roles {
                if let Err(e) = rv.deserialize::<super::schema::RoleSpec>() {
                    diags.push(de_diag(path, &format!("roles.{}", rk.name), &e, rv.loc));
                    ok = false;
                }
            }
            if ok { Ok(()) } else { Err(None) }
        }
        "mission" | "description" => v.deserialize::<Option<String>>().map(|_| ()).map_err(Some),
        "include" => v.deserialize::<Vec<String>>().map(|_| ()).map_err(Some),
        "goals" => v.deserialize::<Option<super::schema::GoalsSpec>>().map(|_| ()).map_err(Some),
        "subtrees" => v.deserialize::<BTreeMap<String, super::schema::TreeNode>>().map(|_| ()).map_err(Some),
        "complete_when" => v.deserialize::<super::schema::CompleteWhen>().map(|_| ()).map_err(Some),
        "time_limit_s" => v.deserialize::<f64>().map(|_| ()).map_err(Some),
        "comms" => v.deserialize::<super::schema::CommsSpec>().map(|_| ()).map_err(Some),
        "sim" => v.deserialize::<Option<super::schema::SimSpec>>().map(|_| ()).map_err(Some),
        "classes" => v.deserialize::<BTreeMap<String, String>>().map(|_| ()).map_err(Some),
        _ => Ok(()),
    }
}

/// Stage parse, for the included files, and the subtrees of every file: the subtrees a tree
/// may refer to, by name.
pub fn include_stage(
    root: &Node,
    path: &Path,
    roots: &[PathBuf],
    out: &mut LoadedMission,
    diags: &mut Vec<Diagnostic>,
) -> BTreeMap<String, SubtreeDef> {
    let file: FileId = 0;
    let mut subtrees: BTreeMap<String, SubtreeDef> = BTreeMap::new();
    collect_subtrees(root, file, &mut subtrees, &out.files, diags);
    let mut stack = vec![canonical(path)];
    if let Some(inc) = root.get("include") {
        load_includes(inc, path, roots, out, &mut stack, &mut subtrees, diags);
    }
    subtrees
}

/// Stage wiring: every role's tree compiled (node types, ports, references, state machines)
/// and its blackboard typed by the ports it feeds; then the subtrees no role uses, and the
/// limits on the literal durations and files of the trees.
pub fn wiring_stage(
    root: &Node,
    path: &Path,
    registry: &NodeCatalog,
    subtrees: &BTreeMap<String, SubtreeDef>,
    roots: &[PathBuf],
    out: &mut LoadedMission,
    diags: &mut Vec<Diagnostic>,
) {
    let files = out.files.clone();
    let mut used_subtrees_ok = true;
    if let Some(roles) = root.get("roles").and_then(Node::as_map) {
        for (rk, rv) in roles {
            let Some(tree) = rv.get("tree") else {
                continue; // reported by the schema stage
            };
            let mut compiler = Compiler::new(registry, subtrees, &files);
            let ir = compiler.compile(tree, 0, &rk.name);
            let mut d = compiler.into_diagnostics();
            used_subtrees_ok &= d.is_empty();
            let Some(ir) = ir else {
                diags.append(&mut d);
                continue;
            };
            let role = compile_role(&rk.name, rv, ir, path, &files, &mut d);
            diags.append(&mut d);
            out.roles.insert(rk.name.clone(), role);
        }
    }
    // Subtrees no role uses still get checked on their own (when the roles compiled cleanly,
    // so a broken subtree is not reported twice).
    if used_subtrees_ok {
        for (name, def) in subtrees {
            let mut compiler = Compiler::new(registry, subtrees, &files);
            let _ = compiler.compile(&def.node, def.file, name);
            diags.append(&mut compiler.into_diagnostics());
        }
    }
    // Limits on literal durations and files in the trees.
    for role in out.roles.values() {
        limits::check_tree_literals(&role.tree, &out.files, roots, diags);
    }
}

/// A role whose tree compiled: its entries typed by the ports they feed, its initial values
/// and the entries it keeps across reboots checked against them.
fn compile_role(
    name: &str,
    rv: &Node,
    ir: Ir,
    path: &Path,
    files: &[PathBuf],
    d: &mut Vec<Diagnostic>,
) -> CompiledRole {
    let file: FileId = 0;
    let mut initial: BTreeMap<String, (Option<PortType>, Loc, FileId)> = BTreeMap::new();
    for (entry, ty) in PROVIDED_ENTRIES {
        initial.insert((*entry).to_string(), (Some(*ty), Loc::default(), file));
    }
    let bb_node = rv.get("blackboard");
    for (bk, _) in bb_node.and_then(Node::as_map).unwrap_or(&[]) {
        initial.insert(bk.name.clone(), (None, bk.loc, file));
    }
    let entry_types = check_wiring(&ir, &initial, files, d);
    // Type the role's initial values by the ports they feed.
    let mut values = Vec::new();
    for (bk, bv) in bb_node.and_then(Node::as_map).unwrap_or(&[]) {
        let bpath = format!("roles.{name}.blackboard.{}", bk.name);
        match entry_types.get(&bk.name) {
            None => d.push(Diagnostic::new(
                path,
                bk.loc,
                bpath,
                Stage::Wiring,
                format!("blackboard entry `{}` is never used by the tree", bk.name),
            )),
            Some(ty) => match BbValue::from_json(*ty, &bv.to_json()) {
                Ok(v) => values.push((bk.name.clone(), v)),
                Err(e) => d.push(Diagnostic::new(
                    path,
                    bv.loc,
                    bpath,
                    Stage::Wiring,
                    format!("entry `{}` feeds {ty} ports: {e}", bk.name),
                )),
            },
        }
    }
    let mut persist = Vec::new();
    if let Some(list) = rv.get("persist").and_then(Node::as_seq) {
        for (k, item) in list.iter().enumerate() {
            let Some(entry) = item.as_str() else { continue };
            if values.iter().any(|(n, _)| n == entry) {
                persist.push(entry.to_string());
            } else {
                d.push(Diagnostic::new(
                    path,
                    item.loc,
                    format!("roles.{name}.persist[{k}]"),
                    Stage::Wiring,
                    format!(
                        "`{entry}` is kept across reboots, so it needs an initial value in the role's `blackboard`"
                    ),
                ));
            }
        }
    }
    let tick_hz = rv.get("tick_hz").and_then(Node::as_f64).unwrap_or(super::schema::DEFAULT_TICK_HZ);
    CompiledRole { tree: ir, entry_types, initial: values, persist, tick_hz }
}

/// Stage team: robots against their roles (kinds, skills, priorities, ids), then the robot
/// layer's checks of robot settings and skill parameters, with the skills' rules.
pub fn team_stage(
    mission: &MissionFile,
    root: &Node,
    path: &Path,
    registry: &NodeCatalog,
    roles: &BTreeMap<String, CompiledRole>,
    diags: &mut Vec<Diagnostic>,
) {
    check_team(mission, root, path, registry, roles, diags);
    if let Some(checks) = registry.robot_checks() {
        for p in checks.check(mission) {
            let segs: Vec<&str> = p.path.iter().map(String::as_str).collect();
            diags.push(Diagnostic::new(path, loc_at(root, &segs), p.path.join("."), Stage::Schema, p.message));
        }
        let role_nodes: BTreeMap<String, std::collections::BTreeSet<String>> = roles
            .iter()
            .map(|(name, role)| {
                let mut types = std::collections::BTreeSet::new();
                node_types(&role.tree, &mut types);
                (name.clone(), types)
            })
            .collect();
        for p in checks.warnings(mission, &role_nodes) {
            let segs: Vec<&str> = p.path.iter().map(String::as_str).collect();
            let d = Diagnostic::new(path, loc_at(root, &segs), p.path.join("."), Stage::Schema, p.message);
            diags.push(d.into_warning());
        }
    }
}

/// Every node type in a compiled tree (subtrees are expanded in it).
fn node_types(ir: &super::compile::Ir, out: &mut std::collections::BTreeSet<String>) {
    use super::compile::IrKind;
    out.insert(ir.type_name.clone());
    match &ir.kind {
        IrKind::Control { children, .. } => children.iter().for_each(|c| node_types(c, out)),
        IrKind::Decorator { child, .. } => node_types(child, out),
        IrKind::StateMachine { states, .. } => {
            states.iter().filter_map(|s| s.run.as_ref()).for_each(|r| node_types(r, out))
        }
        IrKind::Leaf { .. } => {}
    }
}

/// Stage build, for a mission every other stage passed: each role's tree built with the
/// node factories, which check what only they can (e.g. a plan file that must parse).
pub fn build_stage<E: 'static>(nodes: &NodeRegistry<E>, path: &Path, out: &LoadedMission, diags: &mut Vec<Diagnostic>) {
    let base = path.parent().map(Path::to_path_buf).unwrap_or_default();
    for role in out.roles.values() {
        let opts = super::BuildOptions { base_dir: Some(base.clone()), ..super::BuildOptions::default() };
        let mut bb = crate::blackboard::Blackboard::new();
        if let Err(super::BuildError::Node { path: node_path, error }) =
            super::build_tree(&role.tree, nodes, &mut bb, opts)
        {
            let node = find_ir(&role.tree, &node_path).unwrap_or(&role.tree);
            let file = out.files.get(node.file).cloned().unwrap_or_else(|| path.to_path_buf());
            diags.push(Diagnostic::new(&file, node.loc, node_path, Stage::Wiring, error.to_string()));
        }
    }
}

/// The node of a compiled tree with this path.
fn find_ir<'a>(ir: &'a Ir, node_path: &str) -> Option<&'a Ir> {
    if ir.path == node_path {
        return Some(ir);
    }
    match &ir.kind {
        IrKind::Leaf { .. } => None,
        IrKind::Control { children, .. } => children.iter().find_map(|c| find_ir(c, node_path)),
        IrKind::Decorator { child, .. } => find_ir(child, node_path),
        IrKind::StateMachine { states, .. } => {
            states.iter().filter_map(|s| s.run.as_ref()).find_map(|r| find_ir(r, node_path))
        }
    }
}

fn canonical(p: &Path) -> PathBuf {
    std::fs::canonicalize(p).unwrap_or_else(|_| p.to_path_buf())
}

fn collect_subtrees(
    root: &Node,
    file: FileId,
    into: &mut BTreeMap<String, SubtreeDef>,
    files: &[PathBuf],
    diags: &mut Vec<Diagnostic>,
) {
    let Some(entries) = root.get("subtrees").and_then(Node::as_map) else { return };
    for (k, v) in entries {
        if let Some(prev) = into.get(&k.name) {
            let where_ = files.get(prev.file).map(|f| f.display().to_string()).unwrap_or_default();
            diags.push(Diagnostic::new(
                files.get(file).cloned().unwrap_or_default(),
                k.loc,
                format!("subtrees.{}", k.name),
                Stage::Wiring,
                format!("subtree `{}` is defined twice (also in {where_})", k.name),
            ));
            continue;
        }
        into.insert(k.name.clone(), SubtreeDef { node: v.clone(), file });
    }
}

fn load_includes(
    list: &Node,
    including: &Path,
    roots: &[PathBuf],
    out: &mut LoadedMission,
    stack: &mut Vec<PathBuf>,
    subtrees: &mut BTreeMap<String, SubtreeDef>,
    diags: &mut Vec<Diagnostic>,
) {
    let Some(items) = list.as_seq() else { return };
    let base = including.parent().map(Path::to_path_buf).unwrap_or_default();
    for item in items {
        let Some(rel) = item.as_str() else { continue };
        let target = match limits::resolve_inside(roots, &base, rel) {
            Ok(t) => t,
            Err(e) => {
                diags.push(Diagnostic::new(including, item.loc, "include", Stage::Parse, e.to_string()));
                continue;
            }
        };
        let canon = canonical(&target);
        if stack.contains(&canon) {
            let chain: Vec<String> = stack
                .iter()
                .chain(std::iter::once(&canon))
                .map(|p| p.file_name().map(|f| f.to_string_lossy().into_owned()).unwrap_or_default())
                .collect();
            diags.push(Diagnostic::new(
                including,
                item.loc,
                "include",
                Stage::Parse,
                format!("include cycle: {}", chain.join(" → ")),
            ));
            continue;
        }
        if out.files.iter().any(|f| canonical(f) == canon) {
            continue; // already included through another path
        }
        let text = match limits::read_text(&target, limits::MAX_SOURCE_BYTES) {
            Ok(t) => t,
            Err(e) => {
                diags.push(Diagnostic::new(
                    including,
                    item.loc,
                    "include",
                    Stage::Parse,
                    format!("cannot read included file: {e}"),
                ));
                continue;
            }
        };
        let file = out.files.len();
        out.files.push(target.clone());
        out.sources.push(text.clone());
        let node = match parse(&text) {
            Ok(n) => n,
            Err(e) => {
                diags.push(Diagnostic::new(&target, e.loc, "", Stage::Parse, e.message));
                continue;
            }
        };
        if node.as_map().is_none() {
            // Say what was expected without quoting the file: it may not be a mission file at all.
            let found = node.value.kind();
            let message = format!("an included file is a mapping with `subtrees:` (and `include:`); found {found}");
            diags.push(Diagnostic::new(&target, node.loc, "", Stage::Schema, message));
            continue;
        }
        if let Err(e) = node.deserialize::<IncludeFile>() {
            diags.push(de_diag(&target, "", &e, node.loc));
            continue;
        }
        collect_subtrees(&node, file, subtrees, &out.files, diags);
        if let Some(inc) = node.get("include") {
            stack.push(canon);
            load_includes(inc, &target, roots, out, stack, subtrees, diags);
            stack.pop();
        }
    }
}

/// Location of a nested field, falling back to the closest known parent.
fn loc_at(root: &Node, path: &[&str]) -> Loc {
    let mut node = root;
    let mut loc = root.loc;
    for seg in path {
        let next = match seg.parse::<usize>() {
            Ok(i) => node.as_seq().and_then(|s| s.get(i)),
            Err(_) => node.get(seg),
        };
        match next {
            Some(n) => {
                node = n;
                loc = n.loc;
            }
            None => break,
        }
    }
    loc
}

fn check_ranges(m: &MissionFile, root: &Node, file: &Path, roots: &[PathBuf], diags: &mut Vec<Diagnostic>) {
    let mut bad = |path: &[&str], msg: String| {
        diags.push(Diagnostic::new(file, loc_at(root, path), path.join("."), Stage::Schema, msg));
    };
    if let Err(e) = limits::check_time_limit(m.time_limit_s) {
        bad(&["time_limit_s"], e);
    }
    if let Err(e) = limits::check_identifier("the mission name", &m.mission) {
        bad(&["mission"], e);
    }
    if m.comms.position_range_m < 0.0 {
        bad(
            &["comms", "position_range_m"],
            format!("expected a non-negative distance in metres, found {}", m.comms.position_range_m),
        );
    }
    if m.comms.data_range_m < 0.0 {
        bad(
            &["comms", "data_range_m"],
            format!("expected a non-negative distance in metres, found {}", m.comms.data_range_m),
        );
    }
    if m.comms.data_range_m > m.comms.position_range_m {
        bad(
            &["comms", "data_range_m"],
            format!(
                "the data range ({} m) cannot exceed the position range ({} m)",
                m.comms.data_range_m, m.comms.position_range_m
            ),
        );
    }
    if m.comms.bandwidth_bytes_per_s <= 0.0 {
        bad(
            &["comms", "bandwidth_bytes_per_s"],
            format!("expected a positive rate, found {}", m.comms.bandwidth_bytes_per_s),
        );
    }
    if let Some(g) = &m.goals {
        if g.time_limit_per_m_s <= 0.0 {
            bad(
                &["goals", "time_limit_per_m_s"],
                format!("expected a positive number of seconds per metre, found {}", g.time_limit_per_m_s),
            );
        }
        if let Some(d) = &g.detect {
            let classes = ClassTable::default_table();
            if classes.by_name(&d.class).is_none() {
                bad(
                    &["goals", "detect", "class"],
                    format!("unknown class `{}`; classes are: {}", d.class, classes.names().join(", ")),
                );
            }
        }
        if g.detect.is_none() && g.manual.is_empty() {
            bad(&["goals"], "no goal source: give `detect:` or `manual:` goals (or leave `goals` out)".into());
        }
    }
    for (name, role) in &m.roles {
        if !(role.tick_hz > 0.0 && role.tick_hz <= 1000.0) {
            bad(
                &["roles", name, "tick_hz"],
                format!("expected a tick rate in (0, 1000] per second, found {}", role.tick_hz),
            );
        }
    }
    for (i, r) in m.team.iter().enumerate() {
        let idx = i.to_string();
        if let Some(l) = &r.localization
            && (l.prior_sigma_m < 0.0 || l.prior_sigma_deg < 0.0 || l.noise_m < 0.0)
        {
            bad(&["team", &idx, "localization"], "uncertainties and noise cannot be negative".into());
        }
        if let Some(ros) = &r.ros2 {
            check_ros2(ros, &idx, &mut bad);
        }
        if let Some(link) = &r.team_link {
            for (field, list) in [("listen", &link.listen), ("connect", &link.connect)] {
                for (k, e) in list.iter().enumerate() {
                    if let Err(why) = check_endpoint(e) {
                        bad(&["team", &idx, "team_link", field, &k.to_string()], why);
                    }
                }
            }
        }
    }
    if let Some(sim) = &m.sim {
        if let Some(super::schema::WorldSpec::Dir(dir)) = &sim.world
            && let Err(e) = limits::resolve_inside(roots, &roots[0], dir)
        {
            bad(&["sim", "world"], format!("the world folder {e}"));
        }
        if let Some(super::schema::WorldSpec::Generate(g)) = &sim.world
            && g.size_m.iter().any(|s| !(*s >= 50.0 && *s <= 5000.0))
        {
            bad(
                &["sim", "world", "generate", "size_m"],
                format!("each side must be between 50 and 5000 m, found {:?}", g.size_m),
            );
        }
        if sim.trials == Some(0) {
            bad(&["sim", "trials"], "expected at least one trial".into());
        }
        for (i, f) in sim.faults.iter().enumerate() {
            let idx = i.to_string();
            use super::schema::FaultSpec;
            let negative = match f {
                FaultSpec::Kill { at_s, .. } => limits::duration_from_secs(*at_s).is_err(),
                FaultSpec::Blackout { from_s, to_s, region } => {
                    limits::duration_from_secs(*from_s).is_err()
                        || limits::duration_from_secs(*to_s).is_err()
                        || to_s < from_s
                        || region.as_ref().is_some_and(|c| c.radius_m.is_nan() || c.radius_m < 0.0)
                }
                FaultSpec::OdometryNoise { scale } | FaultSpec::LocalizationNoise { scale } => {
                    !(scale.is_finite() && (0.0..=100.0).contains(scale))
                }
            };
            if negative {
                bad(
                    &["sim", "faults", &idx],
                    "times must be between 0 and 1e9 s and in order, radii non-negative, scales between 0 and 100"
                        .into(),
                );
            }
            if let FaultSpec::Kill { robot, .. } = f
                && !m.team.iter().any(|r| &r.id == robot)
            {
                bad(&["sim", "faults", &idx, "kill", "robot"], format!("no robot `{robot}` in the team"));
            }
        }
    }
}

fn leaf_types(ir: &Ir, out: &mut Vec<(String, String, Loc, FileId)>) {
    match &ir.kind {
        IrKind::Leaf { .. } => out.push((ir.type_name.clone(), ir.path.clone(), ir.loc, ir.file)),
        IrKind::Control { children, .. } => children.iter().for_each(|c| leaf_types(c, out)),
        IrKind::Decorator { child, .. } => leaf_types(child, out),
        IrKind::StateMachine { states, .. } => {
            states.iter().filter_map(|s| s.run.as_ref()).for_each(|r| leaf_types(r, out))
        }
    }
}

fn check_team(
    m: &MissionFile,
    root: &Node,
    file: &Path,
    registry: &NodeCatalog,
    roles: &BTreeMap<String, CompiledRole>,
    diags: &mut Vec<Diagnostic>,
) {
    let mut team_diag = |path: Vec<String>, msg: String| {
        let segs: Vec<&str> = path.iter().map(String::as_str).collect();
        let shown = path
            .iter()
            .enumerate()
            .map(|(i, s)| {
                if i > 0 && s.parse::<usize>().is_ok() {
                    format!("[{s}]")
                } else if i > 0 {
                    format!(".{s}")
                } else {
                    s.clone()
                }
            })
            .collect::<String>();
        diags.push(Diagnostic::new(file, loc_at(root, &segs), shown, Stage::Team, msg));
    };
    if m.team.is_empty() {
        team_diag(vec!["team".into()], "the team has no robots".into());
    }
    if m.team.len() > limits::MAX_ROBOTS {
        team_diag(
            vec!["team".into()],
            format!("the team has {} robots; at most {} are allowed", m.team.len(), limits::MAX_ROBOTS),
        );
    }
    let mut ids: HashMap<&str, usize> = HashMap::new();
    let mut priorities: HashMap<u32, &str> = HashMap::new();
    for (i, r) in m.team.iter().enumerate() {
        let idx = i.to_string();
        if let Err(e) = limits::check_identifier("a robot id", &r.id) {
            team_diag(vec!["team".into(), idx.clone(), "id".into()], e);
        } else if limits::RESERVED_ROBOT_IDS.contains(&r.id.as_str()) {
            team_diag(
                vec!["team".into(), idx.clone(), "id".into()],
                format!(
                    "robot id `{}` is reserved: the goals listed in the mission file are written under that name, \
                     so this robot's goals would share their ids; pick another id",
                    r.id
                ),
            );
        }
        if let Some(first) = ids.insert(&r.id, i) {
            team_diag(
                vec!["team".into(), idx.clone(), "id".into()],
                format!("robot id `{}` is used twice (also team[{first}])", r.id),
            );
        }
        if !m.roles.contains_key(&r.role) {
            let names: Vec<&str> = m.roles.keys().map(String::as_str).collect();
            team_diag(
                vec!["team".into(), idx.clone(), "role".into()],
                format!("role `{}` is not defined; roles are: {}", r.role, names.join(", ")),
            );
        }
        match (r.kind, r.priority) {
            (RobotKind::Ugv, None) => team_diag(
                vec!["team".into(), idx.clone()],
                format!("UGV `{}` needs a `priority` (lower number = higher priority)", r.id),
            ),
            (RobotKind::Ugv, Some(p)) => {
                if let Some(other) = priorities.insert(p, &r.id) {
                    team_diag(
                        vec!["team".into(), idx.clone(), "priority".into()],
                        format!("priority {p} is used by `{other}` and `{}`; UGV priorities must be unique", r.id),
                    );
                }
            }
            (_, Some(_)) => team_diag(
                vec!["team".into(), idx.clone(), "priority".into()],
                format!("`priority` orders UGVs only; `{}` is a {}", r.id, r.kind),
            ),
            (_, None) => {}
        }
        if r.localization.is_some() && r.kind != RobotKind::Ugv {
            team_diag(
                vec!["team".into(), idx.clone(), "localization".into()],
                format!("`localization` applies to UGVs; `{}` is a {} (it has GPS or is fixed)", r.id, r.kind),
            );
        }
        // Every node of the robot's role must suit its kind and find its skills.
        if let Some(role) = roles.get(&r.role) {
            let mut leaves = Vec::new();
            leaf_types(&role.tree, &mut leaves);
            let mut reported = HashSet::new();
            for (ty, npath, _, _) in leaves {
                let Some(spec) = registry.get(&ty) else { continue };
                if !spec.robot_kinds.is_empty() && !spec.robot_kinds.contains(&r.kind) && reported.insert(ty.clone()) {
                    let kinds: Vec<&str> = spec.robot_kinds.iter().map(|k| k.as_str()).collect();
                    team_diag(
                        vec!["team".into(), idx.clone(), "role".into()],
                        format!(
                            "`{}` ({}) runs role `{}`, whose node `{ty}` at {npath} runs on {} only",
                            r.id,
                            r.kind,
                            r.role,
                            kinds.join(", ")
                        ),
                    );
                }
                for skill in &spec.skills {
                    if !skills_of(r.kind).contains(skill) && reported.insert(format!("{ty}:{skill}")) {
                        team_diag(
                            vec!["team".into(), idx.clone(), "role".into()],
                            format!("node `{ty}` needs the `{skill}` skill, which a {} does not carry", r.kind),
                        );
                    }
                }
            }
        }
    }
    for name in m.roles.keys() {
        if !m.team.iter().any(|r| &r.role == name) {
            diags.push(Diagnostic::new(
                file,
                root.get("roles").and_then(|r| r.key(name)).map_or(root.loc, |k| k.loc),
                format!("roles.{name}"),
                Stage::Team,
                format!("role `{name}` is assigned to no robot"),
            ));
        }
    }
}

/// Checks a team-link endpoint: `tcp/HOST:PORT` with a port in 1..=65535.
pub fn check_endpoint(e: &str) -> Result<(), String> {
    let expected = || format!("expected an endpoint `tcp/HOST:PORT`, found `{e}`");
    let rest = e.strip_prefix("tcp/").ok_or_else(expected)?;
    let (host, port) = rest.rsplit_once(':').ok_or_else(expected)?;
    match port.parse::<u16>() {
        Ok(p) if p > 0 && !host.is_empty() => Ok(()),
        _ => Err(expected()),
    }
}

/// Topic roles a robot's `ros2.topics` may rename (the ROS 2 adapter's inputs and outputs).
pub const ROS2_TOPIC_ROLES: &[&str] = &[
    "odom",
    "panorama/depth",
    "panorama/semantic",
    "gps",
    "pose_in",
    "camera/tiles",
    "cmd_vel",
    "setpoint",
    "setpoint_speed",
    "pose_estimate",
    "path",
    "goals",
    "reachability",
    "diagnostics",
    "estop",
    "team/in",
    "team/out",
    "tf",
    "tf_static",
];

fn check_ros2(ros: &super::schema::Ros2Spec, idx: &str, bad: &mut impl FnMut(&[&str], String)) {
    for (field, v) in [("odometry_timeout_s", ros.odometry_timeout_s), ("panorama_timeout_s", ros.panorama_timeout_s)] {
        if !(v.is_finite() && v > 0.0 && v <= 3600.0) {
            bad(&["team", idx, "ros2", field], format!("expected a time in (0, 3600] seconds, found {v}"));
        }
    }
    if !(ros.panorama_v_fov_deg.is_finite() && ros.panorama_v_fov_deg > 0.0 && ros.panorama_v_fov_deg <= 180.0) {
        bad(
            &["team", idx, "ros2", "panorama_v_fov_deg"],
            format!("expected (0, 180] degrees, found {}", ros.panorama_v_fov_deg),
        );
    }
    if !(ros.sensor_height_m.is_finite() && (0.0..=100.0).contains(&ros.sensor_height_m)) {
        bad(&["team", idx, "ros2", "sensor_height_m"], format!("expected 0..100 m, found {}", ros.sensor_height_m));
    }
    if let Some(scale) = ros.depth_scale_m
        && !(scale.is_finite() && scale > 0.0 && scale <= 1.0)
    {
        bad(&["team", idx, "ros2", "depth_scale_m"], format!("expected metres per count in (0, 1], found {scale}"));
    }
    if ros.depth_scale_m.is_some() && ros.depth_encoding.default_scale_m().is_none() {
        bad(
            &["team", idx, "ros2", "depth_scale_m"],
            format!(
                "a scale applies to integer depth images; depth_encoding is {} (metres): set depth_encoding: 16UC1 or mono16, or remove depth_scale_m",
                ros.depth_encoding.name()
            ),
        );
    }
    if let Some(o) = &ros.gps_origin {
        if !(o.latitude_deg.is_finite() && o.latitude_deg.abs() <= 90.0) {
            bad(
                &["team", idx, "ros2", "gps_origin", "latitude_deg"],
                format!("expected -90..90 degrees, found {}", o.latitude_deg),
            );
        }
        if !(o.longitude_deg.is_finite() && o.longitude_deg.abs() <= 180.0) {
            bad(
                &["team", idx, "ros2", "gps_origin", "longitude_deg"],
                format!("expected -180..180 degrees, found {}", o.longitude_deg),
            );
        }
        if !o.altitude_m.is_finite() {
            bad(
                &["team", idx, "ros2", "gps_origin", "altitude_m"],
                format!("expected a finite height, found {}", o.altitude_m),
            );
        }
    }
    for (i, addr) in ros.interfaces.iter().enumerate() {
        if addr.parse::<std::net::IpAddr>().is_err() {
            bad(
                &["team", idx, "ros2", "interfaces", &i.to_string()],
                format!("expected an IP address, found `{addr}`"),
            );
        }
    }
    for (role, name) in &ros.topics {
        if !ROS2_TOPIC_ROLES.contains(&role.as_str()) {
            bad(
                &["team", idx, "ros2", "topics", role],
                format!("unknown topic role `{role}`; roles are: {}", ROS2_TOPIC_ROLES.join(", ")),
            );
        } else if !valid_ros_name(name) {
            bad(
                &["team", idx, "ros2", "topics", role],
                format!(
                    "`{name}` is not a ROS 2 topic name (letters, digits, `_` and `/` separators, not starting with a digit)"
                ),
            );
        }
    }
    if let Some(ns) = &ros.namespace
        && !(ns.is_empty() || ns == "/" || valid_ros_name(ns))
    {
        bad(&["team", idx, "ros2", "namespace"], format!("`{ns}` is not a ROS 2 namespace"));
    }
    if let Some(prefix) = &ros.frame_prefix
        && !(prefix.is_empty() || valid_frame_id(prefix.strip_suffix('/').unwrap_or(prefix)))
    {
        bad(
            &["team", idx, "ros2", "frame_prefix"],
            format!("`{prefix}` is not a frame prefix (frame-id tokens, no leading `/`; empty for none)"),
        );
    }
    let mut seen: Vec<(&str, &str)> = Vec::new();
    for (field, id) in ros.frames.given() {
        if !valid_frame_id(id) {
            bad(
                &["team", idx, "ros2", "frames", field],
                format!("`{id}` is not a frame id (tf2: letters, digits, `_`, `/` separators, no leading `/`)"),
            );
        } else if let Some((other, _)) = seen.iter().find(|(_, o)| *o == id) {
            bad(
                &["team", idx, "ros2", "frames", field],
                format!("`{id}` is also `frames.{other}`: each frame of the tf tree needs its own id"),
            );
        }
        seen.push((field, id));
    }
}

/// A tf2 frame id: a ROS name without the leading `/` (tf2 refuses one).
pub fn valid_frame_id(id: &str) -> bool {
    !id.starts_with('/') && valid_ros_name(id)
}

/// A ROS 2 topic or namespace name: `/`-separated tokens of letters, digits and `_`, no token
/// starting with a digit, no empty token but an optional leading `/`.
pub fn valid_ros_name(name: &str) -> bool {
    let body = name.strip_prefix('/').unwrap_or(name);
    !body.is_empty()
        && body.split('/').all(|t| {
            !t.is_empty()
                && !t.starts_with(|c: char| c.is_ascii_digit())
                && t.chars().all(|c| c.is_ascii_alphanumeric() || c == '_')
                && !t.contains("__")
        })
}
