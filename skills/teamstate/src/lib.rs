//! Replicated team database with priorities and deterministic merge rules, transport-free.
//!
//! The paper's MOCHA role (docs/design.md §5 "Team state"): every robot holds a [`TeamState`] with
//! goals and their status (identified / claimed / visited / unreachable), the last known state of
//! every robot, shared reachability scans and aerial-map versions. Robots exchange
//! [`SyncMessage`]s pairwise whenever a link allows; the merge is a join-semilattice per record,
//! so order, duplication and re-delivery do not matter, and two robots that have exchanged
//! everything hold identical records. See the README for the merge rules and the protocol.
//!
//! ```
//! use spomp_core::{Point2, RobotId, Time};
//! use spomp_teamstate::{GoalOrigin, TeamState, TeamStateParams, TierSet};
//!
//! let (ugv1, ugv2) = (RobotId::new("ugv1"), RobotId::new("ugv2"));
//! let mut a = TeamState::new(ugv1.clone(), 1, TeamStateParams::default())?;
//! let mut b = TeamState::new(ugv2.clone(), 2, TeamStateParams::default())?;
//! let goal = a.identify_goal(Point2::new(40.0, 5.0), GoalOrigin::Detected, Time::ZERO)?.id().clone();
//! a.claim(&goal, Time::from_secs_f64(1.0))?;
//!
//! // Whatever transport: bytes from a to b, and b's answer (acknowledgements) back.
//! let bytes = a.make_sync(&ugv2, TierSet::ALL, 64 * 1024).map(|m| m.encode());
//! if let Some(bytes) = bytes {
//!     b.apply_bytes(&ugv1, &bytes)?;
//! }
//! assert!(b.goal(&goal).is_some_and(|g| g.is_held_by(&ugv1)));
//! assert!(b.claimable_goals_for(&ugv2, Point2::new(0.0, 0.0)).is_empty());
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

pub mod auth;
mod error;
mod intern;
mod operator;
mod params;
mod record;
mod snapshot;
mod state;
mod sync;
mod view;

pub use auth::{KeyError, SecurityError, Signature, TeamKeys, TeamSecurity};
pub use error::{SyncError, TeamStateError};
pub use operator::{
    CommandAckRecord, CommandId, CommandTarget, CommandView, MAX_COMMAND_TEXT, OPERATOR_ID, OperatorAction,
    OperatorCommand, OperatorMode, RobotOrders,
};
pub use params::TeamStateParams;
pub use record::{
    ClaimRecord, GoalOrigin, GoalRecord, MAX_DOT, MapVersion, Record, RecordBody, RecordKey, RobotRecord, Tier,
    TierSet, UnreachableRecord, VisitRecord,
};
pub use snapshot::{RestoreSummary, SnapshotError};
pub use state::{ApplyReport, ClaimOutcome, IdentifyOutcome, MISSION_WRITER, RobotStatus, TableSizes, TeamState};
pub use sync::{Ack, SyncMessage, decode, encode};
pub use view::{ClaimInfo, GoalStatus, GoalView};
