//! What a node may do to the team state: read all of it, and claim, release and mark goals.
//!
//! The rest of the team state's mutations belong to the robot, not to its tree: the sync with
//! teammates (`make_sync`, `apply_bytes`: the team round, through the seam), the team's
//! security and session, and what the robot publishes of itself (pose, path end, scans, map
//! versions: its upkeep). A node gets [`TeamGoalsMut`] from `RobotRuntime::team_mut`, which
//! reaches none of them, so a node cannot drive the sync. `spomp-teamstate` stays one plain
//! type; the split is the robot's.

use std::ops::Deref;

use spomp_core::{GoalId, Time};
use spomp_teamstate::{ClaimOutcome, TeamState, TeamStateError};

/// The team state as a node changes it (reads go through `Deref`). The sync is out of reach:
///
/// ```compile_fail
/// fn a_node_drives_the_sync(rt: &mut spomp_robot::RobotRuntime, peer: &spomp_core::RobotId) {
///     let _ = rt.team_mut().make_sync(peer, spomp_teamstate::TierSet::ALL, 1000);
/// }
/// ```
///
/// ```compile_fail
/// fn a_node_applies_bytes(rt: &mut spomp_robot::RobotRuntime, peer: &spomp_core::RobotId) {
///     let _ = rt.team_mut().apply_bytes(peer, &[]);
/// }
/// ```
///
/// ```
/// fn a_node_reads_and_claims(rt: &mut spomp_robot::RobotRuntime, goal: &spomp_core::GoalId) {
///     let mut team = rt.team_mut();
///     let _ = team.goals().len();
///     let _ = team.claim(goal, spomp_core::Time::ZERO);
/// }
/// ```
pub struct TeamGoalsMut<'a> {
    team: &'a mut TeamState,
}

impl<'a> TeamGoalsMut<'a> {
    pub(crate) fn new(team: &'a mut TeamState) -> Self {
        TeamGoalsMut { team }
    }

    /// Claims `goal` at `stamp` (see [`TeamState::claim`]).
    pub fn claim(&mut self, goal: &GoalId, stamp: Time) -> Result<ClaimOutcome, TeamStateError> {
        self.team.claim(goal, stamp)
    }

    /// Releases this robot's claim on `goal` (see [`TeamState::release`]).
    pub fn release(&mut self, goal: &GoalId, stamp: Time) -> Result<(), TeamStateError> {
        self.team.release(goal, stamp)
    }

    /// Marks `goal` visited by this robot (see [`TeamState::mark_visited`]).
    pub fn mark_visited(&mut self, goal: &GoalId, stamp: Time) -> Result<(), TeamStateError> {
        self.team.mark_visited(goal, stamp)
    }

    /// Marks `goal` unreachable for this robot (see [`TeamState::mark_unreachable`]).
    pub fn mark_unreachable(&mut self, goal: &GoalId, stamp: Time) -> Result<(), TeamStateError> {
        self.team.mark_unreachable(goal, stamp)
    }

    /// Forgets this robot's unreachable marks (see [`TeamState::clear_unreachable`]).
    pub fn clear_unreachable(&mut self) {
        self.team.clear_unreachable();
    }
}

impl Deref for TeamGoalsMut<'_> {
    type Target = TeamState;
    fn deref(&self) -> &TeamState {
        self.team
    }
}
