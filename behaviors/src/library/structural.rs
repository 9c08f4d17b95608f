//! Control nodes, decorators, the state machine and subtree references, as registry entries.

use serde_json::json;

use crate::blackboard::PortType;
use crate::registry::{Category, NodeRegistry, NodeTypeSpec, PortSpec};

/// Registers the structural node types.
pub fn register_structural<E>(r: &mut NodeRegistry<E>) {
    use Category::{Control, Decorator};
    use PortType::{Bool, Float, Int, String as Str};
    let s = NodeTypeSpec::structural;
    r.register(s("sequence", Control, "Ticks `children` in order and resumes at the running one; fails on the first failure, succeeds when all succeed.", vec![]));
    r.register(s(
        "sequence_with_memory",
        Control,
        "Like `sequence`, but after a failure or a halt the next run resumes at the child that failed or was running instead of the first; only finishing with success starts it over.",
        vec![],
    ));
    r.register(s(
        "fallback",
        Control,
        "Ticks `children` in order and resumes at the running one; succeeds on the first success, fails when all fail.",
        vec![],
    ));
    r.register(s("reactive_sequence", Control, "Like `sequence`, but restarts from the first child every tick, so conditions before a running action are re-checked; a later running child is halted as soon as an earlier one fails or runs.", vec![]));
    r.register(s("reactive_fallback", Control, "Like `fallback`, but restarts from the first child every tick, so a preferred option that becomes possible halts the running fallback.", vec![]));
    r.register(s(
        "parallel",
        Control,
        "Ticks its unfinished `children` in order every tick and checks the thresholds after each: succeeds once `success_threshold` succeeded, fails once `failure_threshold` failed or success can no longer be reached; then ticks no further child and halts the running ones. Skipped children count towards neither threshold. Thresholds outside 1..=children are load errors.",
        vec![
            PortSpec::optional("success_threshold", Int, "Successes needed (default: all children)."),
            PortSpec::input("failure_threshold", Int, "Failures that fail the node.").with_default(json!(1)),
        ],
    ));
    r.register(s(
        "if_then_else",
        Control,
        "Two or three `children`: ticks the first (the condition) until it finishes, then runs the second on success or the third on failure (fails without one) to its end; the condition is not re-checked meanwhile.",
        vec![],
    ));
    r.register(s(
        "while_do_else",
        Control,
        "Two or three `children`: re-ticks the first (the condition) every tick; runs the second while it succeeds and the third while it fails (fails without one). When the condition changes, the running branch is halted before the other is ticked, in the same tick.",
        vec![],
    ));
    r.register(s(
        "timeout",
        Decorator,
        "Fails and halts its `child` if it has not finished within `duration_s`.",
        vec![PortSpec::input("duration_s", Float, "Time allowed, seconds.")],
    ));
    r.register(s(
        "retry",
        Decorator,
        "Re-runs a failing `child` at once, up to `max_attempts` attempts in all.",
        vec![PortSpec::input("max_attempts", Int, "Attempts in all, ≥ 1.")],
    ));
    r.register(s("repeat", Decorator, "Re-runs a succeeding `child` `times` times (each run on a new tick), or forever if `times` is left out; fails when the child fails.", vec![PortSpec::optional("times", Int, "Runs; forever if absent.")]));
    r.register(s("inverter", Decorator, "Swaps Success and Failure of its `child`.", vec![]));
    r.register(s("force_success", Decorator, "Reports Success whatever its finished `child` reported.", vec![]));
    r.register(s("force_failure", Decorator, "Reports Failure whatever its finished `child` reported.", vec![]));
    r.register(s(
        "run_once",
        Decorator,
        "Runs its `child` to completion once; afterwards reports that outcome without ticking it, or with `then_skip` reports `skipped`, so a parent sequence moves on as if it were not there.",
        vec![
            PortSpec::input("then_skip", Bool, "After the first completion report `skipped` instead of the outcome.")
                .with_default(json!(false)),
        ],
    ));
    r.register(s(
        "keep_running_until_failure",
        Decorator,
        "Restarts its succeeding `child` on the next tick and reports Running meanwhile; fails when the child fails.",
        vec![],
    ));
    r.register(s(
        "delay",
        Decorator,
        "Waits `delay_s`, then runs its `child`.",
        vec![PortSpec::input("delay_s", Float, "Wait before the child starts, seconds.")],
    ));
    r.register(s(
        "rate_limit",
        Decorator,
        "Ticks its `child` at most `hz` times per second; reports Running in between.",
        vec![PortSpec::input("hz", Float, "Maximum child ticks per second.")],
    ));
    r.register(s(
        "state_machine",
        Category::StateMachine,
        "Named `states`, each running an optional subtree (`run`), with `transitions` on the subtree's outcome (`on: success|failure`), on timers (`on: timer, after_s`) and on events (`on: event, event`); `terminal: success|failure` states end the machine.",
        vec![PortSpec::input("initial", Str, "Name of the first state.")],
    ));
    r.register(s("subtree", Category::Subtree, "Inserts the named subtree (from `subtrees:` of this file or an included file); it shares the robot's blackboard.", vec![PortSpec::input("name", Str, "Subtree name.")]));
}
