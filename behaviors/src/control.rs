//! Control nodes: sequence, fallback, their reactive forms, and parallel.
//!
//! Semantics (the usual ones, spelled out because engines differ):
//! - `sequence` remembers which child is running and resumes there; `fallback` likewise.
//! - `reactive_sequence` / `reactive_fallback` re-tick from the first child every tick; when an
//!   earlier child changes the outcome, a later child that was running is halted.
//! - `parallel` ticks every unfinished child each tick and finishes as soon as the success or
//!   failure threshold is reached (or can no longer be), halting the others.
//! - When a control node finishes, it resets its children so it can run again.

use crate::node::{Behavior, Slot, TickContext, halt_all, reset_all};
use crate::status::Status;

/// The control node types.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ControlType {
    /// `sequence`.
    Sequence,
    /// `fallback`.
    Fallback,
    /// `reactive_sequence`.
    ReactiveSequence,
    /// `reactive_fallback`.
    ReactiveFallback,
    /// `parallel`.
    Parallel,
}

impl ControlType {
    /// By mission name.
    pub fn from_name(name: &str) -> Option<Self> {
        Some(match name {
            "sequence" => ControlType::Sequence,
            "fallback" => ControlType::Fallback,
            "reactive_sequence" => ControlType::ReactiveSequence,
            "reactive_fallback" => ControlType::ReactiveFallback,
            "parallel" => ControlType::Parallel,
            _ => return None,
        })
    }
}

/// `sequence` and `fallback`: tick children in order, resuming at the running one. The node
/// finishes with `decisive` as soon as a child reports it (Failure for a sequence, Success for a
/// fallback), and with the opposite outcome when every child reported the opposite.
pub struct Ordered<E = ()> {
    children: Vec<Slot<E>>,
    decisive: Status,
    current: usize,
}

impl<E: 'static> Ordered<E> {
    /// A sequence: fails on the first failure, succeeds when all succeed.
    pub fn sequence(children: Vec<Slot<E>>) -> Self {
        Ordered { children, decisive: Status::Failure, current: 0 }
    }

    /// A fallback: succeeds on the first success, fails when all fail.
    pub fn fallback(children: Vec<Slot<E>>) -> Self {
        Ordered { children, decisive: Status::Success, current: 0 }
    }

    fn finish(&mut self, outcome: Status, ctx: &mut TickContext<'_, E>) -> Status {
        reset_all(&mut self.children, ctx);
        self.current = 0;
        outcome
    }
}

/// The outcome opposite to a decisive one.
fn opposite(s: Status) -> Status {
    if s == Status::Success { Status::Failure } else { Status::Success }
}

impl<E: 'static> Behavior<E> for Ordered<E> {
    fn tick(&mut self, prev: Status, ctx: &mut TickContext<'_, E>) -> Status {
        if prev != Status::Running {
            self.current = 0;
        }
        while self.current < self.children.len() {
            match self.children[self.current].tick(ctx) {
                Status::Running => return Status::Running,
                s if s == self.decisive => return self.finish(s, ctx),
                _ => self.current += 1,
            }
        }
        self.finish(opposite(self.decisive), ctx)
    }
    fn halt(&mut self, ctx: &mut TickContext<'_, E>) {
        halt_all(&mut self.children, ctx);
        self.current = 0;
    }
    fn reset(&mut self) {
        self.current = 0;
    }
    fn children(&self) -> &[Slot<E>] {
        &self.children
    }
}

/// `reactive_sequence` and `reactive_fallback`: like [`Ordered`], but every tick restarts from
/// the first child, so conditions before a running child are re-checked; a later child that was
/// running is halted as soon as an earlier one runs or decides the outcome.
pub struct Reactive<E = ()> {
    children: Vec<Slot<E>>,
    decisive: Status,
}

impl<E: 'static> Reactive<E> {
    /// A reactive sequence.
    pub fn sequence(children: Vec<Slot<E>>) -> Self {
        Reactive { children, decisive: Status::Failure }
    }

    /// A reactive fallback.
    pub fn fallback(children: Vec<Slot<E>>) -> Self {
        Reactive { children, decisive: Status::Success }
    }
}

impl<E: 'static> Behavior<E> for Reactive<E> {
    fn tick(&mut self, _prev: Status, ctx: &mut TickContext<'_, E>) -> Status {
        for i in 0..self.children.len() {
            match self.children[i].tick(ctx) {
                Status::Running => {
                    halt_all(&mut self.children[i + 1..], ctx);
                    return Status::Running;
                }
                s if s == self.decisive => {
                    halt_all(&mut self.children[i + 1..], ctx);
                    reset_all(&mut self.children, ctx);
                    return s;
                }
                _ => {}
            }
        }
        reset_all(&mut self.children, ctx);
        opposite(self.decisive)
    }
    fn halt(&mut self, ctx: &mut TickContext<'_, E>) {
        halt_all(&mut self.children, ctx);
    }
    fn children(&self) -> &[Slot<E>] {
        &self.children
    }
}

/// Ticks all children concurrently; succeeds once `success_threshold` children succeeded,
/// fails once `failure_threshold` failed or success became impossible.
pub struct Parallel<E = ()> {
    children: Vec<Slot<E>>,
    success_threshold: usize,
    failure_threshold: usize,
}

impl<E: 'static> Parallel<E> {
    /// A parallel node; thresholds are clamped to 1..=children (checked by the loader).
    pub fn new(children: Vec<Slot<E>>, success_threshold: usize, failure_threshold: usize) -> Self {
        let n = children.len().max(1);
        Parallel {
            success_threshold: success_threshold.clamp(1, n),
            failure_threshold: failure_threshold.clamp(1, n),
            children,
        }
    }
}

impl<E: 'static> Behavior<E> for Parallel<E> {
    fn tick(&mut self, _prev: Status, ctx: &mut TickContext<'_, E>) -> Status {
        let (mut ok, mut failed) = (0, 0);
        for c in &mut self.children {
            let s = if c.status().is_done() { c.status() } else { c.tick(ctx) };
            match s {
                Status::Success => ok += 1,
                Status::Failure => failed += 1,
                _ => {}
            }
        }
        let n = self.children.len();
        let result = if ok >= self.success_threshold {
            Status::Success
        } else if failed >= self.failure_threshold || n - failed < self.success_threshold {
            Status::Failure
        } else {
            return Status::Running;
        };
        halt_all(&mut self.children, ctx);
        result
    }
    fn halt(&mut self, ctx: &mut TickContext<'_, E>) {
        halt_all(&mut self.children, ctx);
    }
    fn children(&self) -> &[Slot<E>] {
        &self.children
    }
}
