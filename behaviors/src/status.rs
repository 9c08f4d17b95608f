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
}

impl Status {
    /// Success or Failure.
    pub fn is_done(self) -> bool {
        matches!(self, Status::Success | Status::Failure)
    }

    /// Lower-case name.
    pub fn as_str(self) -> &'static str {
        match self {
            Status::Idle => "idle",
            Status::Running => "running",
            Status::Success => "success",
            Status::Failure => "failure",
        }
    }
}

impl fmt::Display for Status {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}
