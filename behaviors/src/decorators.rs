//! Decorators: one child, one twist. A child that reports [`Status::Skipped`] is passed up as
//! `Skipped` (and reset) by every decorator; `run_once` with `then_skip` is the one that makes
//! a node skipped.

use std::time::Duration;

use spomp_core::Time;

use crate::node::{Behavior, Slot, TickContext};
use crate::status::Status;

/// The decorator types.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum DecoratorType {
    /// `timeout`.
    Timeout,
    /// `retry`.
    Retry,
    /// `repeat`.
    Repeat,
    /// `inverter`.
    Inverter,
    /// `force_success`.
    ForceSuccess,
    /// `force_failure`.
    ForceFailure,
    /// `run_once`.
    RunOnce,
    /// `keep_running_until_failure`.
    KeepRunningUntilFailure,
    /// `delay`.
    Delay,
    /// `rate_limit`.
    RateLimit,
}

impl DecoratorType {
    /// By mission name.
    pub fn from_name(name: &str) -> Option<Self> {
        Some(match name {
            "timeout" => DecoratorType::Timeout,
            "retry" => DecoratorType::Retry,
            "repeat" => DecoratorType::Repeat,
            "inverter" => DecoratorType::Inverter,
            "force_success" => DecoratorType::ForceSuccess,
            "force_failure" => DecoratorType::ForceFailure,
            "run_once" => DecoratorType::RunOnce,
            "keep_running_until_failure" => DecoratorType::KeepRunningUntilFailure,
            "delay" => DecoratorType::Delay,
            "rate_limit" => DecoratorType::RateLimit,
            _ => return None,
        })
    }

    /// The mission name.
    pub fn name(self) -> &'static str {
        match self {
            DecoratorType::Timeout => "timeout",
            DecoratorType::Retry => "retry",
            DecoratorType::Repeat => "repeat",
            DecoratorType::Inverter => "inverter",
            DecoratorType::ForceSuccess => "force_success",
            DecoratorType::ForceFailure => "force_failure",
            DecoratorType::RunOnce => "run_once",
            DecoratorType::KeepRunningUntilFailure => "keep_running_until_failure",
            DecoratorType::Delay => "delay",
            DecoratorType::RateLimit => "rate_limit",
        }
    }
}

/// What a result-mapping decorator does to its child's outcome.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ResultMap {
    /// Success ↔ Failure.
    Invert,
    /// Any outcome → Success.
    ForceSuccess,
    /// Any outcome → Failure.
    ForceFailure,
}

/// `inverter`, `force_success`, `force_failure`: Running and Skipped pass through.
pub struct MapResult<E = ()> {
    child: Vec<Slot<E>>,
    map: ResultMap,
}

impl<E: 'static> MapResult<E> {
    /// A result-mapping decorator.
    pub fn new(child: Slot<E>, map: ResultMap) -> Self {
        MapResult { child: vec![child], map }
    }
}

fn one<E>(child: &mut [Slot<E>]) -> &mut Slot<E> {
    // Decorators are built with exactly one child (the loader checks it).
    &mut child[0]
}

/// Ticks the child and, when it finished, resets it so the next run starts fresh.
fn tick_once<E: 'static>(child: &mut [Slot<E>], ctx: &mut TickContext<'_, E>) -> Status {
    let c = one(child);
    let s = c.tick(ctx);
    if s.is_settled() {
        c.reset(ctx);
    }
    s
}

impl<E: 'static> Behavior<E> for MapResult<E> {
    fn tick(&mut self, _prev: Status, ctx: &mut TickContext<'_, E>) -> Status {
        let s = tick_once(&mut self.child, ctx);
        match (self.map, s) {
            (_, Status::Running | Status::Idle | Status::Skipped) => s,
            (ResultMap::Invert, Status::Success) => Status::Failure,
            (ResultMap::Invert, _) => Status::Success,
            (ResultMap::ForceSuccess, _) => Status::Success,
            (ResultMap::ForceFailure, _) => Status::Failure,
        }
    }
    fn halt(&mut self, ctx: &mut TickContext<'_, E>) {
        one(&mut self.child).halt(ctx);
    }
    fn children(&self) -> &[Slot<E>] {
        &self.child
    }
}

/// Fails (halting the child) if the child has not finished within the duration.
pub struct Timeout<E = ()> {
    child: Vec<Slot<E>>,
    duration: Duration,
    deadline: Time,
}

impl<E: 'static> Timeout<E> {
    /// A timeout.
    pub fn new(child: Slot<E>, duration: Duration) -> Self {
        Timeout { child: vec![child], duration, deadline: Time::ZERO }
    }
}

impl<E: 'static> Behavior<E> for Timeout<E> {
    fn tick(&mut self, prev: Status, ctx: &mut TickContext<'_, E>) -> Status {
        if prev != Status::Running {
            self.deadline = ctx.now + self.duration;
        }
        if ctx.now >= self.deadline {
            one(&mut self.child).halt(ctx);
            return Status::Failure;
        }
        tick_once(&mut self.child, ctx)
    }
    fn halt(&mut self, ctx: &mut TickContext<'_, E>) {
        one(&mut self.child).halt(ctx);
    }
    fn children(&self) -> &[Slot<E>] {
        &self.child
    }
}

/// Re-runs a failing child, up to `max_attempts` attempts in all.
pub struct Retry<E = ()> {
    child: Vec<Slot<E>>,
    max_attempts: u32,
    attempts: u32,
}

impl<E: 'static> Retry<E> {
    /// A retry decorator.
    pub fn new(child: Slot<E>, max_attempts: u32) -> Self {
        Retry { child: vec![child], max_attempts: max_attempts.max(1), attempts: 0 }
    }
}

impl<E: 'static> Behavior<E> for Retry<E> {
    fn tick(&mut self, prev: Status, ctx: &mut TickContext<'_, E>) -> Status {
        if prev != Status::Running {
            self.attempts = 0;
        }
        let c = one(&mut self.child);
        // Retry at once within the tick: a quick failure should not cost a tick period.
        loop {
            let s = c.tick(ctx);
            match s {
                Status::Failure => {
                    self.attempts += 1;
                    c.reset(ctx);
                    if self.attempts >= self.max_attempts {
                        self.attempts = 0;
                        return Status::Failure;
                    }
                }
                Status::Success | Status::Skipped => {
                    c.reset(ctx);
                    self.attempts = 0;
                    return s;
                }
                other => return other,
            }
        }
    }
    fn halt(&mut self, ctx: &mut TickContext<'_, E>) {
        one(&mut self.child).halt(ctx);
        self.attempts = 0;
    }
    fn children(&self) -> &[Slot<E>] {
        &self.child
    }
}

/// Re-runs a succeeding child `times` times (or forever); fails as soon as the child fails.
/// Each repetition starts on a new tick, so an instant child cannot spin a tick forever.
pub struct Repeat<E = ()> {
    child: Vec<Slot<E>>,
    times: Option<u32>,
    done: u32,
}

impl<E: 'static> Repeat<E> {
    /// A repeat decorator; `None` repeats forever.
    pub fn new(child: Slot<E>, times: Option<u32>) -> Self {
        Repeat { child: vec![child], times, done: 0 }
    }
}

impl<E: 'static> Behavior<E> for Repeat<E> {
    fn tick(&mut self, prev: Status, ctx: &mut TickContext<'_, E>) -> Status {
        if prev != Status::Running {
            self.done = 0;
        }
        let c = one(&mut self.child);
        match c.tick(ctx) {
            Status::Success => {
                c.reset(ctx);
                self.done += 1;
                match self.times {
                    Some(n) if self.done >= n => {
                        self.done = 0;
                        Status::Success
                    }
                    _ => Status::Running,
                }
            }
            s @ (Status::Failure | Status::Skipped) => {
                c.reset(ctx);
                self.done = 0;
                s
            }
            other => other,
        }
    }
    fn halt(&mut self, ctx: &mut TickContext<'_, E>) {
        one(&mut self.child).halt(ctx);
        self.done = 0;
    }
    fn children(&self) -> &[Slot<E>] {
        &self.child
    }
}

/// Runs the child to completion once; afterwards returns that outcome without ticking it, or
/// with `then_skip` reports [`Status::Skipped`] (its parent carries on as if it were not
/// there). The memory lasts as long as the tree: neither a halt nor a parent's reset clears it.
pub struct RunOnce<E = ()> {
    child: Vec<Slot<E>>,
    outcome: Option<Status>,
    then_skip: bool,
}

impl<E: 'static> RunOnce<E> {
    /// A run-once decorator that repeats the first outcome.
    pub fn new(child: Slot<E>) -> Self {
        RunOnce { child: vec![child], outcome: None, then_skip: false }
    }

    /// A run-once decorator that is skipped after its first completion.
    pub fn then_skip(child: Slot<E>) -> Self {
        RunOnce { child: vec![child], outcome: None, then_skip: true }
    }
}

impl<E: 'static> Behavior<E> for RunOnce<E> {
    fn tick(&mut self, _prev: Status, ctx: &mut TickContext<'_, E>) -> Status {
        if let Some(s) = self.outcome {
            return if self.then_skip { Status::Skipped } else { s };
        }
        let s = tick_once(&mut self.child, ctx);
        if s.is_done() {
            self.outcome = Some(s);
        }
        s
    }
    fn halt(&mut self, ctx: &mut TickContext<'_, E>) {
        one(&mut self.child).halt(ctx);
    }
    fn children(&self) -> &[Slot<E>] {
        &self.child
    }
}

/// `keep_running_until_failure`: restarts a succeeding child on the next tick and reports
/// Running meanwhile; fails when the child fails. One run of the child per tick at most.
pub struct KeepRunningUntilFailure<E = ()> {
    child: Vec<Slot<E>>,
}

impl<E: 'static> KeepRunningUntilFailure<E> {
    /// The decorator.
    pub fn new(child: Slot<E>) -> Self {
        KeepRunningUntilFailure { child: vec![child] }
    }
}

impl<E: 'static> Behavior<E> for KeepRunningUntilFailure<E> {
    fn tick(&mut self, _prev: Status, ctx: &mut TickContext<'_, E>) -> Status {
        match tick_once(&mut self.child, ctx) {
            Status::Success => Status::Running,
            s => s,
        }
    }
    fn halt(&mut self, ctx: &mut TickContext<'_, E>) {
        one(&mut self.child).halt(ctx);
    }
    fn children(&self) -> &[Slot<E>] {
        &self.child
    }
}

/// Waits for the delay, then runs the child.
pub struct Delay<E = ()> {
    child: Vec<Slot<E>>,
    delay: Duration,
    start_at: Time,
}

impl<E: 'static> Delay<E> {
    /// A delay decorator.
    pub fn new(child: Slot<E>, delay: Duration) -> Self {
        Delay { child: vec![child], delay, start_at: Time::ZERO }
    }
}

impl<E: 'static> Behavior<E> for Delay<E> {
    fn tick(&mut self, prev: Status, ctx: &mut TickContext<'_, E>) -> Status {
        if prev != Status::Running {
            self.start_at = ctx.now + self.delay;
        }
        if ctx.now < self.start_at {
            return Status::Running;
        }
        tick_once(&mut self.child, ctx)
    }
    fn halt(&mut self, ctx: &mut TickContext<'_, E>) {
        one(&mut self.child).halt(ctx);
    }
    fn children(&self) -> &[Slot<E>] {
        &self.child
    }
}

/// Ticks the child at most once per period; in between it reports Running (the child keeps
/// its state). Use it to throttle expensive checks inside a faster tree.
pub struct RateLimit<E = ()> {
    child: Vec<Slot<E>>,
    period: Duration,
    next_at: Option<Time>,
}

impl<E: 'static> RateLimit<E> {
    /// A rate limiter at `hz` ticks per second.
    pub fn new(child: Slot<E>, hz: f64) -> Self {
        let period = Duration::from_secs_f64(1.0 / hz.max(1e-6));
        RateLimit { child: vec![child], period, next_at: None }
    }
}

impl<E: 'static> Behavior<E> for RateLimit<E> {
    fn tick(&mut self, _prev: Status, ctx: &mut TickContext<'_, E>) -> Status {
        if let Some(t) = self.next_at
            && ctx.now < t
        {
            return Status::Running;
        }
        self.next_at = Some(ctx.now + self.period);
        tick_once(&mut self.child, ctx)
    }
    fn halt(&mut self, ctx: &mut TickContext<'_, E>) {
        one(&mut self.child).halt(ctx);
    }
    fn children(&self) -> &[Slot<E>] {
        &self.child
    }
}
