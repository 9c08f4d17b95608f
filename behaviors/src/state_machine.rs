//! The state-machine node: named states, each running a subtree, with transitions on the
//! subtree's outcome, on timers (time since entering the state) and on blackboard events.
//!
//! Per tick, in order: a terminal state ends the machine with its outcome; otherwise the
//! current state's timer and event transitions are checked first (a firing transition halts the
//! running subtree); then the subtree is ticked, and its outcome is matched against the
//! `on: success` / `on: failure` transitions. An outcome no transition handles ends the machine
//! with that outcome.

use std::time::Duration;

use spomp_core::Time;

use crate::node::{Behavior, Slot, TickContext};
use crate::status::Status;

/// What triggers a transition.
#[derive(Clone, Debug, PartialEq)]
pub enum Trigger {
    /// The state's subtree succeeded.
    Success,
    /// The state's subtree failed.
    Failure,
    /// This long after entering the state.
    Timer(Duration),
    /// A blackboard event was raised.
    Event(String),
}

/// A built transition.
#[derive(Clone, Debug)]
pub struct Transition {
    /// Trigger.
    pub trigger: Trigger,
    /// Index of the target state.
    pub target: usize,
}

/// A built state.
pub struct State {
    /// Name from the mission.
    pub name: String,
    /// Index into the machine's children of the subtree run while in the state, if any (a
    /// state without one waits for a timer or event).
    pub run: Option<usize>,
    /// Outgoing transitions, in mission order.
    pub transitions: Vec<Transition>,
    /// Entering this state ends the machine with this outcome.
    pub terminal: Option<Status>,
}

/// The state-machine behaviour.
pub struct StateMachine<E = ()> {
    states: Vec<State>,
    initial: usize,
    current: usize,
    entered_at: Time,
    children: Vec<Slot<E>>,
}

impl<E: 'static> StateMachine<E> {
    /// A state machine starting in `initial`; states refer to `children` by index.
    pub fn new(states: Vec<State>, children: Vec<Slot<E>>, initial: usize) -> Self {
        StateMachine { states, initial, current: initial, entered_at: Time::ZERO, children }
    }

    fn run_slot(&mut self, state: usize) -> Option<&mut Slot<E>> {
        let i = self.states.get(state)?.run?;
        self.children.get_mut(i)
    }

    /// Name of the current state.
    pub fn current_state(&self) -> &str {
        self.states.get(self.current).map_or("", |s| s.name.as_str())
    }

    fn enter(&mut self, target: usize, ctx: &mut TickContext<'_, E>) {
        if let Some(run) = self.run_slot(self.current) {
            run.halt(ctx);
        }
        self.current = target;
        self.entered_at = ctx.now;
        if let Some(run) = self.run_slot(target) {
            run.reset(ctx);
        }
    }

    /// A timer or event transition of the current state that fires now.
    fn fired(&self, ctx: &mut TickContext<'_, E>) -> Option<usize> {
        let state = self.states.get(self.current)?;
        let elapsed = ctx.now.since(self.entered_at);
        for t in &state.transitions {
            match &t.trigger {
                Trigger::Timer(d) if elapsed >= *d => return Some(t.target),
                Trigger::Event(name) if ctx.blackboard.take_event(name) => return Some(t.target),
                _ => {}
            }
        }
        None
    }
}

impl<E: 'static> Behavior<E> for StateMachine<E> {
    fn tick(&mut self, prev: Status, ctx: &mut TickContext<'_, E>) -> Status {
        if prev != Status::Running {
            self.current = self.initial;
            self.entered_at = ctx.now;
        }
        // Bounded: at most one hop per state per tick, so a cycle of instant states cannot spin.
        for _ in 0..=self.states.len() {
            let Some(state) = self.states.get(self.current) else { return Status::Failure };
            if let Some(outcome) = state.terminal {
                return outcome;
            }
            if let Some(target) = self.fired(ctx) {
                self.enter(target, ctx);
                continue;
            }
            let current = self.current;
            let Some(run) = self.run_slot(current) else { return Status::Running };
            let outcome = run.tick(ctx);
            if !outcome.is_settled() {
                return Status::Running;
            }
            run.reset(ctx);
            // A skipped subtree did what it had to (nothing): its state's success.
            let outcome = if outcome == Status::Skipped { Status::Success } else { outcome };
            let wanted = if outcome == Status::Success { Trigger::Success } else { Trigger::Failure };
            let target = self.states[current].transitions.iter().find(|t| t.trigger == wanted).map(|t| t.target);
            match target {
                Some(target) => {
                    self.enter(target, ctx);
                    // A plain state entered on an outcome starts on the next tick; a terminal
                    // one reports at once (next loop iteration).
                    if self.states.get(target).is_some_and(|s| s.terminal.is_none()) {
                        return Status::Running;
                    }
                }
                None => return outcome,
            }
        }
        Status::Running
    }

    fn halt(&mut self, ctx: &mut TickContext<'_, E>) {
        if let Some(run) = self.run_slot(self.current) {
            run.halt(ctx);
        }
        self.current = self.initial;
    }

    fn reset(&mut self) {
        self.current = self.initial;
    }

    fn children(&self) -> &[Slot<E>] {
        &self.children
    }
}
