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

/// Ticks children in order; fails on the first failure; succeeds when all succeed.
pub struct Sequence {
    children: Vec<Slot>,
    current: usize,
}

impl Sequence {
    /// A sequence.
    pub fn new(children: Vec<Slot>) -> Self {
        Sequence { children, current: 0 }
    }
}

impl Behavior for Sequence {
    fn tick(&mut self, prev: Status, ctx: &mut TickContext<'_>) -> Status {
        if prev != Status::Running {
            self.current = 0;
        }
        while self.current < self.children.len() {
            match self.children[self.current].tick(ctx) {
                Status::Running => return Status::Running,
                Status::Failure => {
                    reset_all(&mut self.children, ctx);
                    self.current = 0;
                    return Status::Failure;
                }
                Status::Success | Status::Idle => self.current += 1,
            }
        }
        reset_all(&mut self.children, ctx);
        self.current = 0;
        Status::Success
    }
    fn halt(&mut self, ctx: &mut TickContext<'_>) {
        halt_all(&mut self.children, ctx);
        self.current = 0;
    }
    fn reset(&mut self) {
        self.current = 0;
    }
    fn children(&self) -> &[Slot] {
        &self.children
    }
}

/// Ticks children in order; succeeds on the first success; fails when all fail.
pub struct Fallback {
    children: Vec<Slot>,
    current: usize,
}

impl Fallback {
    /// A fallback.
    pub fn new(children: Vec<Slot>) -> Self {
        Fallback { children, current: 0 }
    }
}

impl Behavior for Fallback {
    fn tick(&mut self, prev: Status, ctx: &mut TickContext<'_>) -> Status {
        if prev != Status::Running {
            self.current = 0;
        }
        while self.current < self.children.len() {
            match self.children[self.current].tick(ctx) {
                Status::Running => return Status::Running,
                Status::Success => {
                    reset_all(&mut self.children, ctx);
                    self.current = 0;
                    return Status::Success;
                }
                Status::Failure | Status::Idle => self.current += 1,
            }
        }
        reset_all(&mut self.children, ctx);
        self.current = 0;
        Status::Failure
    }
    fn halt(&mut self, ctx: &mut TickContext<'_>) {
        halt_all(&mut self.children, ctx);
        self.current = 0;
    }
    fn reset(&mut self) {
        self.current = 0;
    }
    fn children(&self) -> &[Slot] {
        &self.children
    }
}

/// A sequence that re-checks earlier children every tick (conditions guarding an action).
pub struct ReactiveSequence {
    children: Vec<Slot>,
}

impl ReactiveSequence {
    /// A reactive sequence.
    pub fn new(children: Vec<Slot>) -> Self {
        ReactiveSequence { children }
    }
}

impl Behavior for ReactiveSequence {
    fn tick(&mut self, _prev: Status, ctx: &mut TickContext<'_>) -> Status {
        for i in 0..self.children.len() {
            match self.children[i].tick(ctx) {
                Status::Running => {
                    // Anything after a running child must not keep running.
                    halt_all(&mut self.children[i + 1..], ctx);
                    return Status::Running;
                }
                Status::Failure => {
                    halt_all(&mut self.children[i + 1..], ctx);
                    reset_all(&mut self.children, ctx);
                    return Status::Failure;
                }
                Status::Success | Status::Idle => {}
            }
        }
        reset_all(&mut self.children, ctx);
        Status::Success
    }
    fn halt(&mut self, ctx: &mut TickContext<'_>) {
        halt_all(&mut self.children, ctx);
    }
    fn children(&self) -> &[Slot] {
        &self.children
    }
}

/// A fallback that re-tries earlier children every tick (preferred option first).
pub struct ReactiveFallback {
    children: Vec<Slot>,
}

impl ReactiveFallback {
    /// A reactive fallback.
    pub fn new(children: Vec<Slot>) -> Self {
        ReactiveFallback { children }
    }
}

impl Behavior for ReactiveFallback {
    fn tick(&mut self, _prev: Status, ctx: &mut TickContext<'_>) -> Status {
        for i in 0..self.children.len() {
            match self.children[i].tick(ctx) {
                Status::Running => {
                    halt_all(&mut self.children[i + 1..], ctx);
                    return Status::Running;
                }
                Status::Success => {
                    halt_all(&mut self.children[i + 1..], ctx);
                    reset_all(&mut self.children, ctx);
                    return Status::Success;
                }
                Status::Failure | Status::Idle => {}
            }
        }
        reset_all(&mut self.children, ctx);
        Status::Failure
    }
    fn halt(&mut self, ctx: &mut TickContext<'_>) {
        halt_all(&mut self.children, ctx);
    }
    fn children(&self) -> &[Slot] {
        &self.children
    }
}

/// Ticks all children concurrently; succeeds once `success_threshold` children succeeded,
/// fails once `failure_threshold` failed or success became impossible.
pub struct Parallel {
    children: Vec<Slot>,
    success_threshold: usize,
    failure_threshold: usize,
}

impl Parallel {
    /// A parallel node; thresholds are clamped to 1..=children (checked by the loader).
    pub fn new(children: Vec<Slot>, success_threshold: usize, failure_threshold: usize) -> Self {
        let n = children.len().max(1);
        Parallel {
            success_threshold: success_threshold.clamp(1, n),
            failure_threshold: failure_threshold.clamp(1, n),
            children,
        }
    }
}

impl Behavior for Parallel {
    fn tick(&mut self, _prev: Status, ctx: &mut TickContext<'_>) -> Status {
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
    fn halt(&mut self, ctx: &mut TickContext<'_>) {
        halt_all(&mut self.children, ctx);
    }
    fn children(&self) -> &[Slot] {
        &self.children
    }
}
