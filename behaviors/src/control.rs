//! Control nodes: sequence (with and without memory), fallback, their reactive forms, parallel,
//! and the two conditional nodes `if_then_else` and `while_do_else`.
//!
//! Semantics (the usual ones, spelled out because engines differ; `behaviors/README.md` has
//! them side by side with BehaviorTree.CPP 4.x):
//! - `sequence` remembers which child is running and resumes there; `fallback` likewise. When
//!   they finish (or are halted) they start again from the first child.
//! - `sequence_with_memory` also resumes at the child that failed: its next run starts there,
//!   and neither a halt nor a parent's reset returns it to the first child; only finishing with
//!   success does.
//! - `reactive_sequence` / `reactive_fallback` re-tick from the first child every tick; when an
//!   earlier child changes the outcome, a later child that was running is halted.
//! - `parallel` ticks its unfinished children in order and checks its thresholds after each:
//!   once the result is decided it ticks no further child, halts the running ones and reports
//!   it; it fails as soon as the success threshold can no longer be reached.
//! - `if_then_else` ticks its condition (first child) once per run, then runs the chosen branch
//!   to its end without looking at the condition again.
//! - `while_do_else` re-ticks its condition every tick; when it changes, the branch that was
//!   running is halted before the other one is ticked, in the same tick.
//! - A child reporting [`Status::Skipped`] is passed over as if it were not there; a node whose
//!   children were all skipped reports `Skipped`.
//! - When a control node finishes, it resets its children so it can run again.

use crate::node::{Behavior, Slot, TickContext, halt_all, reset_all};
use crate::status::Status;

/// The control node types.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ControlType {
    /// `sequence`.
    Sequence,
    /// `sequence_with_memory`.
    SequenceWithMemory,
    /// `fallback`.
    Fallback,
    /// `reactive_sequence`.
    ReactiveSequence,
    /// `reactive_fallback`.
    ReactiveFallback,
    /// `parallel`.
    Parallel,
    /// `if_then_else`.
    IfThenElse,
    /// `while_do_else`.
    WhileDoElse,
}

impl ControlType {
    /// By mission name.
    pub fn from_name(name: &str) -> Option<Self> {
        Some(match name {
            "sequence" => ControlType::Sequence,
            "sequence_with_memory" => ControlType::SequenceWithMemory,
            "fallback" => ControlType::Fallback,
            "reactive_sequence" => ControlType::ReactiveSequence,
            "reactive_fallback" => ControlType::ReactiveFallback,
            "parallel" => ControlType::Parallel,
            "if_then_else" => ControlType::IfThenElse,
            "while_do_else" => ControlType::WhileDoElse,
            _ => return None,
        })
    }

    /// The mission name.
    pub fn name(self) -> &'static str {
        match self {
            ControlType::Sequence => "sequence",
            ControlType::SequenceWithMemory => "sequence_with_memory",
            ControlType::Fallback => "fallback",
            ControlType::ReactiveSequence => "reactive_sequence",
            ControlType::ReactiveFallback => "reactive_fallback",
            ControlType::Parallel => "parallel",
            ControlType::IfThenElse => "if_then_else",
            ControlType::WhileDoElse => "while_do_else",
        }
    }

    /// How many children the node takes, at least and at most.
    pub fn child_count(self) -> (usize, usize) {
        match self {
            ControlType::IfThenElse | ControlType::WhileDoElse => (2, 3),
            _ => (1, usize::MAX),
        }
    }
}

/// `sequence`, `sequence_with_memory` and `fallback`: tick children in order, resuming at the
/// running one. The node finishes with `decisive` as soon as a child reports it (Failure for a
/// sequence, Success for a fallback), and with the opposite outcome when every child reported
/// the opposite (or was skipped).
pub struct Ordered<E = ()> {
    children: Vec<Slot<E>>,
    decisive: Status,
    current: usize,
    skipped: usize,
    memory: bool,
}

impl<E: 'static> Ordered<E> {
    /// A sequence: fails on the first failure, succeeds when all succeed.
    pub fn sequence(children: Vec<Slot<E>>) -> Self {
        Ordered { children, decisive: Status::Failure, current: 0, skipped: 0, memory: false }
    }

    /// A sequence with memory: like [`Ordered::sequence`], but after a failure or a halt the
    /// next run resumes at the child that failed or was running, not at the first.
    pub fn sequence_with_memory(children: Vec<Slot<E>>) -> Self {
        Ordered { children, decisive: Status::Failure, current: 0, skipped: 0, memory: true }
    }

    /// A fallback: succeeds on the first success, fails when all fail.
    pub fn fallback(children: Vec<Slot<E>>) -> Self {
        Ordered { children, decisive: Status::Success, current: 0, skipped: 0, memory: false }
    }

    fn finish(&mut self, outcome: Status, ctx: &mut TickContext<'_, E>) -> Status {
        reset_all(&mut self.children, ctx);
        // A sequence with memory keeps the index of the child that failed.
        if !(self.memory && outcome == self.decisive) {
            self.current = 0;
        }
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
            self.skipped = 0;
            if !self.memory {
                self.current = 0;
            }
        }
        while self.current < self.children.len() {
            match self.children[self.current].tick(ctx) {
                Status::Running => return Status::Running,
                Status::Skipped => {
                    self.skipped += 1;
                    self.current += 1;
                }
                s if s == self.decisive => return self.finish(s, ctx),
                _ => self.current += 1,
            }
        }
        let all_skipped = self.skipped == self.children.len();
        self.finish(if all_skipped { Status::Skipped } else { opposite(self.decisive) }, ctx)
    }
    fn halt(&mut self, ctx: &mut TickContext<'_, E>) {
        halt_all(&mut self.children, ctx);
        if !self.memory {
            self.current = 0;
        }
    }
    fn reset(&mut self) {
        if !self.memory {
            self.current = 0;
        }
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

impl<E: 'static> Reactive<E> {
    /// Ends a tick at child `at`, which reported `status` (Running or decisive): the later
    /// children stop; a decided node also resets its children for the next run. Out of line,
    /// and so is [`Reactive::all_passed`], so that the hot loop in `tick` holds only what it
    /// needs in registers (measured: one register shuffle more per child tick otherwise).
    #[inline(never)]
    fn stop_at(&mut self, at: usize, status: Status, ctx: &mut TickContext<'_, E>) -> Status {
        if let Some(later) = self.children.get_mut(at + 1..) {
            halt_all(later, ctx);
        }
        if status != Status::Running {
            reset_all(&mut self.children, ctx);
        }
        status
    }

    /// Ends a tick in which no child ran or decided: every child reported the outcome opposite
    /// to the decisive one or was skipped (all skipped: the node is skipped).
    #[cold]
    #[inline(never)]
    fn all_passed(&mut self, ctx: &mut TickContext<'_, E>) -> Status {
        let all_skipped = self.children.iter().all(|c| c.status() == Status::Skipped);
        reset_all(&mut self.children, ctx);
        if all_skipped { Status::Skipped } else { opposite(self.decisive) }
    }
}

impl<E: 'static> Behavior<E> for Reactive<E> {
    fn tick(&mut self, _prev: Status, ctx: &mut TickContext<'_, E>) -> Status {
        // The hot loop counts nothing and ends in an out-of-line call: whether every child was
        // skipped is asked only at the end, from their statuses (a skipped child is neither
        // running nor decisive).
        let decisive = self.decisive;
        for (i, child) in self.children.iter_mut().enumerate() {
            let status = child.tick(ctx);
            if status == Status::Running || status == decisive {
                return self.stop_at(i, status, ctx);
            }
        }
        self.all_passed(ctx)
    }
    fn halt(&mut self, ctx: &mut TickContext<'_, E>) {
        halt_all(&mut self.children, ctx);
    }
    fn children(&self) -> &[Slot<E>] {
        &self.children
    }
}

/// Thresholds a [`Parallel`] cannot meet with its children.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{name} must be between 1 and the number of children ({children}), found {value}")]
pub struct ThresholdError {
    /// `success_threshold` or `failure_threshold`.
    pub name: &'static str,
    /// The value given.
    pub value: i64,
    /// The number of children.
    pub children: usize,
}

impl ThresholdError {
    /// The one range rule of both thresholds, used by [`Parallel::new`] and by the mission
    /// loader: `value` as a count when it lies in 1..=`children`.
    pub fn check(name: &'static str, value: i64, children: usize) -> Result<usize, ThresholdError> {
        match usize::try_from(value) {
            Ok(count) if (1..=children).contains(&count) => Ok(count),
            _ => Err(ThresholdError { name, value, children }),
        }
    }
}

/// Ticks its unfinished children in order each tick; succeeds once `success_threshold`
/// children succeeded, fails once `failure_threshold` failed or success became impossible.
/// The thresholds are checked after each child: once the result is decided no further child is
/// ticked, and the running ones are halted. Skipped children count towards neither threshold
/// and lower the number of successes needed to at most the children that were not skipped.
pub struct Parallel<E = ()> {
    children: Vec<Slot<E>>,
    tally: Tally,
}

/// A parallel node's thresholds and what its children reported in the current run.
struct Tally {
    children: usize,
    success_threshold: usize,
    failure_threshold: usize,
    succeeded: usize,
    failed: usize,
    skipped: usize,
}

impl Tally {
    /// Counts a child that settled with `status` and tells whether that decided the node.
    /// Out of line: children settle rarely, while the loop in [`Parallel`]'s `tick` runs for
    /// every running child on every tick and keeps fewer values live without it (measured).
    #[inline(never)]
    fn count(&mut self, status: Status) -> Option<Status> {
        match status {
            Status::Success => self.succeeded += 1,
            Status::Failure => self.failed += 1,
            _ => self.skipped += 1,
        }
        let present = self.children - self.skipped;
        let needed = self.success_threshold.min(present);
        if present > 0 && self.succeeded >= needed {
            Some(Status::Success)
        } else if self.failed >= self.failure_threshold || present - self.failed < needed {
            Some(Status::Failure)
        } else {
            None
        }
    }

    /// Forgets the run's counts.
    fn clear(&mut self) {
        (self.succeeded, self.failed, self.skipped) = (0, 0, 0);
    }
}

impl<E: 'static> Parallel<E> {
    /// A parallel node; each threshold must be between 1 and the number of children.
    pub fn new(
        children: Vec<Slot<E>>,
        success_threshold: usize,
        failure_threshold: usize,
    ) -> Result<Self, ThresholdError> {
        let n = children.len();
        for (name, value) in [("success_threshold", success_threshold), ("failure_threshold", failure_threshold)] {
            ThresholdError::check(name, i64::try_from(value).unwrap_or(i64::MAX), n)?;
        }
        let tally = Tally { children: n, success_threshold, failure_threshold, succeeded: 0, failed: 0, skipped: 0 };
        Ok(Parallel { children, tally })
    }

    fn finish(&mut self, outcome: Status, ctx: &mut TickContext<'_, E>) -> Status {
        reset_all(&mut self.children, ctx);
        self.tally.clear();
        outcome
    }
}

impl<E: 'static> Behavior<E> for Parallel<E> {
    fn tick(&mut self, prev: Status, ctx: &mut TickContext<'_, E>) -> Status {
        if prev != Status::Running {
            self.tally.clear();
        }
        let mut decided = None;
        for child in &mut self.children {
            if child.status().is_settled() {
                continue;
            }
            let status = child.tick(ctx);
            if status.is_settled() {
                decided = self.tally.count(status);
                if decided.is_some() {
                    break;
                }
            }
        }
        match decided {
            Some(outcome) => self.finish(outcome, ctx),
            None if self.tally.skipped == self.children.len() => self.finish(Status::Skipped, ctx),
            None => Status::Running,
        }
    }
    fn halt(&mut self, ctx: &mut TickContext<'_, E>) {
        reset_all(&mut self.children, ctx);
        self.tally.clear();
    }
    fn reset(&mut self) {
        self.tally.clear();
    }
    fn children(&self) -> &[Slot<E>] {
        &self.children
    }
}

/// `if_then_else`: ticks the condition (first child) until it finishes, then runs the second
/// child on success or the third on failure (fails if there is none) to its end. The condition
/// is not looked at again during that run.
pub struct IfThenElse<E = ()> {
    children: Vec<Slot<E>>,
    /// The chosen branch, 0 while the condition has not decided.
    branch: usize,
}

impl<E: 'static> IfThenElse<E> {
    /// An if-then-else over a condition, a then-branch and an optional else-branch (2 or 3
    /// children; the loader checks the count).
    pub fn new(children: Vec<Slot<E>>) -> Self {
        IfThenElse { children, branch: 0 }
    }

    fn finish(&mut self, outcome: Status, ctx: &mut TickContext<'_, E>) -> Status {
        reset_all(&mut self.children, ctx);
        self.branch = 0;
        outcome
    }
}

impl<E: 'static> Behavior<E> for IfThenElse<E> {
    fn tick(&mut self, prev: Status, ctx: &mut TickContext<'_, E>) -> Status {
        if prev != Status::Running {
            self.branch = 0;
        }
        if self.branch == 0 {
            let Some(condition) = self.children.first_mut() else { return Status::Failure };
            match condition.tick(ctx) {
                Status::Success => self.branch = 1,
                Status::Failure if self.children.len() > 2 => self.branch = 2,
                Status::Failure => return self.finish(Status::Failure, ctx),
                Status::Skipped => return self.finish(Status::Skipped, ctx),
                Status::Running | Status::Idle => return Status::Running,
            }
        }
        let Some(branch) = self.children.get_mut(self.branch) else { return self.finish(Status::Failure, ctx) };
        match branch.tick(ctx) {
            Status::Running | Status::Idle => Status::Running,
            outcome => self.finish(outcome, ctx),
        }
    }
    fn halt(&mut self, ctx: &mut TickContext<'_, E>) {
        halt_all(&mut self.children, ctx);
        self.branch = 0;
    }
    fn reset(&mut self) {
        self.branch = 0;
    }
    fn children(&self) -> &[Slot<E>] {
        &self.children
    }
}

/// `while_do_else`: ticks the condition (first child) every tick; while it succeeds the second
/// child runs, while it fails the third (or the node fails if there is none). When the
/// condition changes, the branch that was running is halted before the other is ticked, in
/// the same tick; while the condition itself runs, both branches are halted.
pub struct WhileDoElse<E = ()> {
    children: Vec<Slot<E>>,
}

impl<E: 'static> WhileDoElse<E> {
    /// A while-do-else over a condition, a do-branch and an optional else-branch (2 or 3
    /// children; the loader checks the count).
    pub fn new(children: Vec<Slot<E>>) -> Self {
        WhileDoElse { children }
    }
}

impl<E: 'static> Behavior<E> for WhileDoElse<E> {
    fn tick(&mut self, _prev: Status, ctx: &mut TickContext<'_, E>) -> Status {
        let Some((condition, branches)) = self.children.split_first_mut() else { return Status::Failure };
        let (run, other) = match condition.tick(ctx) {
            Status::Success => (0, 1),
            Status::Failure if branches.len() > 1 => (1, 0),
            Status::Failure => {
                reset_all(&mut self.children, ctx);
                return Status::Failure;
            }
            Status::Skipped => {
                reset_all(&mut self.children, ctx);
                return Status::Skipped;
            }
            Status::Running | Status::Idle => {
                halt_all(branches, ctx);
                return Status::Running;
            }
        };
        if let Some(o) = branches.get_mut(other) {
            o.halt(ctx);
        }
        let Some(branch) = branches.get_mut(run) else { return Status::Failure };
        match branch.tick(ctx) {
            Status::Running | Status::Idle => Status::Running,
            outcome => {
                reset_all(&mut self.children, ctx);
                outcome
            }
        }
    }
    fn halt(&mut self, ctx: &mut TickContext<'_, E>) {
        halt_all(&mut self.children, ctx);
    }
    fn children(&self) -> &[Slot<E>] {
        &self.children
    }
}
