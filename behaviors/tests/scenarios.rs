//! The engine's semantics at a glance: one table of scenarios. Each runs a small tree, written
//! in the mission language, of scripted leaves, and records per step the root status and every
//! leaf event, in order.
//!
//! Leaves `a` … `f` are scripted: `{a: {steps: RRS}}` reports Running, Running, then Success on
//! every later tick (the last step repeats; the script goes on across restarts).
//!
//! A step reads `ROOT: EVENTS`:
//! - `ROOT` is the root status after a tick: `R` running, `S` success, `F` failure, `K` skipped;
//!   or `halt` for `TreeExecutor::halt` (after which the root and the executor are both idle);
//! - `a=S` means leaf `a` was ticked and reported Success, `a!` that it was halted.
//!
//! Ticks are 100 ms apart, from t = 0. `behaviors/README.md` states each rule beside
//! BehaviorTree.CPP 4.x's.

#![allow(clippy::unwrap_used, clippy::expect_used)] // tests fail loudly by design

use std::sync::{Arc, Mutex};

use spomp_behaviors::mission::load_tree_str;
use spomp_behaviors::node::{Behavior, TickContext};
use spomp_behaviors::registry::{Category, NodeError, NodeRegistry, NodeTypeSpec, PortSpec};
use spomp_behaviors::{BbValue, PortType, Status, engine_registry};
use spomp_core::Time;

struct Scenario {
    name: &'static str,
    tree: &'static str,
    steps: &'static [&'static str],
}

#[rustfmt::skip]
const SCENARIOS: &[Scenario] = &[
    // --- sequence, fallback, sequence_with_memory ---
    Scenario { name: "sequence resumes at the running child",
        tree: "sequence: [{a: {steps: S}}, {b: {steps: RS}}, {c: {steps: S}}]",
        steps: &["R: a=S b=R", "S: b=S c=S"] },
    Scenario { name: "sequence fails on the first failure, then starts over",
        tree: "sequence: [{a: {steps: S}}, {b: {steps: FS}}, {c: {steps: S}}]",
        steps: &["F: a=S b=F", "S: a=S b=S c=S"] },
    Scenario { name: "sequence starts over after a halt",
        tree: "sequence: [{a: {steps: S}}, {b: {steps: RRS}}, {c: {steps: S}}]",
        steps: &["R: a=S b=R", "halt: b!", "R: a=S b=R", "S: b=S c=S"] },
    Scenario { name: "sequence_with_memory resumes at the child that failed",
        tree: "sequence_with_memory: [{a: {steps: S}}, {b: {steps: FS}}, {c: {steps: S}}]",
        steps: &["F: a=S b=F", "S: b=S c=S", "S: a=S b=S c=S"] },
    Scenario { name: "sequence_with_memory keeps its place through a halt",
        tree: "sequence_with_memory: [{a: {steps: S}}, {b: {steps: RRS}}, {c: {steps: S}}]",
        steps: &["R: a=S b=R", "halt: b!", "R: b=R", "S: b=S c=S"] },
    Scenario { name: "sequence_with_memory inside a fallback keeps its place through the fallback's reset",
        tree: "fallback: [{sequence_with_memory: [{a: {steps: S}}, {b: {steps: FS}}]}, {c: {steps: S}}]",
        steps: &["S: a=S b=F c=S", "S: b=S"] },
    Scenario { name: "sequence_with_memory passes children that succeed at once in one tick (BT.CPP yields after each)",
        tree: "sequence_with_memory: [{a: {steps: S}}, {b: {steps: S}}, {c: {steps: S}}]",
        steps: &["S: a=S b=S c=S"] },
    Scenario { name: "fallback stops at the first success",
        tree: "fallback: [{a: {steps: F}}, {b: {steps: RS}}, {c: {steps: S}}]",
        steps: &["R: a=F b=R", "S: b=S"] },
    // --- reactive control nodes ---
    Scenario { name: "reactive_sequence re-checks its condition and halts the running child when it fails",
        tree: "reactive_sequence: [{a: {steps: SSF}}, {b: {steps: R}}]",
        steps: &["R: a=S b=R", "R: a=S b=R", "F: a=F b!"] },
    Scenario { name: "reactive_sequence halts a running subtree, only its running leaves",
        tree: "reactive_sequence: [{a: {steps: SF}}, {sequence: [{b: {steps: S}}, {c: {steps: R}}]}]",
        steps: &["R: a=S b=S c=R", "F: a=F c!"] },
    Scenario { name: "reactive_fallback: a higher-priority child that succeeds pre-empts the running one",
        tree: "reactive_fallback: [{a: {steps: FFS}}, {b: {steps: R}}]",
        steps: &["R: a=F b=R", "R: a=F b=R", "S: a=S b!"] },
    Scenario { name: "reactive_fallback: a higher-priority child that starts running halts the lower one",
        tree: "reactive_fallback: [{a: {steps: FR}}, {b: {steps: R}}]",
        steps: &["R: a=F b=R", "R: a=R b!"] },
    // --- parallel: thresholds checked after each child ---
    Scenario { name: "parallel success reached at the first child: the others are never started",
        tree: "parallel: {success_threshold: 1, children: [{a: {steps: S}}, {b: {steps: R}}, {c: {steps: R}}]}",
        steps: &["S: a=S"] },
    Scenario { name: "parallel success reached mid-tick: later children are not ticked, running ones halted",
        tree: "parallel: {success_threshold: 2, children: [{a: {steps: RS}}, {b: {steps: R}}, {c: {steps: S}}]}",
        steps: &["R: a=R b=R c=S", "S: a=S b!"] },
    Scenario { name: "parallel failure threshold reached at the first child",
        tree: "parallel: [{a: {steps: F}}, {b: {steps: R}}, {c: {steps: R}}]",
        steps: &["F: a=F"] },
    Scenario { name: "parallel fails as soon as success can no longer be reached",
        tree: "parallel: {success_threshold: 2, failure_threshold: 3, children: [{a: {steps: RF}}, {b: {steps: F}}, {c: {steps: R}}]}",
        steps: &["R: a=R b=F c=R", "F: a=F c!"] },
    Scenario { name: "parallel does not re-tick finished children",
        tree: "parallel: [{a: {steps: S}}, {b: {steps: RRS}}]",
        steps: &["R: a=S b=R", "R: b=R", "S: b=S"] },
    // --- if_then_else, while_do_else ---
    Scenario { name: "if_then_else evaluates its condition once, then runs the chosen branch to its end",
        tree: "if_then_else: [{a: {steps: SF}}, {b: {steps: RRS}}, {c: {steps: S}}]",
        steps: &["R: a=S b=R", "R: b=R", "S: b=S", "S: a=F c=S"] },
    Scenario { name: "if_then_else without an else-branch fails when the condition fails",
        tree: "if_then_else: [{a: {steps: F}}, {b: {steps: S}}]",
        steps: &["F: a=F"] },
    Scenario { name: "if_then_else waits for a running condition",
        tree: "if_then_else: [{a: {steps: RS}}, {b: {steps: S}}]",
        steps: &["R: a=R", "S: a=S b=S"] },
    Scenario { name: "while_do_else re-evaluates every tick; a switch halts the other branch first, same tick",
        tree: "while_do_else: [{a: {steps: SSFS}}, {b: {steps: R}}, {c: {steps: R}}]",
        steps: &["R: a=S b=R", "R: a=S b=R", "R: a=F b! c=R", "R: a=S c! b=R"] },
    Scenario { name: "while_do_else without an else-branch fails and halts the do-branch",
        tree: "while_do_else: [{a: {steps: SF}}, {b: {steps: R}}]",
        steps: &["R: a=S b=R", "F: a=F b!"] },
    Scenario { name: "while_do_else ends with its branch",
        tree: "while_do_else: [{a: {steps: S}}, {b: {steps: RS}}]",
        steps: &["R: a=S b=R", "S: a=S b=S"] },
    // --- retry, repeat, keep_running_until_failure ---
    Scenario { name: "retry re-runs a synchronously failing child within the same tick",
        tree: "retry: {max_attempts: 3, child: {a: {steps: FFS}}}",
        steps: &["S: a=F a=F a=S"] },
    Scenario { name: "retry gives up after max_attempts",
        tree: "retry: {max_attempts: 2, child: {a: {steps: F}}}",
        steps: &["F: a=F a=F"] },
    Scenario { name: "retry restarts an asynchronous child at once when it fails",
        tree: "retry: {max_attempts: 2, child: {a: {steps: RFRS}}}",
        steps: &["R: a=R", "R: a=F a=R", "S: a=S"] },
    Scenario { name: "repeat runs one cycle per tick over a synchronous child",
        tree: "repeat: {times: 3, child: {a: {steps: S}}}",
        steps: &["R: a=S", "R: a=S", "S: a=S"] },
    Scenario { name: "repeat starts the next cycle on the next tick after an asynchronous child succeeds",
        tree: "repeat: {times: 2, child: {a: {steps: RSRS}}}",
        steps: &["R: a=R", "R: a=S", "R: a=R", "S: a=S"] },
    Scenario { name: "repeat fails when its child fails",
        tree: "repeat: {child: {a: {steps: SF}}}",
        steps: &["R: a=S", "F: a=F"] },
    Scenario { name: "keep_running_until_failure restarts a succeeding child each tick until it fails",
        tree: "keep_running_until_failure: {child: {a: {steps: SRSF}}}",
        steps: &["R: a=S", "R: a=R", "R: a=S", "F: a=F"] },
    // --- run_once and the skipped status ---
    Scenario { name: "run_once repeats its first outcome without ticking the child",
        tree: "sequence: [{run_once: {child: {a: {steps: F}}}}, {b: {steps: S}}]",
        steps: &["F: a=F", "F: "] },
    Scenario { name: "run_once then_skip: a sequence moves on as if it were not there",
        tree: "sequence: [{run_once: {then_skip: true, child: {a: {steps: S}}}}, {b: {steps: S}}]",
        steps: &["S: a=S b=S", "S: b=S"] },
    Scenario { name: "run_once then_skip: a fallback moves on too (skipped is no success)",
        tree: "fallback: [{run_once: {then_skip: true, child: {a: {steps: F}}}}, {b: {steps: S}}]",
        steps: &["S: a=F b=S", "S: b=S"] },
    Scenario { name: "a control node whose children were all skipped is skipped",
        tree: "sequence: [{run_once: {then_skip: true, child: {a: {steps: S}}}}]",
        steps: &["S: a=S", "K: "] },
    Scenario { name: "parallel leaves skipped children out of its thresholds",
        tree: "parallel: [{run_once: {then_skip: true, child: {a: {steps: S}}}}, {b: {steps: RSS}}]",
        steps: &["R: a=S b=R", "S: b=S", "S: b=S"] },
    Scenario { name: "parallel with a positive success threshold and a skipped child succeeds (BT.CPP stays running)",
        tree: "parallel: {success_threshold: 2, children: [{run_once: {then_skip: true, child: {a: {steps: S}}}}, {b: {steps: S}}]}",
        steps: &["S: a=S b=S", "S: b=S"] },
    Scenario { name: "decorators pass skipped up",
        tree: "sequence: [{inverter: {child: {run_once: {then_skip: true, child: {a: {steps: F}}}}}}, {b: {steps: S}}]",
        steps: &["S: a=F b=S", "S: b=S"] },
    Scenario { name: "a state whose subtree is skipped takes its success transition",
        tree: "state_machine: {initial: once, states: {once: {run: {run_once: {then_skip: true, child: {a: {steps: S}}}}, transitions: [{on: success, to: done}]}, done: {terminal: success}}}",
        steps: &["S: a=S", "S: "] },
    // --- timeout, halting the whole tree ---
    Scenario { name: "timeout halts its running child past the deadline",
        tree: "timeout: {duration_s: 0.25, child: {a: {steps: R}}}",
        steps: &["R: a=R", "R: a=R", "R: a=R", "F: a!"] },
    Scenario { name: "halt_tree halts the running leaves; the next tick restarts the tree",
        tree: "sequence: [{a: {steps: RS}}, {parallel: [{b: {steps: R}}, {c: {steps: R}}]}]",
        steps: &["R: a=R", "halt: a!", "R: a=S b=R c=R", "halt: b! c!", "R: a=S b=R c=R"] },
    Scenario { name: "halting a finished tree leaves it idle without halting anything",
        tree: "sequence: [{a: {steps: S}}]",
        steps: &["S: a=S", "halt: ", "S: a=S"] },
];

/// Scripted leaf types `a` … `f`, registered as closures that capture the shared event log.
fn registry(log: &Arc<Mutex<Vec<String>>>) -> NodeRegistry<()> {
    let mut r = engine_registry::<()>();
    for id in ["a", "b", "c", "d", "e", "f"] {
        let log = Arc::clone(log);
        r.try_register(NodeTypeSpec::leaf(
            id,
            Category::Action,
            "A scripted leaf.",
            vec![PortSpec::input("steps", PortType::String, "R, S, F or K per tick; the last repeats.")],
            move |ports| {
                let Some(BbValue::Str(steps)) = ports.literal("steps")? else {
                    return Err(NodeError::port("steps", "steps: a literal"));
                };
                let steps = steps.chars().map(status_of).collect::<Result<Vec<_>, _>>().map_err(NodeError::Invalid)?;
                Ok(Box::new(Scripted { id, steps, at: 0, log: Arc::clone(&log) }))
            },
        ))
        .unwrap();
    }
    r
}

struct Scripted {
    id: &'static str,
    steps: Vec<Status>,
    at: usize,
    log: Arc<Mutex<Vec<String>>>,
}

impl Behavior for Scripted {
    fn tick(&mut self, _prev: Status, _ctx: &mut TickContext<'_>) -> Status {
        let s = self.steps[self.at.min(self.steps.len() - 1)];
        self.at += 1;
        self.log.lock().unwrap().push(format!("{}={}", self.id, letter(s)));
        s
    }
    fn halt(&mut self, _ctx: &mut TickContext<'_>) {
        self.log.lock().unwrap().push(format!("{}!", self.id));
    }
}

fn status_of(c: char) -> Result<Status, String> {
    Ok(match c {
        'R' => Status::Running,
        'S' => Status::Success,
        'F' => Status::Failure,
        'K' => Status::Skipped,
        other => return Err(format!("unknown step `{other}`")),
    })
}

fn letter(s: Status) -> &'static str {
    match s {
        Status::Idle => "I",
        Status::Running => "R",
        Status::Success => "S",
        Status::Failure => "F",
        Status::Skipped => "K",
    }
}

/// Runs a scenario and returns its steps as recorded, in the table's notation.
fn run(scenario: &Scenario) -> Vec<String> {
    let log = Arc::new(Mutex::new(Vec::new()));
    let registry = registry(&log);
    let mut ex = load_tree_str(scenario.tree, &registry, &[])
        .unwrap_or_else(|d| panic!("{}: the tree does not load: {d:#?}", scenario.name));
    let mut ticks = 0;
    let mut out = Vec::new();
    for step in scenario.steps {
        let root = if step.starts_with("halt") {
            ex.halt(Time::from_millis(100 * ticks), &mut (), None);
            assert_eq!(ex.root().status(), Status::Idle, "{}: root not idle after a halt", scenario.name);
            "halt"
        } else {
            let s = ex.tick(Time::from_millis(100 * ticks), &mut (), None);
            ticks += 1;
            letter(s)
        };
        assert_eq!(ex.status(), ex.root().status(), "{}: executor and root disagree", scenario.name);
        let events = std::mem::take(&mut *log.lock().unwrap());
        out.push(format!("{root}: {}", events.join(" ")));
    }
    out
}

#[test]
fn scenario_table() {
    let mut failures = Vec::new();
    for scenario in SCENARIOS {
        let got = run(scenario);
        if got != scenario.steps {
            failures.push(format!("{}\n    expected {:?}\n    got      {:?}", scenario.name, scenario.steps, got));
        }
    }
    assert!(
        failures.is_empty(),
        "{} of {} scenarios differ:\n{}",
        failures.len(),
        SCENARIOS.len(),
        failures.join("\n")
    );
}

#[test]
fn the_table_covers_every_control_node_and_decorator() {
    let registry = registry(&Arc::new(Mutex::new(Vec::new())));
    for spec in registry.iter().filter(|s| matches!(s.category, Category::Control | Category::Decorator)) {
        let used = SCENARIOS.iter().any(|s| s.tree.contains(&format!("{}:", spec.name)));
        // `delay`, `rate_limit`, `force_*` are timing and mapping decorators covered in engine.rs.
        let elsewhere = ["delay", "rate_limit", "force_success", "force_failure"].contains(&&*spec.name);
        assert!(used || elsewhere, "no scenario uses `{}`", spec.name);
    }
}
