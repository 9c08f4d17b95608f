//! The node interface, the tick context and the slot that wraps every node in a tree.

use std::sync::Arc;

use spomp_core::Time;

use crate::blackboard::Blackboard;
use crate::status::Status;

/// What a node sees during a tick.
pub struct TickContext<'a, E = ()> {
    /// The robot's current time (simulated or wall), from its `Clock`.
    pub now: Time,
    /// Root ticks so far.
    pub tick: u64,
    /// The robot's blackboard.
    pub blackboard: &'a mut Blackboard,
    /// The environment the tree acts on, typed: for a robot's tree the robot runtime
    /// (`spomp-robot`), for engine tests anything (`()` by default).
    pub env: &'a mut E,
    /// Who hears about status transitions.
    pub observer: Option<&'a mut dyn TreeObserver>,
}

impl<E> TickContext<'_, E> {
    #[inline]
    fn notify(&mut self, node: &NodeInfo, from: Status, to: Status) {
        if let Some(obs) = self.observer.as_deref_mut() {
            obs.on_transition(&Transition { tick: self.tick, time: self.now, node, from, to });
        }
    }
}

/// A status change of one node.
#[derive(Debug)]
pub struct Transition<'a> {
    /// Root tick number.
    pub tick: u64,
    /// Robot time.
    pub time: Time,
    /// The node.
    pub node: &'a NodeInfo,
    /// Status before.
    pub from: Status,
    /// Status after.
    pub to: Status,
}

/// Receives every status transition of every node.
pub trait TreeObserver {
    /// Called once per transition, in tick order.
    fn on_transition(&mut self, t: &Transition<'_>);
}

/// Identity of a node in a tree.
#[derive(Debug, Clone)]
pub struct NodeInfo {
    /// Index in depth-first order.
    pub id: u32,
    /// Node type name (`sequence`, `claim_goal`, …).
    pub type_name: Arc<str>,
    /// Path from the root, e.g. `visitor/repeat/fallback[0]/claim_goal`.
    pub path: Arc<str>,
}

/// The behaviour of a node. Control nodes own their children's [`Slot`]s.
pub trait Behavior<E = ()>: Send {
    /// Runs one step. `prev` is the node's status before this tick: anything but `Running`
    /// means the node is (re)starting.
    fn tick(&mut self, prev: Status, ctx: &mut TickContext<'_, E>) -> Status;

    /// Called when the node is halted while `Running`: cancel work, stop motion, halt
    /// children. The slot has already checked that the node was running.
    fn halt(&mut self, _ctx: &mut TickContext<'_, E>) {}

    /// Resets any memory after the node finished (children reset by their parents).
    fn reset(&mut self) {}

    /// Children, for traversal (tree printing, counting).
    fn children(&self) -> &[Slot<E>] {
        &[]
    }
}

/// A node in a tree: its identity, its status and its behaviour.
pub struct Slot<E = ()> {
    info: NodeInfo,
    status: Status,
    behavior: Box<dyn Behavior<E>>,
}

impl<E> Slot<E> {
    /// Wraps a behaviour.
    pub fn new(info: NodeInfo, behavior: Box<dyn Behavior<E>>) -> Self {
        Slot { info, status: Status::Idle, behavior }
    }

    /// Identity.
    pub fn info(&self) -> &NodeInfo {
        &self.info
    }

    /// Current status.
    #[inline]
    pub fn status(&self) -> Status {
        self.status
    }

    /// The behaviour, for inspection.
    pub fn behavior(&self) -> &dyn Behavior<E> {
        &*self.behavior
    }

    /// Ticks the node and records the transition.
    #[inline]
    pub fn tick(&mut self, ctx: &mut TickContext<'_, E>) -> Status {
        let prev = self.status;
        let next = self.behavior.tick(prev, ctx);
        if next != prev {
            self.transition(prev, next, ctx);
        }
        next
    }

    /// Records a status change. Out of line: `tick` is inlined into every control node's loop,
    /// where a node that keeps its status (the common case: running, or a condition that holds)
    /// should cost a compare, not the observer call's setup (measured with callgrind).
    #[cold]
    #[inline(never)]
    fn transition(&mut self, prev: Status, next: Status, ctx: &mut TickContext<'_, E>) {
        self.status = next;
        ctx.notify(&self.info, prev, next);
    }

    /// Halts the node if it is running (recursively, through its behaviour) and sets it idle.
    pub fn halt(&mut self, ctx: &mut TickContext<'_, E>) {
        if self.status == Status::Running {
            self.behavior.halt(ctx);
        }
        self.set_idle(ctx);
    }

    /// Returns a finished node to idle so it can run again (no halt: it is not running).
    pub fn reset(&mut self, ctx: &mut TickContext<'_, E>) {
        if self.status == Status::Running {
            self.halt(ctx);
            return;
        }
        self.behavior.reset();
        self.set_idle(ctx);
    }

    fn set_idle(&mut self, ctx: &mut TickContext<'_, E>) {
        if self.status != Status::Idle {
            let prev = self.status;
            self.status = Status::Idle;
            ctx.notify(&self.info, prev, Status::Idle);
        }
    }

    /// Number of nodes in this subtree.
    pub fn count(&self) -> usize {
        1 + self.behavior.children().iter().map(Slot::<E>::count).sum::<usize>()
    }

    /// Visits the subtree depth-first with the depth of each node.
    pub fn visit(&self, depth: usize, f: &mut dyn FnMut(&Slot<E>, usize)) {
        f(self, depth);
        for c in self.behavior.children() {
            c.visit(depth + 1, f);
        }
    }
}

/// Halts every child of a control node.
pub fn halt_all<E>(children: &mut [Slot<E>], ctx: &mut TickContext<'_, E>) {
    for c in children {
        c.halt(ctx);
    }
}

/// Resets every child of a control node (halting any still running).
pub fn reset_all<E>(children: &mut [Slot<E>], ctx: &mut TickContext<'_, E>) {
    for c in children {
        c.reset(ctx);
    }
}
