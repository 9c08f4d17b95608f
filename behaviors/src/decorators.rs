//! Decorators: one child, one twist.

use std::time::Duration;

use spomp_core::Time;

use crate::node::{Behavior, Slot, TickContext};
use crate::status::Status;

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

/// `inverter`, `force_success`, `force_failure`: Running passes through.
pub struct MapResult {
    child: Vec<Slot>,
    map: ResultMap,
}

impl MapResult {
    /// A result-mapping decorator.
    pub fn new(child: Slot, map: ResultMap) -> Self {
        MapResult { child: vec![child], map }
    }
}

fn one(child: &mut [Slot]) -> &mut Slot {
    // Decorators are built with exactly one child (the loader checks it).
    &mut child[0]
}

/// Ticks the child and, when it finished, resets it so the next run starts fresh.
fn tick_once(child: &mut [Slot], ctx: &mut TickContext<'_>) -> Status {
    let c = one(child);
    let s = c.tick(ctx);
    if s.is_done() {
        c.reset(ctx);
    }
    s
}

impl Behavior for MapResult {
    fn tick(&mut self, _prev: Status, ctx: &mut TickContext<'_>) -> Status {
        let s = tick_once(&mut self.child, ctx);
        match (self.map, s) {
            (_, Status::Running | Status::Idle) => s,
            (ResultMap::Invert, Status::Success) => Status::Failure,
            (ResultMap::Invert, _) => Status::Success,
            (ResultMap::ForceSuccess, _) => Status::Success,
            (ResultMap::ForceFailure, _) => Status::Failure,
        }
    }
    fn halt(&mut self, ctx: &mut TickContext<'_>) {
        one(&mut self.child).halt(ctx);
    }
    fn children(&self) -> &[Slot] {
        &self.child
    }
}

/// Fails (halting the child) if the child has not finished within the duration.
pub struct Timeout {
    child: Vec<Slot>,
    duration: Duration,
    deadline: Time,
}

impl Timeout {
    /// A timeout.
    pub fn new(child: Slot, duration: Duration) -> Self {
        Timeout { child: vec![child], duration, deadline: Time::ZERO }
    }
}

impl Behavior for Timeout {
    fn tick(&mut self, prev: Status, ctx: &mut TickContext<'_>) -> Status {
        if prev != Status::Running {
            self.deadline = ctx.now + self.duration;
        }
        if ctx.now >= self.deadline {
            one(&mut self.child).halt(ctx);
            return Status::Failure;
        }
        tick_once(&mut self.child, ctx)
    }
    fn halt(&mut self, ctx: &mut TickContext<'_>) {
        one(&mut self.child).halt(ctx);
    }
    fn children(&self) -> &[Slot] {
        &self.child
    }
}

/// Re-runs a failing child, up to `max_attempts` attempts in all.
pub struct Retry {
    child: Vec<Slot>,
    max_attempts: u32,
    attempts: u32,
}

impl Retry {
    /// A retry decorator.
    pub fn new(child: Slot, max_attempts: u32) -> Self {
        Retry { child: vec![child], max_attempts: max_attempts.max(1), attempts: 0 }
    }
}

impl Behavior for Retry {
    fn tick(&mut self, prev: Status, ctx: &mut TickContext<'_>) -> Status {
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
                Status::Success => {
                    c.reset(ctx);
                    self.attempts = 0;
                    return Status::Success;
                }
                other => return other,
            }
        }
    }
    fn halt(&mut self, ctx: &mut TickContext<'_>) {
        one(&mut self.child).halt(ctx);
        self.attempts = 0;
    }
    fn children(&self) -> &[Slot] {
        &self.child
    }
}

/// Re-runs a succeeding child `times` times (or forever); fails as soon as the child fails.
/// Each repetition starts on a new tick, so an instant child cannot spin a tick forever.
pub struct Repeat {
    child: Vec<Slot>,
    times: Option<u32>,
    done: u32,
}

impl Repeat {
    /// A repeat decorator; `None` repeats forever.
    pub fn new(child: Slot, times: Option<u32>) -> Self {
        Repeat { child: vec![child], times, done: 0 }
    }
}

impl Behavior for Repeat {
    fn tick(&mut self, prev: Status, ctx: &mut TickContext<'_>) -> Status {
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
            Status::Failure => {
                c.reset(ctx);
                self.done = 0;
                Status::Failure
            }
            other => other,
        }
    }
    fn halt(&mut self, ctx: &mut TickContext<'_>) {
        one(&mut self.child).halt(ctx);
        self.done = 0;
    }
    fn children(&self) -> &[Slot] {
        &self.child
    }
}

/// Runs the child to completion once; afterwards returns that outcome without ticking it.
pub struct RunOnce {
    child: Vec<Slot>,
    outcome: Option<Status>,
}

impl RunOnce {
    /// A run-once decorator.
    pub fn new(child: Slot) -> Self {
        RunOnce { child: vec![child], outcome: None }
    }
}

impl Behavior for RunOnce {
    fn tick(&mut self, _prev: Status, ctx: &mut TickContext<'_>) -> Status {
        if let Some(s) = self.outcome {
            return s;
        }
        let s = tick_once(&mut self.child, ctx);
        if s.is_done() {
            self.outcome = Some(s);
        }
        s
    }
    fn halt(&mut self, ctx: &mut TickContext<'_>) {
        one(&mut self.child).halt(ctx);
    }
    fn children(&self) -> &[Slot] {
        &self.child
    }
}

/// Waits for the delay, then runs the child.
pub struct Delay {
    child: Vec<Slot>,
    delay: Duration,
    start_at: Time,
}

impl Delay {
    /// A delay decorator.
    pub fn new(child: Slot, delay: Duration) -> Self {
        Delay { child: vec![child], delay, start_at: Time::ZERO }
    }
}

impl Behavior for Delay {
    fn tick(&mut self, prev: Status, ctx: &mut TickContext<'_>) -> Status {
        if prev != Status::Running {
            self.start_at = ctx.now + self.delay;
        }
        if ctx.now < self.start_at {
            return Status::Running;
        }
        tick_once(&mut self.child, ctx)
    }
    fn halt(&mut self, ctx: &mut TickContext<'_>) {
        one(&mut self.child).halt(ctx);
    }
    fn children(&self) -> &[Slot] {
        &self.child
    }
}

/// Ticks the child at most once per period; in between it reports Running (the child keeps
/// its state). Use it to throttle expensive checks inside a faster tree.
pub struct RateLimit {
    child: Vec<Slot>,
    period: Duration,
    next_at: Option<Time>,
}

impl RateLimit {
    /// A rate limiter at `hz` ticks per second.
    pub fn new(child: Slot, hz: f64) -> Self {
        let period = Duration::from_secs_f64(1.0 / hz.max(1e-6));
        RateLimit { child: vec![child], period, next_at: None }
    }
}

impl Behavior for RateLimit {
    fn tick(&mut self, _prev: Status, ctx: &mut TickContext<'_>) -> Status {
        if let Some(t) = self.next_at
            && ctx.now < t
        {
            return Status::Running;
        }
        self.next_at = Some(ctx.now + self.period);
        tick_once(&mut self.child, ctx)
    }
    fn halt(&mut self, ctx: &mut TickContext<'_>) {
        one(&mut self.child).halt(ctx);
    }
    fn children(&self) -> &[Slot] {
        &self.child
    }
}
