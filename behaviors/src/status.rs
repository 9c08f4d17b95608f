//! Node statuses.

use std::fmt;

use serde::{Deserialize, Serialize};

/// What a node reports when ticked (and `Idle` when it is not running).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Status {
    /// Not started, finished and reset, or halted.
    Idle,
    /// Still working; tick again.
    Running,
    /// Done, succeeded.
    Success,
    /// Done, failed.
    Failure,
    /// Not executed, on purpose (BT.CPP's `SKIPPED`): `run_once` with `then_skip: true` after
    /// its first completion. Parents carry on as if the node were not there: a sequence or
    /// fallback moves to the next child, a parallel leaves it out of its thresholds, a
    /// decorator passes it up, a state machine takes it as its subtree's success; a control
    /// node whose children were all skipped reports `Skipped` itself.
    Skipped,
}

impl Status {
    /// Success or Failure.
    pub fn is_done(self) -> bool {
        matches!(self, Status::Success | Status::Failure)
    }

    /// Success, Failure or Skipped: the node will not report anything more for this run.
    #[inline]
    pub fn is_settled(self) -> bool {
        matches!(self, Status::Success | Status::Failure | Status::Skipped)
    }

    /// Lower-case name.
    pub fn as_str(self) -> &'static str {
        match self {
            Status::Idle => "idle",
            Status::Running => "running",
            Status::Success => "success",
            Status::Failure => "failure",
            Status::Skipped => "skipped",
        }
    }
}

impl fmt::Display for Status {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}
