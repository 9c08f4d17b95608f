//! Observers of node transitions.

use std::io::Write;

use spomp_core::Time;

use crate::node::{Slot, Transition, TreeObserver};
use crate::status::Status;

/// One recorded transition.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct TransitionRecord {
    /// Root tick.
    pub tick: u64,
    /// Robot time.
    pub time: Time,
    /// Node id (depth-first index).
    pub node_id: u32,
    /// Node path.
    pub path: String,
    /// Before.
    pub from: Status,
    /// After.
    pub to: Status,
}

/// Keeps every transition (for tests, logs and replay checks).
#[derive(Debug, Default)]
pub struct Recorder {
    /// Transitions in order.
    pub records: Vec<TransitionRecord>,
}

impl TreeObserver for Recorder {
    fn on_transition(&mut self, t: &Transition<'_>) {
        self.records.push(TransitionRecord {
            tick: t.tick,
            time: t.time,
            node_id: t.node.id,
            path: t.node.path.to_string(),
            from: t.from,
            to: t.to,
        });
    }
}

/// Prints each transition as a line (`--trace`).
pub struct LinePrinter<W: Write> {
    out: W,
    prefix: String,
}

impl<W: Write> LinePrinter<W> {
    /// A printer writing to `out`, each line starting with `prefix` (e.g. the robot id).
    pub fn new(out: W, prefix: impl Into<String>) -> Self {
        LinePrinter { out, prefix: prefix.into() }
    }
}

impl<W: Write> TreeObserver for LinePrinter<W> {
    fn on_transition(&mut self, t: &Transition<'_>) {
        // A closed pipe must not take the robot down; tracing is best effort.
        let _ = writeln!(
            self.out,
            "{} #{:<6} {:>9} {} {} -> {}",
            self.prefix,
            t.tick,
            t.time.to_string(),
            t.node.path,
            t.from,
            t.to
        );
    }
}

/// Renders a tree with each node's current status, one node per line, indented by depth
/// (the live view of `--trace`).
pub fn render_tree(root: &Slot) -> String {
    let mut s = String::new();
    root.visit(0, &mut |slot, depth| {
        let mark = match slot.status() {
            Status::Idle => "·",
            Status::Running => "▶",
            Status::Success => "✔",
            Status::Failure => "✘",
            Status::Skipped => "↷",
        };
        s.push_str(&format!("{}{} {} [{}]\n", "  ".repeat(depth), mark, slot.info().type_name, slot.status()));
    });
    s
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::blackboard::Blackboard;
    use crate::control::Ordered;
    use crate::node::{Behavior, NodeInfo, TickContext};

    struct Run;
    impl Behavior for Run {
        fn tick(&mut self, _prev: Status, _ctx: &mut TickContext<'_>) -> Status {
            Status::Running
        }
    }

    fn slot(name: &str, b: Box<dyn Behavior>) -> Slot {
        Slot::new(NodeInfo { id: 0, type_name: name.into(), path: name.into() }, b)
    }

    #[test]
    fn line_printer_and_tree_render_show_transitions() {
        let mut root = slot("sequence", Box::new(Ordered::sequence(vec![slot("wait", Box::new(Run))])));
        let mut out = Vec::new();
        {
            let mut printer = LinePrinter::new(&mut out, "ugv1");
            let mut bb = Blackboard::new();
            let mut ctx = TickContext {
                now: Time::from_millis(100),
                tick: 1,
                blackboard: &mut bb,
                env: &mut (),
                observer: Some(&mut printer),
            };
            root.tick(&mut ctx);
        }
        let text = String::from_utf8(out).unwrap();
        assert!(text.contains("ugv1 #1") && text.contains("wait idle -> running"), "{text}");
        assert_eq!(render_tree(&root), "▶ sequence [running]\n  ▶ wait [running]\n");
    }
}
