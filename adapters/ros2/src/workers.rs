//! The threads the heavy skills run on under `spomp run`, so the tree keeps its tick rate: one
//! thread per kind of work (a panorama's processing never waits behind a graph rebuild), each
//! taking [`SkillWork`] in the order the robot gave it. A skill that panics is reported as a
//! failure of its kind; the robot then stops (the state the work held is lost with it).

use std::collections::HashMap;
use std::sync::mpsc;
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use spomp_robot::runtime::{FinishedWork, SkillWork, WorkKind};

/// What a worker sends back.
pub enum WorkOutcome {
    /// The work finished.
    Done {
        /// Its result, for `Robot::finish_work`.
        work: FinishedWork,
        /// How long it ran.
        took: Duration,
    },
    /// The skill panicked.
    Panicked {
        /// Which kind of work.
        kind: WorkKind,
        /// The panic's message.
        message: String,
    },
}

/// One worker thread per kind of work.
pub struct SkillWorkers {
    lanes: HashMap<WorkKind, Lane>,
    done: mpsc::Receiver<WorkOutcome>,
}

struct Lane {
    tx: Option<mpsc::Sender<SkillWork>>,
    handle: Option<JoinHandle<()>>,
}

impl SkillWorkers {
    /// Starts the threads (named after `robot` and their kind).
    pub fn start(robot: &str) -> std::io::Result<Self> {
        let (done_tx, done) = mpsc::channel();
        let mut lanes = HashMap::new();
        for kind in [WorkKind::Perception, WorkKind::Planner] {
            let (tx, rx) = mpsc::channel::<SkillWork>();
            let done_tx = done_tx.clone();
            let handle = std::thread::Builder::new()
                .name(format!("{robot}-{}", kind.name()))
                .spawn(move || work_loop(kind, &rx, &done_tx))?;
            lanes.insert(kind, Lane { tx: Some(tx), handle: Some(handle) });
        }
        Ok(SkillWorkers { lanes, done })
    }

    /// Queues `work` on the thread of its kind.
    pub fn submit(&self, work: SkillWork) {
        if let Some(tx) = self.lanes.get(&work.kind()).and_then(|l| l.tx.as_ref()) {
            // A worker that is gone has already reported why (a panic).
            let _ = tx.send(work);
        }
    }

    /// A finished work, if one is waiting.
    pub fn try_finished(&self) -> Option<WorkOutcome> {
        self.done.try_recv().ok()
    }

    /// The next finished work, waiting for it at most `timeout` (a farm's lockstep hands a
    /// result back at its modelled time, and waits for the thread if it is not done by then).
    pub fn wait_finished(&self, timeout: Duration) -> Option<WorkOutcome> {
        self.done.recv_timeout(timeout).ok()
    }
}

fn work_loop(kind: WorkKind, rx: &mpsc::Receiver<SkillWork>, done: &mpsc::Sender<WorkOutcome>) {
    while let Ok(work) = rx.recv() {
        let started = Instant::now();
        let outcome = match std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| work.run())) {
            Ok(work) => WorkOutcome::Done { work, took: started.elapsed() },
            Err(payload) => {
                let message = payload
                    .downcast_ref::<&str>()
                    .map(|s| (*s).to_string())
                    .or_else(|| payload.downcast_ref::<String>().cloned())
                    .unwrap_or_else(|| "a skill panicked".into());
                let _ = done.send(WorkOutcome::Panicked { kind, message });
                return;
            }
        };
        if done.send(outcome).is_err() {
            return;
        }
    }
}

impl Drop for SkillWorkers {
    fn drop(&mut self) {
        for lane in self.lanes.values_mut() {
            // Closing the queue ends the thread after the work it is on.
            lane.tx.take();
            if let Some(h) = lane.handle.take() {
                let _ = h.join();
            }
        }
    }
}
