//! Semantics of the control nodes, decorators and state machine, on small trees of scripted
//! leaves. Each test covers a case engines commonly get wrong.

#![allow(clippy::unwrap_used, clippy::expect_used)] // tests fail loudly by design

use std::sync::{Arc, Mutex};
use std::time::Duration;

use spomp_behaviors::blackboard::Blackboard;
use spomp_behaviors::control::{Ordered, Parallel, Reactive};
use spomp_behaviors::decorators::{Delay, MapResult, RateLimit, Repeat, ResultMap, Retry, RunOnce, Timeout};
use spomp_behaviors::job::{Job, JobPoll, JobRunner};
use spomp_behaviors::node::{Behavior, NodeInfo, Slot, TickContext};
use spomp_behaviors::state_machine::{State, StateMachine, Transition, Trigger};
use spomp_behaviors::trace::Recorder;
use spomp_behaviors::{Status, TreeExecutor};
use spomp_core::Time;

/// What a scripted leaf saw.
#[derive(Default, Debug)]
struct Log {
    ticks: usize,
    starts: usize,
    halts: usize,
}

/// A leaf that returns the next status of its script each tick (the last one repeats).
struct Scripted {
    script: Vec<Status>,
    at: usize,
    log: Arc<Mutex<Log>>,
}

impl Behavior for Scripted {
    fn tick(&mut self, prev: Status, _ctx: &mut TickContext<'_>) -> Status {
        let mut log = self.log.lock().unwrap();
        log.ticks += 1;
        if prev != Status::Running {
            log.starts += 1;
        }
        let s = self.script[self.at.min(self.script.len() - 1)];
        self.at += 1;
        s
    }
    fn halt(&mut self, _ctx: &mut TickContext<'_>) {
        self.log.lock().unwrap().halts += 1;
    }
}

fn leaf(name: &str, script: &[Status]) -> (Slot, Arc<Mutex<Log>>) {
    let log = Arc::new(Mutex::new(Log::default()));
    let b = Scripted { script: script.to_vec(), at: 0, log: log.clone() };
    (slot(name, Box::new(b)), log)
}

fn slot(name: &str, b: Box<dyn Behavior>) -> Slot {
    Slot::new(NodeInfo { id: 0, type_name: name.into(), path: name.into() }, b)
}

/// Ticks `root` at 10 Hz from t = 0 and returns the statuses.
fn run(root: Slot, ticks: usize) -> (Vec<Status>, TreeExecutor) {
    let mut ex = TreeExecutor::from_root(root, Blackboard::new());
    let mut out = Vec::new();
    for i in 0..ticks {
        out.push(ex.tick(Time::from_millis(100 * i as i64), &mut (), None));
    }
    (out, ex)
}

use Status::{Failure as F, Running as R, Success as S};

#[test]
fn sequence_resumes_at_the_running_child() {
    let (a, la) = leaf("a", &[S]);
    let (b, lb) = leaf("b", &[R, R, S]);
    let (statuses, _) = run(slot("seq", Box::new(Ordered::sequence(vec![a, b]))), 3);
    assert_eq!(statuses, vec![R, R, S]);
    assert_eq!(la.lock().unwrap().ticks, 1, "a finished child is not re-ticked");
    assert_eq!(lb.lock().unwrap().starts, 1);
}

#[test]
fn sequence_fails_on_first_failure_and_restarts() {
    let (a, la) = leaf("a", &[S]);
    let (b, _) = leaf("b", &[F]);
    let (c, lc) = leaf("c", &[S]);
    let (statuses, _) = run(slot("seq", Box::new(Ordered::sequence(vec![a, b, c]))), 2);
    assert_eq!(statuses, vec![F, F]);
    assert_eq!(la.lock().unwrap().ticks, 2, "a failed sequence starts over");
    assert_eq!(lc.lock().unwrap().ticks, 0);
}

#[test]
fn fallback_stops_at_first_success() {
    let (a, _) = leaf("a", &[F]);
    let (b, _) = leaf("b", &[R, S]);
    let (c, lc) = leaf("c", &[S]);
    let (statuses, _) = run(slot("fb", Box::new(Ordered::fallback(vec![a, b, c]))), 2);
    assert_eq!(statuses, vec![R, S]);
    assert_eq!(lc.lock().unwrap().ticks, 0);
}

#[test]
fn reactive_sequence_halts_running_child_when_condition_fails() {
    let (cond, lcond) = leaf("cond", &[S, S, F]);
    let (act, lact) = leaf("act", &[R]);
    let (statuses, _) = run(slot("rs", Box::new(Reactive::sequence(vec![cond, act]))), 3);
    assert_eq!(statuses, vec![R, R, F]);
    assert_eq!(lcond.lock().unwrap().ticks, 3, "the condition is re-checked every tick");
    let la = lact.lock().unwrap();
    assert_eq!(la.ticks, 2);
    assert_eq!(la.halts, 1, "the running action is halted when the condition fails");
    assert_eq!(la.starts, 1, "the action keeps running between ticks, it is not restarted");
}

#[test]
fn reactive_fallback_halts_fallback_when_preferred_option_succeeds() {
    let (preferred, _) = leaf("preferred", &[F, F, S]);
    let (backup, lb) = leaf("backup", &[R]);
    let (statuses, _) = run(slot("rf", Box::new(Reactive::fallback(vec![preferred, backup]))), 3);
    assert_eq!(statuses, vec![R, R, S]);
    assert_eq!(lb.lock().unwrap().halts, 1);
}

#[test]
fn parallel_thresholds() {
    // Succeeds when 2 of 3 succeed; the third is halted.
    let (a, _) = leaf("a", &[S]);
    let (b, _) = leaf("b", &[R, S]);
    let (c, lc) = leaf("c", &[R]);
    let (statuses, _) = run(slot("par", Box::new(Parallel::new(vec![a, b, c], 2, 1).unwrap())), 2);
    assert_eq!(statuses, vec![R, S]);
    assert_eq!(lc.lock().unwrap().halts, 1);

    // Fails at the first failure with failure_threshold 1.
    let (a, _) = leaf("a", &[R]);
    let (b, _) = leaf("b", &[R, F]);
    let (statuses, _) = run(slot("par", Box::new(Parallel::new(vec![a, b], 2, 1).unwrap())), 2);
    assert_eq!(statuses, vec![R, F]);

    // Fails as soon as success became impossible: needs 3, one failed.
    let (a, _) = leaf("a", &[R]);
    let (b, _) = leaf("b", &[F]);
    let (c, _) = leaf("c", &[R]);
    let (statuses, _) = run(slot("par", Box::new(Parallel::new(vec![a, b, c], 3, 3).unwrap())), 1);
    assert_eq!(statuses, vec![F]);

    // Thresholds it cannot meet are refused, not clamped.
    let kids = || vec![leaf("a", &[S]).0, leaf("b", &[S]).0];
    let e = Parallel::new(kids(), 3, 1).err().unwrap();
    assert_eq!((e.name, e.value, e.children), ("success_threshold", 3, 2));
    assert_eq!(Parallel::new(kids(), 1, 0).err().unwrap().name, "failure_threshold");
}

#[test]
fn timeout_halts_its_child() {
    let (a, la) = leaf("a", &[R]);
    let root = slot("to", Box::new(Timeout::new(a, Duration::from_millis(250))));
    let (statuses, _) = run(root, 5);
    // t = 0, 0.1, 0.2 running; t = 0.3 past the deadline.
    assert_eq!(&statuses[..4], &[R, R, R, F]);
    assert_eq!(la.lock().unwrap().halts, 1);
}

#[test]
fn retry_counts_attempts() {
    let (a, la) = leaf("a", &[F, F, F, F, S]);
    let (statuses, _) = run(slot("retry", Box::new(Retry::new(a, 3))), 2);
    assert_eq!(statuses[0], F, "three attempts in the first tick, all failed");
    assert_eq!(statuses[1], S, "the count starts over: a failure, then a success");
    assert_eq!(la.lock().unwrap().ticks, 5);

    let (b, lb) = leaf("b", &[F, F, S]);
    let (statuses, _) = run(slot("retry", Box::new(Retry::new(b, 3))), 1);
    assert_eq!(statuses, vec![S]);
    assert_eq!(lb.lock().unwrap().starts, 3);
}

#[test]
fn repeat_runs_child_n_times_one_per_tick() {
    let (a, la) = leaf("a", &[S]);
    let (statuses, _) = run(slot("rep", Box::new(Repeat::new(a, Some(3)))), 3);
    assert_eq!(statuses, vec![R, R, S]);
    assert_eq!(la.lock().unwrap().starts, 3);
    let (b, _) = leaf("b", &[S, F]);
    let (statuses, _) = run(slot("rep", Box::new(Repeat::new(b, None))), 2);
    assert_eq!(statuses, vec![R, F], "repeat forever stops at the first failure");
}

#[test]
fn inverter_and_forcing() {
    let (a, _) = leaf("a", &[R, S]);
    let (statuses, _) = run(slot("inv", Box::new(MapResult::new(a, ResultMap::Invert))), 2);
    assert_eq!(statuses, vec![R, F]);
    let (b, _) = leaf("b", &[F]);
    let (statuses, _) = run(slot("fs", Box::new(MapResult::new(b, ResultMap::ForceSuccess))), 1);
    assert_eq!(statuses, vec![S]);
    let (c, _) = leaf("c", &[S]);
    let (statuses, _) = run(slot("ff", Box::new(MapResult::new(c, ResultMap::ForceFailure))), 1);
    assert_eq!(statuses, vec![F]);
}

#[test]
fn run_once_remembers_the_outcome() {
    let (a, la) = leaf("a", &[R, S, F]);
    let (statuses, _) = run(slot("once", Box::new(RunOnce::new(a))), 4);
    assert_eq!(statuses, vec![R, S, S, S]);
    assert_eq!(la.lock().unwrap().ticks, 2);
}

#[test]
fn delay_waits_before_starting() {
    let (a, la) = leaf("a", &[S]);
    let (statuses, _) = run(slot("delay", Box::new(Delay::new(a, Duration::from_millis(300)))), 4);
    assert_eq!(statuses, vec![R, R, R, S]);
    assert_eq!(la.lock().unwrap().ticks, 1);
}

#[test]
fn rate_limit_throttles_child_ticks() {
    let (a, la) = leaf("a", &[R]);
    let (statuses, _) = run(slot("rl", Box::new(RateLimit::new(a, 2.0))), 10);
    assert!(statuses.iter().all(|s| *s == R));
    // 10 ticks at 10 Hz over 0.9 s, at most 2 Hz: t = 0, 0.5.
    assert_eq!(la.lock().unwrap().ticks, 2);
}

/// (name, subtree, transitions, terminal outcome) of a test state.
type StateDef<'a> = (&'a str, Option<Slot>, Vec<(Trigger, usize)>, Option<Status>);

fn machine(states: Vec<StateDef<'_>>) -> Slot {
    let mut children = Vec::new();
    let built = states
        .into_iter()
        .map(|(name, run, transitions, terminal)| {
            let run = run.map(|r| {
                children.push(r);
                children.len() - 1
            });
            State {
                name: name.into(),
                run,
                transitions: transitions.into_iter().map(|(trigger, target)| Transition { trigger, target }).collect(),
                terminal,
            }
        })
        .collect();
    slot("sm", Box::new(StateMachine::new(built, children, 0)))
}

#[test]
fn state_machine_timer_fires_while_child_runs() {
    let (explore, le) = leaf("explore", &[R]);
    let (seek, ls) = leaf("seek", &[R, S]);
    let root = machine(vec![
        ("explore", Some(explore), vec![(Trigger::Timer(Duration::from_millis(300)), 1)], None),
        ("seek", Some(seek), vec![(Trigger::Success, 2)], None),
        ("done", None, vec![], Some(S)),
    ]);
    let (statuses, _) = run(root, 6);
    // t=0,0.1,0.2 explore runs; t=0.3 timer fires → seek ticks (R); t=0.4 seek S → done;
    // ticked again after finishing, the machine starts over from its initial state.
    assert_eq!(statuses, vec![R, R, R, R, S, R]);
    let le = le.lock().unwrap();
    assert_eq!(le.ticks, 4);
    assert_eq!(le.halts, 1, "the timer halts the running subtree");
    assert_eq!(ls.lock().unwrap().ticks, 2);
}

#[test]
fn state_machine_transitions_on_outcome_and_events() {
    let (a, _) = leaf("a", &[F]);
    let (b, lb) = leaf("b", &[R]);
    let root = machine(vec![
        ("a", Some(a), vec![(Trigger::Failure, 1)], None),
        ("b", Some(b), vec![(Trigger::Event("go".into()), 2)], None),
        ("end", None, vec![], Some(F)),
    ]);
    let mut ex = TreeExecutor::from_root(root, Blackboard::new());
    assert_eq!(ex.tick(Time::ZERO, &mut (), None), R, "a failed → b");
    assert_eq!(ex.tick(Time::from_millis(100), &mut (), None), R);
    ex.blackboard_mut().raise_event("go");
    assert_eq!(ex.tick(Time::from_millis(200), &mut (), None), F, "the event leads to the failing terminal state");
    assert_eq!(lb.lock().unwrap().halts, 1);
}

#[test]
fn unhandled_outcome_ends_the_machine() {
    let (a, _) = leaf("a", &[S]);
    let root = machine(vec![("a", Some(a), vec![(Trigger::Failure, 0)], None)]);
    let (statuses, _) = run(root, 1);
    assert_eq!(statuses, vec![S]);
}

#[test]
fn halting_is_recursive_and_observed() {
    let (a, la) = leaf("a", &[R]);
    let inner = slot("inner", Box::new(Ordered::sequence(vec![a])));
    let root = slot("outer", Box::new(Ordered::sequence(vec![inner])));
    let mut ex = TreeExecutor::from_root(root, Blackboard::new());
    let mut rec = Recorder::default();
    ex.tick(Time::ZERO, &mut (), Some(&mut rec));
    ex.halt(Time::from_millis(100), &mut (), Some(&mut rec));
    assert_eq!(la.lock().unwrap().halts, 1);
    let to_idle: Vec<&str> = rec.records.iter().filter(|r| r.to == Status::Idle).map(|r| r.path.as_str()).collect();
    assert_eq!(to_idle, vec!["a", "inner", "outer"], "children go idle before their parents");
    assert_eq!(rec.records.iter().filter(|r| r.to == Status::Running).count(), 3);
}

/// A node that runs a job and reports its result; halting cancels the job.
struct JobNode {
    job: Option<Job<u64>>,
    cancelled: Arc<Mutex<bool>>,
    runner: JobRunner,
}

impl Behavior for JobNode {
    fn tick(&mut self, prev: Status, _ctx: &mut TickContext<'_>) -> Status {
        if prev != Status::Running {
            let flag = self.cancelled.clone();
            self.job = Some(Job::start(self.runner, move |token| {
                // Work in slices, checking for cancellation between them.
                let mut sum = 0u64;
                for i in 0..2_000u64 {
                    if token.is_cancelled() {
                        *flag.lock().unwrap() = true;
                        return 0;
                    }
                    sum += i;
                    if matches!(i % 100, 0) {
                        std::thread::sleep(Duration::from_millis(1));
                    }
                }
                sum
            }));
        }
        match self.job.as_mut().map(Job::poll) {
            Some(JobPoll::Pending) => Status::Running,
            Some(JobPoll::Done(1_999_000)) => Status::Success,
            _ => Status::Failure,
        }
    }
    fn halt(&mut self, _ctx: &mut TickContext<'_>) {
        if let Some(j) = self.job.as_mut() {
            j.cancel();
        }
    }
}

#[test]
fn jobs_are_polled_and_cancelled_on_halt() {
    // Inline: deterministic, done on the first poll.
    let flag = Arc::new(Mutex::new(false));
    let node = slot("job", Box::new(JobNode { job: None, cancelled: flag.clone(), runner: JobRunner::Inline }));
    let (statuses, _) = run(node, 1);
    assert_eq!(statuses, vec![S]);

    // Threaded: the tick does not block; halting cancels the work.
    let flag = Arc::new(Mutex::new(false));
    let node = slot("job", Box::new(JobNode { job: None, cancelled: flag.clone(), runner: JobRunner::Threaded }));
    let mut ex = TreeExecutor::from_root(node, Blackboard::new());
    assert_eq!(ex.tick(Time::ZERO, &mut (), None), R, "the first tick returns while the job works");
    ex.halt(Time::from_millis(100), &mut (), None);
    let deadline = std::time::Instant::now() + Duration::from_secs(10);
    while !*flag.lock().unwrap() && std::time::Instant::now() < deadline {
        std::thread::sleep(Duration::from_millis(2));
    }
    assert!(*flag.lock().unwrap(), "the job saw the cancellation");

    // Threaded, left alone: finishes and succeeds on a later poll.
    let flag = Arc::new(Mutex::new(false));
    let node = slot("job", Box::new(JobNode { job: None, cancelled: flag, runner: JobRunner::Threaded }));
    let mut ex = TreeExecutor::from_root(node, Blackboard::new());
    let mut last = R;
    for i in 0..2000 {
        last = ex.tick(Time::from_millis(i), &mut (), None);
        if last != R {
            break;
        }
        std::thread::sleep(Duration::from_millis(2));
    }
    assert_eq!(last, S);
}
