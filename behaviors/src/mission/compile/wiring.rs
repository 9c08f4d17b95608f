//! Blackboard wiring: every entry written before it is read, one type per entry.

use std::collections::{HashSet, VecDeque};

#[allow(clippy::wildcard_imports)]
use super::*;
use crate::registry::Text;

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
    port: Text,
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
                        port: p.spec.name.clone(),
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
