//! Long work off the tick: a node starts a [`Job`] and polls it on later ticks; halting the node
//! cancels it.
//!
//! Two runners: [`JobRunner::Threaded`] runs each job on its own thread (real robots: a global
//! plan must not stall the 10 Hz tick), [`JobRunner::Inline`] runs it at once on the calling
//! thread (the simulator: lockstep runs stay deterministic; the result is still only collected
//! on the next poll).

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc;

/// A flag a job checks to stop early.
#[derive(Clone, Debug, Default)]
pub struct CancelToken(Arc<AtomicBool>);

impl CancelToken {
    /// Whether cancellation was requested.
    pub fn is_cancelled(&self) -> bool {
        self.0.load(Ordering::Relaxed)
    }

    fn cancel(&self) {
        self.0.store(true, Ordering::Relaxed);
    }
}

/// Where jobs run.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum JobRunner {
    /// On a thread of their own.
    #[default]
    Threaded,
    /// Immediately, on the caller's thread (deterministic).
    Inline,
}

/// What polling a job gives.
#[derive(Debug, PartialEq, Eq)]
pub enum JobPoll<T> {
    /// Still working.
    Pending,
    /// Finished with this result.
    Done(T),
    /// Cancelled, or the job panicked or vanished.
    Lost,
}

/// A running piece of work producing a `T`.
pub struct Job<T> {
    rx: mpsc::Receiver<T>,
    cancel: CancelToken,
    finished: bool,
}

impl<T: Send + 'static> Job<T> {
    /// Starts `work` on `runner`; `work` should return early when its token is cancelled.
    pub fn start<F>(runner: JobRunner, work: F) -> Self
    where
        F: FnOnce(&CancelToken) -> T + Send + 'static,
    {
        let (tx, rx) = mpsc::channel();
        let cancel = CancelToken::default();
        let token = cancel.clone();
        match runner {
            JobRunner::Inline => {
                // The receiver is alive: the send cannot fail.
                let _ = tx.send(work(&token));
            }
            JobRunner::Threaded => {
                std::thread::spawn(move || {
                    let out = work(&token);
                    // The node may have dropped the job meanwhile; nobody wants the result then.
                    let _ = tx.send(out);
                });
            }
        }
        Job { rx, cancel, finished: false }
    }

    /// Checks for the result without blocking.
    pub fn poll(&mut self) -> JobPoll<T> {
        if self.finished {
            return JobPoll::Lost;
        }
        match self.rx.try_recv() {
            Ok(v) => {
                self.finished = true;
                JobPoll::Done(v)
            }
            Err(mpsc::TryRecvError::Empty) if !self.cancel.is_cancelled() => JobPoll::Pending,
            Err(_) => {
                self.finished = true;
                JobPoll::Lost
            }
        }
    }

    /// Asks the job to stop; its result, if any, is dropped.
    pub fn cancel(&mut self) {
        self.cancel.cancel();
        self.finished = true;
    }
}

impl<T> Drop for Job<T> {
    fn drop(&mut self) {
        self.cancel.0.store(true, Ordering::Relaxed);
    }
}
