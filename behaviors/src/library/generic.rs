//! Generic leaves: waiting, flags, string checks, events, mission time.

use std::sync::Arc;

use serde_json::json;
use spomp_core::Time;

use crate::blackboard::{BbValue, Binding, PortType};
use crate::node::{Behavior, TickContext};
use crate::registry::{Category, NodeRegistry, NodeTypeSpec, PortSpec};
use crate::status::Status;

/// Registers the generic leaves.
pub fn register_generic<E>(r: &mut NodeRegistry<E>) {
    use Category::{Action, Condition};
    use PortType::{Bool, Float, String as Str};
    r.register(NodeTypeSpec::leaf("succeed", Action, "Succeeds at once.", vec![], |_| {
        Ok(Box::new(Fixed(Status::Success)))
    }));
    r.register(NodeTypeSpec::leaf("fail", Action, "Fails at once.", vec![], |_| Ok(Box::new(Fixed(Status::Failure)))));
    r.register(NodeTypeSpec::leaf(
        "wait",
        Action,
        "Runs for `duration_s` of robot time, then succeeds.",
        vec![PortSpec::input("duration_s", Float, "How long, seconds.")],
        |p| Ok(Box::new(Wait { duration: p.get("duration_s")?, until: Time::ZERO })),
    ));
    r.register(NodeTypeSpec::leaf(
        "set_flag",
        Action,
        "Writes `value` to the boolean entry `flag`, then succeeds.",
        vec![
            PortSpec::output("flag", Bool, "Entry to write."),
            PortSpec::input("value", Bool, "Value to write.").with_default(json!(true)),
        ],
        |p| Ok(Box::new(SetFlag { flag: p.get("flag")?, value: p.get("value")? })),
    ));
    r.register(NodeTypeSpec::leaf(
        "check_flag",
        Condition,
        "Succeeds if the boolean `flag` is true; fails if false or never written.",
        vec![PortSpec::input("flag", Bool, "Entry to read.")],
        |p| Ok(Box::new(CheckFlag { flag: p.get("flag")? })),
    ));
    r.register(NodeTypeSpec::leaf(
        "check_string",
        Condition,
        "Succeeds if the string entry `value` equals `equals` (e.g. a driving node's `failure_reason` is `no_progress`); fails if it differs or was never written.",
        vec![
            PortSpec::input("value", Str, "Entry to read."),
            PortSpec::input("equals", Str, "The string it must equal."),
        ],
        |p| Ok(Box::new(CheckString { value: p.get("value")?, equals: p.get("equals")? })),
    ));
    r.register(NodeTypeSpec::leaf(
        "raise_event",
        Action,
        "Raises the named event (state-machine transitions `on: event` see it this tick and the next), then succeeds.",
        vec![PortSpec::input("event", Str, "Event name.")],
        |p| Ok(Box::new(RaiseEvent { event: p.get("event")? })),
    ));
    r.register(NodeTypeSpec::leaf(
        "wait_for_event",
        Action,
        "Runs until the named event is raised, then consumes it and succeeds.",
        vec![PortSpec::input("event", Str, "Event name.")],
        |p| Ok(Box::new(WaitForEvent { event: p.get("event")? })),
    ));
    r.register(NodeTypeSpec::leaf(
        "mission_time_at_least",
        Condition,
        "Succeeds once the robot's mission clock has reached `time_s` (e.g. to head home before the time limit).",
        vec![PortSpec::input("time_s", Float, "Mission time, seconds since start.")],
        |p| Ok(Box::new(TimeAtLeast { time: p.get("time_s")? })),
    ));
}

struct Fixed(Status);

impl<E> Behavior<E> for Fixed {
    fn tick(&mut self, _prev: Status, _ctx: &mut TickContext<'_, E>) -> Status {
        self.0
    }
}

struct Wait {
    duration: Binding,
    until: Time,
}

impl<E> Behavior<E> for Wait {
    fn tick(&mut self, prev: Status, ctx: &mut TickContext<'_, E>) -> Status {
        if prev != Status::Running {
            let secs = self.duration.get::<f64>(ctx.blackboard).unwrap_or(f64::NAN);
            let duration = match crate::duration::duration_from_secs(secs) {
                Ok(d) => d,
                Err(e) => {
                    ctx.blackboard.report(format!("wait: duration_s: {e}"));
                    return Status::Failure;
                }
            };
            self.until = ctx.now + duration;
        }
        if ctx.now >= self.until { Status::Success } else { Status::Running }
    }
}

struct SetFlag {
    flag: Binding,
    value: Binding,
}

impl<E> Behavior<E> for SetFlag {
    fn tick(&mut self, _prev: Status, ctx: &mut TickContext<'_, E>) -> Status {
        // `value` is always bound (its declared default when the mission leaves it out); an
        // entry never written is the mission's mistake, reported rather than read as `true`.
        let Some(v) = self.value.get::<bool>(ctx.blackboard) else {
            ctx.blackboard.report("set_flag: no value on its `value` port".to_string());
            return Status::Failure;
        };
        if self.flag.set(ctx.blackboard, BbValue::Bool(v)) { Status::Success } else { Status::Failure }
    }
}

struct CheckFlag {
    flag: Binding,
}

impl<E> Behavior<E> for CheckFlag {
    fn tick(&mut self, _prev: Status, ctx: &mut TickContext<'_, E>) -> Status {
        if self.flag.get::<bool>(ctx.blackboard) == Some(true) { Status::Success } else { Status::Failure }
    }
}

struct CheckString {
    value: Binding,
    equals: Binding,
}

impl<E> Behavior<E> for CheckString {
    fn tick(&mut self, _prev: Status, ctx: &mut TickContext<'_, E>) -> Status {
        match (self.value.get::<Arc<str>>(ctx.blackboard), self.equals.get::<Arc<str>>(ctx.blackboard)) {
            (Some(v), Some(e)) if v == e => Status::Success,
            _ => Status::Failure,
        }
    }
}

struct RaiseEvent {
    event: Binding,
}

impl<E> Behavior<E> for RaiseEvent {
    fn tick(&mut self, _prev: Status, ctx: &mut TickContext<'_, E>) -> Status {
        match self.event.get::<Arc<str>>(ctx.blackboard) {
            Some(e) => {
                ctx.blackboard.raise_event(&e);
                Status::Success
            }
            None => Status::Failure,
        }
    }
}

struct WaitForEvent {
    event: Binding,
}

impl<E> Behavior<E> for WaitForEvent {
    fn tick(&mut self, _prev: Status, ctx: &mut TickContext<'_, E>) -> Status {
        match self.event.get::<Arc<str>>(ctx.blackboard) {
            Some(e) if ctx.blackboard.take_event(&e) => Status::Success,
            Some(_) => Status::Running,
            None => Status::Failure,
        }
    }
}

struct TimeAtLeast {
    time: Binding,
}

impl<E> Behavior<E> for TimeAtLeast {
    fn tick(&mut self, _prev: Status, ctx: &mut TickContext<'_, E>) -> Status {
        match self.time.get::<f64>(ctx.blackboard) {
            Some(t) if ctx.now.as_secs_f64() >= t => Status::Success,
            _ => Status::Failure,
        }
    }
}
