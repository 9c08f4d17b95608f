//! Operator commands in the team state (issue 37): add, cancel and re-prioritise goals, recall,
//! hold and resume robots during a mission.
//!
//! A command is one immutable record, [`RecordKey::Command`], keyed by its [`CommandId`] (the
//! operator's id and the operator's sequence number), written by the operator and relayed like
//! every record (tier 0, sent before the other coordination records). Writing the same command
//! twice, receiving it twice or from several relays changes nothing: the id is the record's key.
//! Each robot that applied a command writes an immutable [`RecordKey::CommandAck`], so the
//! operator sees who has and who has not.
//!
//! **Order.** Commands are ordered by (sequence number, operator id): a later number wins
//! whatever the order of arrival. Everything derived from them (a goal's priority, whether it is
//! cancelled, a robot's [`OperatorMode`]) is a pure function of the set of command records held,
//! computed by applying them in that order, so robots holding the same records agree, and a robot
//! out of range applies what it missed when it hears it.
//!
//! **Goals.** [`OperatorAction::AddGoal`] adds a goal with id `GoalId { origin: operator, seq }`
//! (the command's number): it joins the goal view like any goal (deduplicated within the
//! deconfliction radius; the group takes its priority, name and class). A cancelled goal is never
//! claimable, `claim` refuses it, and a robot releases its claim on it as soon as it holds the
//! cancel; a cancelled goal counts as done for "all goals visited". A later `AddGoal` in the
//! group revives it. A goal's priority is 0 unless a command set one; higher is more urgent, and
//! robots take the most urgent claimable goals first (nearest first among equals).
//!
//! **Robots.** `Hold` (stop where you are), `Recall` (go home and stay) and `Resume` (back to the
//! mission) address one robot or all; for each robot the latest command addressing it (by the
//! order above) gives its [`OperatorMode`]: a `resume all` after `hold ugv2` resumes ugv2, a
//! `hold ugv2` after `resume all` holds it. A recall is lifted by a later resume.
//!
//! **Who may issue.** On a secured team only an operator's key ([`crate::TeamKeys::add_operator`])
//! writes command records: a command signed by a robot key, or a command record written by a
//! robot, refuses the whole message and is counted ([`TeamState::refused_operator_records`]).
//! Without security (the simulator) commands are believed like every record.

use std::collections::BTreeMap;
use std::fmt;

use serde::{Deserialize, Serialize};
use spomp_core::{GoalId, Point2, RobotId, Time};

use crate::auth::TeamSecurity;
use crate::error::TeamStateError;
use crate::record::{GoalOrigin, GoalRecord, Record, RecordBody, RecordKey, RecordSet};
use crate::state::TeamState;
use crate::view::GoalIndex;

/// The reserved id of the team's operator (key file `operator.key.json`, transport user
/// `operator`): no robot may be called so.
pub const OPERATOR_ID: &str = "operator";

/// Longest goal name or class an operator command may carry, characters.
pub const MAX_COMMAND_TEXT: usize = 128;

/// A command's id: the operator and its sequence number. Unique per operator: a short-lived
/// operator process sets [`TeamState::set_command_seq_floor`] above any number it used before.
#[derive(Clone, Debug, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
pub struct CommandId {
    /// The operator that issued it.
    pub operator: RobotId,
    /// The operator's sequence number (from 1).
    pub seq: u32,
}

impl CommandId {
    /// The order commands apply in: sequence number, then operator.
    pub fn order(&self) -> (u32, &RobotId) {
        (self.seq, &self.operator)
    }

    /// The id of the goal an [`OperatorAction::AddGoal`] with this id adds.
    pub fn goal_id(&self) -> GoalId {
        GoalId { origin: self.operator.clone(), seq: self.seq }
    }
}

impl fmt::Display for CommandId {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}#{}", self.operator, self.seq)
    }
}

/// Whom a robot command addresses.
#[derive(Clone, Debug, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum CommandTarget {
    /// Every robot of the team.
    All,
    /// One robot.
    Robot(RobotId),
}

impl CommandTarget {
    /// `all` or a robot id.
    pub fn parse(text: &str) -> CommandTarget {
        match text {
            "all" => CommandTarget::All,
            robot => CommandTarget::Robot(RobotId::new(robot)),
        }
    }

    /// Whether the target includes `robot`.
    pub fn includes(&self, robot: &RobotId) -> bool {
        match self {
            CommandTarget::All => true,
            CommandTarget::Robot(r) => r == robot,
        }
    }
}

impl fmt::Display for CommandTarget {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            CommandTarget::All => f.write_str("all"),
            CommandTarget::Robot(r) => write!(f, "{r}"),
        }
    }
}

/// What an operator asks.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum OperatorAction {
    /// Add a goal (id: [`CommandId::goal_id`]).
    AddGoal {
        /// Map-frame position.
        position: Point2,
        /// A name the operator addresses it by (optional).
        name: Option<String>,
        /// Its priority: 0 is an ordinary goal; higher is more urgent, lower less.
        priority: i32,
        /// What is there (a detector class name, for the log), optional.
        class: Option<String>,
    },
    /// Cancel a goal (any id of its group): it is no longer claimed or visited.
    CancelGoal {
        /// The goal.
        goal: GoalId,
    },
    /// Set a goal's priority (any id of its group).
    SetPriority {
        /// The goal.
        goal: GoalId,
        /// The new priority (0 ordinary, higher more urgent).
        priority: i32,
    },
    /// Send robots home (their start), to stay there until resumed.
    Recall {
        /// Who.
        target: CommandTarget,
    },
    /// Stop robots where they are until resumed.
    Hold {
        /// Who.
        target: CommandTarget,
    },
    /// Lift a hold or a recall: back to the mission.
    Resume {
        /// Who.
        target: CommandTarget,
    },
}

impl OperatorAction {
    /// The robots' target of a robot command; None for a goal command (which every robot applies).
    pub fn target(&self) -> Option<&CommandTarget> {
        match self {
            OperatorAction::Recall { target } | OperatorAction::Hold { target } | OperatorAction::Resume { target } => {
                Some(target)
            }
            _ => None,
        }
    }

    /// Whether `robot` has to apply (and acknowledge) the command.
    pub fn concerns(&self, robot: &RobotId) -> bool {
        self.target().is_none_or(|t| t.includes(robot))
    }

    /// A short fixed name of the action (for logs and counters).
    pub fn kind(&self) -> &'static str {
        match self {
            OperatorAction::AddGoal { .. } => "goal_add",
            OperatorAction::CancelGoal { .. } => "goal_cancel",
            OperatorAction::SetPriority { .. } => "goal_priority",
            OperatorAction::Recall { .. } => "recall",
            OperatorAction::Hold { .. } => "hold",
            OperatorAction::Resume { .. } => "resume",
        }
    }
}

impl fmt::Display for OperatorAction {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            OperatorAction::AddGoal { position, name, priority, class } => {
                write!(f, "goal add at ({:.1}, {:.1}) priority {priority}", position.x, position.y)?;
                if let Some(n) = name {
                    write!(f, " name {n}")?;
                }
                if let Some(c) = class {
                    write!(f, " class {c}")?;
                }
                Ok(())
            }
            OperatorAction::CancelGoal { goal } => write!(f, "goal cancel {goal}"),
            OperatorAction::SetPriority { goal, priority } => write!(f, "goal {goal} priority {priority}"),
            OperatorAction::Recall { target } => write!(f, "recall {target}"),
            OperatorAction::Hold { target } => write!(f, "hold {target}"),
            OperatorAction::Resume { target } => write!(f, "resume {target}"),
        }
    }
}

/// An operator command (the body of a [`RecordKey::Command`]).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct OperatorCommand {
    /// What is asked.
    pub action: OperatorAction,
    /// When the operator issued it, on the operator's clock (for the log; an operator's clock
    /// need not be the robots', so nothing is judged by it).
    pub issued_at: Time,
}

impl OperatorCommand {
    /// Checks values (finite position, text lengths).
    pub fn validate(&self) -> Result<(), String> {
        if let OperatorAction::AddGoal { position, name, class, .. } = &self.action {
            if !(position.x.is_finite() && position.y.is_finite()) {
                return Err("operator goal position is not finite".into());
            }
            for (what, text) in [("name", name), ("class", class)] {
                if text.as_ref().is_some_and(|t| t.chars().count() > MAX_COMMAND_TEXT) {
                    return Err(format!("operator goal {what} longer than {MAX_COMMAND_TEXT} characters"));
                }
            }
        }
        Ok(())
    }
}

/// A robot's acknowledgement of a command (the body of a [`RecordKey::CommandAck`]).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct CommandAckRecord {
    /// When the robot applied the command (its clock).
    pub stamp: Time,
}

/// What the operator's commands ask of one robot now.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum OperatorMode {
    /// No hold or recall in force: the mission runs.
    #[default]
    Mission,
    /// Stop where it is.
    Hold,
    /// Go home (its start) and stay.
    Recall,
}

impl OperatorMode {
    /// `mission`, `hold` or `recall`.
    pub fn as_str(self) -> &'static str {
        match self {
            OperatorMode::Mission => "mission",
            OperatorMode::Hold => "hold",
            OperatorMode::Recall => "recall",
        }
    }
}

/// A robot's [`OperatorMode`] and the command that set it.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct RobotOrders {
    /// The mode.
    pub mode: OperatorMode,
    /// The latest command addressing the robot (None: none yet).
    pub by: Option<CommandId>,
}

/// A command and who acknowledged it ([`TeamState::commands`]).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct CommandView {
    /// Its id.
    pub id: CommandId,
    /// The command.
    pub command: OperatorCommand,
    /// The robots that applied it and when (their clocks), in robot order.
    pub acked_by: Vec<(RobotId, Time)>,
}

impl CommandView {
    /// Whether `robot` acknowledged it.
    pub fn acked_by(&self, robot: &RobotId) -> bool {
        self.acked_by.iter().any(|(r, _)| r == robot)
    }
}

/// The smallest command key: command records sort together from it.
fn first_command_key() -> RecordKey {
    RecordKey::Command(CommandId { operator: RobotId::new(""), seq: 0 })
}

/// The command records held, in command order (sequence number, operator).
pub(crate) fn command_records(records: &RecordSet) -> Vec<(&CommandId, &OperatorCommand)> {
    let mut out: Vec<(&CommandId, &OperatorCommand)> = records
        .starting_at(first_command_key())
        .map_while(|r| match (&r.key, &r.body) {
            (RecordKey::Command(id), RecordBody::Command(c)) => Some(Some((id, c.as_ref()))),
            // A key and body that disagree never pass validation; skipped all the same.
            (RecordKey::Command(_), _) => Some(None),
            _ => None,
        })
        .flatten()
        .collect();
    out.sort_by(|a, b| a.0.order().cmp(&b.0.order()));
    out
}

/// The goals added by operator commands, as goal records (position, issue time).
pub(crate) fn operator_goals(records: &RecordSet) -> Vec<(GoalId, GoalRecord)> {
    command_records(records)
        .into_iter()
        .filter_map(|(id, c)| match &c.action {
            OperatorAction::AddGoal { position, .. } => Some((
                id.goal_id(),
                GoalRecord { position: *position, origin: GoalOrigin::Operator, identified_at: c.issued_at },
            )),
            _ => None,
        })
        .collect()
}

/// Applies the goal commands to the goal views, in command order: priority, name and class of
/// added goals, priority changes, cancels (a later add in the group revives it).
pub(crate) fn apply_goal_commands(records: &RecordSet, index: &mut GoalIndex) {
    for (id, command) in command_records(records) {
        match &command.action {
            OperatorAction::AddGoal { name, priority, class, .. } => {
                let Some(&i) = index.by_id.get(&id.goal_id()) else { continue };
                let Some(view) = index.views.get_mut(i) else { continue };
                view.priority = *priority;
                view.cancelled = None;
                if view.name.is_none() {
                    view.name.clone_from(name);
                }
                if view.class.is_none() {
                    view.class.clone_from(class);
                }
            }
            OperatorAction::CancelGoal { goal } => {
                let Some(&i) = index.by_id.get(goal) else { continue };
                if let Some(view) = index.views.get_mut(i) {
                    view.cancelled = Some(id.clone());
                }
            }
            OperatorAction::SetPriority { goal, priority } => {
                let Some(&i) = index.by_id.get(goal) else { continue };
                if let Some(view) = index.views.get_mut(i) {
                    view.priority = *priority;
                }
            }
            _ => {}
        }
    }
}

impl TeamState {
    /// Every operator command held, in command order, with the robots that acknowledged it.
    pub fn commands(&self) -> Vec<CommandView> {
        // Acknowledgements are keyed (command, robot): grouped in one pass, in robot order.
        let mut acks: BTreeMap<&CommandId, Vec<(RobotId, Time)>> = BTreeMap::new();
        for (command, robot, stamp) in self.command_acks(None) {
            acks.entry(command).or_default().push((robot.clone(), stamp));
        }
        command_records(self.records_set())
            .into_iter()
            .map(|(id, c)| CommandView {
                id: id.clone(),
                command: c.clone(),
                acked_by: acks.remove(id).unwrap_or_default(),
            })
            .collect()
    }

    /// The command `id`, if held, with its acknowledgements (looked up, not listed).
    pub fn command(&self, id: &CommandId) -> Option<CommandView> {
        let RecordBody::Command(command) = &self.records_set().get(&RecordKey::Command(id.clone()))?.body else {
            return None;
        };
        let acked_by = self.command_acks(Some(id)).into_iter().map(|(_, r, t)| (r.clone(), t)).collect();
        Some(CommandView { id: id.clone(), command: command.as_ref().clone(), acked_by })
    }

    /// The acknowledgements held: (command, robot, stamp), in key order; of one command only
    /// with `only`.
    fn command_acks(&self, only: Option<&CommandId>) -> Vec<(&CommandId, &RobotId, Time)> {
        let first = RecordKey::CommandAck {
            command: only.cloned().unwrap_or(CommandId { operator: RobotId::new(""), seq: 0 }),
            robot: RobotId::new(""),
        };
        self.records_set()
            .starting_at(first)
            .take_while(|r| match (&r.key, only) {
                (RecordKey::CommandAck { command, .. }, Some(only)) => command == only,
                _ => true,
            })
            .map_while(|r| match (&r.key, &r.body) {
                (RecordKey::CommandAck { command, robot }, RecordBody::CommandAck(a)) => {
                    Some(Some((command, robot, a.stamp)))
                }
                (RecordKey::CommandAck { .. }, _) => Some(None),
                _ => None,
            })
            .flatten()
            .collect()
    }

    /// What the operator's commands held ask of `robot` now: the latest hold, recall or resume
    /// addressing it (or all), in command order.
    pub fn operator_mode(&self, robot: &RobotId) -> RobotOrders {
        let mut orders = RobotOrders::default();
        for (id, c) in command_records(self.records_set()) {
            let mode = match &c.action {
                OperatorAction::Hold { target } if target.includes(robot) => OperatorMode::Hold,
                OperatorAction::Recall { target } if target.includes(robot) => OperatorMode::Recall,
                OperatorAction::Resume { target } if target.includes(robot) => OperatorMode::Mission,
                _ => continue,
            };
            orders = RobotOrders { mode, by: Some(id.clone()) };
        }
        orders
    }

    /// The commands this robot has to apply and has not acknowledged yet, in command order:
    /// goal commands and robot commands addressing it (not those it issued itself).
    pub fn commands_to_acknowledge(&self) -> Vec<CommandId> {
        let me = self.self_id();
        // Each command's own acknowledgement is looked up by its key: O(commands × log records),
        // not a scan of every acknowledgement per command.
        let acked = |id: &CommandId| {
            self.records_set().contains_key(&RecordKey::CommandAck { command: id.clone(), robot: me.clone() })
        };
        command_records(self.records_set())
            .into_iter()
            .filter(|(id, c)| &id.operator != me && c.action.concerns(me) && !acked(id))
            .map(|(id, _)| id.clone())
            .collect()
    }

    /// Records that this robot applied command `id` (an immutable acknowledgement record, which
    /// travels back to the operator like any record). False if it had already; an error if the
    /// command is not held.
    pub fn acknowledge(&mut self, id: &CommandId, stamp: Time) -> Result<bool, TeamStateError> {
        if !self.records_set().contains_key(&RecordKey::Command(id.clone())) {
            return Err(TeamStateError::InvalidInput(format!("no operator command {id} to acknowledge")));
        }
        let key = RecordKey::CommandAck { command: id.clone(), robot: self.self_id().clone() };
        if self.records_set().contains_key(&key) {
            return Ok(false);
        }
        self.put_record(Record { key, dot: 1, body: RecordBody::CommandAck(CommandAckRecord { stamp }), sig: None });
        Ok(true)
    }

    /// Issues a command as this team member (a short-lived operator member with the reserved id
    /// [`OPERATOR_ID`], or the simulator's operator), signed with its own key on a secured team,
    /// where its key must be an operator's. Returns the command's id.
    pub fn issue_command(&mut self, action: OperatorAction, stamp: Time) -> Result<CommandId, TeamStateError> {
        if let Some(security) = self.security()
            && !security.keys().is_operator(self.self_id())
        {
            return Err(TeamStateError::InvalidInput(format!(
                "{} is not an operator of the team: its key cannot issue operator commands",
                self.self_id()
            )));
        }
        let operator = self.self_id().clone();
        self.write_command(operator, None, action, stamp)
    }

    /// Issues a command as `operator` from a process that is a robot of the team and holds the
    /// operator's key (a viewer's interface served by a robot): written into this robot's team
    /// state, signed with the operator's key, relayed like any record.
    pub fn issue_command_as(
        &mut self,
        operator: &TeamSecurity,
        action: OperatorAction,
        stamp: Time,
    ) -> Result<CommandId, TeamStateError> {
        if !operator.keys().is_operator(operator.robot()) {
            return Err(TeamStateError::InvalidInput(format!(
                "{} is not an operator of the team: its key cannot issue operator commands",
                operator.robot()
            )));
        }
        let id = operator.robot().clone();
        self.write_command(id, Some(operator), action, stamp)
    }

    fn write_command(
        &mut self,
        operator: RobotId,
        signer: Option<&TeamSecurity>,
        action: OperatorAction,
        stamp: Time,
    ) -> Result<CommandId, TeamStateError> {
        let command = OperatorCommand { action, issued_at: stamp };
        command.validate().map_err(TeamStateError::InvalidInput)?;
        let used = command_records(self.records_set())
            .into_iter()
            .filter(|(id, _)| id.operator == operator)
            .map(|(id, _)| id.seq)
            .max()
            .unwrap_or(0);
        let seq = used
            .max(self.command_seq_floor())
            .checked_add(1)
            .ok_or_else(|| TeamStateError::InvalidInput(format!("operator {operator} has no command numbers left")))?;
        let id = CommandId { operator, seq };
        let mut rec = Record {
            key: RecordKey::Command(id.clone()),
            dot: 1,
            body: RecordBody::Command(Box::new(command)),
            sig: None,
        };
        if let Some(signer) = signer {
            rec.sig = Some(Box::new(signer.sign_record(&crate::state::record_bytes(&rec))));
        }
        self.put_record(rec);
        // A cancel of a goal this member holds (a robot serving a viewer) releases it now.
        self.resolve_own_conflicts();
        Ok(id)
    }
}

#[cfg(test)]
mod tests {
    use std::sync::Arc;

    use super::*;
    use crate::{SyncError, TeamKeys, TeamStateParams, TierSet};

    fn at(s: f64) -> Time {
        Time::from_secs_f64(s)
    }

    fn member(id: &str, priority: u32) -> TeamState {
        TeamState::new(RobotId::new(id), priority, TeamStateParams::default()).unwrap()
    }

    /// Sends everything `a` has for `b`, and `b`'s answer back; returns b's report.
    fn exchange(a: &mut TeamState, b: &mut TeamState) -> Result<crate::ApplyReport, SyncError> {
        let (ida, idb) = (a.self_id().clone(), b.self_id().clone());
        let mut report = crate::ApplyReport::default();
        if let Some(m) = a.make_sync(&idb, TierSet::ALL, usize::MAX) {
            report = b.apply_bytes(&ida, &m.encode())?;
        }
        if let Some(m) = b.make_sync(&ida, TierSet::ALL, usize::MAX) {
            a.apply_bytes(&idb, &m.encode())?;
        }
        Ok(report)
    }

    fn add_goal(x: f64, priority: i32) -> OperatorAction {
        OperatorAction::AddGoal { position: Point2::new(x, 0.0), name: None, priority, class: None }
    }

    #[test]
    fn an_operator_goal_is_a_goal_with_its_priority_and_robots_acknowledge_it() {
        let mut op = member(OPERATOR_ID, 0);
        let mut ugv = member("ugv1", 1);
        ugv.identify_goal(Point2::new(5.0, 0.0), GoalOrigin::Detected, at(0.0)).unwrap();
        let near = ugv.goals()[0].id.clone();
        let first = op.issue_command(add_goal(100.0, 0), at(1.0)).unwrap();
        let urgent = op.issue_command(add_goal(200.0, 2), at(2.0)).unwrap();
        assert_eq!((first.seq, urgent.seq), (1, 2));
        exchange(&mut op, &mut ugv).unwrap();
        let order: Vec<GoalId> = ugv
            .claimable_goals_for(&RobotId::new("ugv1"), Point2::new(0.0, 0.0))
            .iter()
            .map(|v| v.id.clone())
            .collect();
        assert_eq!(order, vec![urgent.goal_id(), near, first.goal_id()], "most urgent first, then nearest");
        assert_eq!(ugv.goal(&urgent.goal_id()).unwrap().origin, GoalOrigin::Operator);
        assert_eq!(ugv.commands_to_acknowledge(), vec![first.clone(), urgent.clone()]);
        assert!(ugv.acknowledge(&first, at(3.0)).unwrap());
        assert!(!ugv.acknowledge(&first, at(4.0)).unwrap(), "once");
        assert_eq!(ugv.commands_to_acknowledge(), vec![urgent.clone()]);
        exchange(&mut ugv, &mut op).unwrap();
        let seen = op.commands();
        assert_eq!(seen.len(), 2);
        assert!(seen[0].acked_by(&RobotId::new("ugv1")) && !seen[1].acked_by(&RobotId::new("ugv1")));
        assert!(op.commands_to_acknowledge().is_empty(), "the operator does not acknowledge its own");
        // A restarted operator numbers above what it used (a floor), and above what it learns.
        let mut again = member(OPERATOR_ID, 0);
        again.set_command_seq_floor(10);
        assert_eq!(again.issue_command(add_goal(300.0, 0), at(5.0)).unwrap().seq, 11);
    }

    #[test]
    fn a_cancel_releases_the_claim_in_one_exchange_and_the_goal_is_never_claimed_again() {
        let mut op = member(OPERATOR_ID, 0);
        let (mut a, mut b) = (member("ugv1", 1), member("ugv2", 2));
        let goal = op.issue_command(add_goal(50.0, 0), at(1.0)).unwrap().goal_id();
        exchange(&mut op, &mut a).unwrap();
        exchange(&mut a, &mut b).unwrap();
        a.claim(&goal, at(2.0)).unwrap();
        exchange(&mut a, &mut b).unwrap();
        op.issue_command(OperatorAction::CancelGoal { goal: goal.clone() }, at(3.0)).unwrap();
        let report = exchange(&mut op, &mut a).unwrap();
        assert_eq!(report.released, vec![goal.clone()], "released on hearing the cancel");
        assert!(a.goal(&goal).unwrap().claimant.is_none() && a.goal(&goal).unwrap().cancelled.is_some());
        assert!(matches!(a.claim(&goal, at(4.0)), Err(TeamStateError::Cancelled { .. })));
        exchange(&mut a, &mut b).unwrap();
        assert!(b.claimable_goals_for(&RobotId::new("ugv2"), Point2::new(0.0, 0.0)).is_empty());
        assert!(b.all_goals_visited(), "a cancelled goal counts as done");
        // A later add of a goal in the group revives it.
        op.issue_command(add_goal(52.0, 1), at(5.0)).unwrap();
        exchange(&mut op, &mut b).unwrap();
        let view = b.goal(&goal).unwrap();
        assert!(view.cancelled.is_none() && view.priority == 1);
    }

    #[test]
    fn the_latest_robot_command_wins_per_robot() {
        let mut op = member(OPERATOR_ID, 0);
        let ugv2 = RobotId::new("ugv2");
        let target = |t: &str| CommandTarget::parse(t);
        op.issue_command(OperatorAction::Hold { target: target("ugv2") }, at(1.0)).unwrap();
        assert_eq!(op.operator_mode(&ugv2).mode, OperatorMode::Hold);
        assert_eq!(op.operator_mode(&RobotId::new("ugv1")).mode, OperatorMode::Mission);
        op.issue_command(OperatorAction::Resume { target: target("all") }, at(2.0)).unwrap();
        assert_eq!(op.operator_mode(&ugv2).mode, OperatorMode::Mission);
        let recall = op.issue_command(OperatorAction::Recall { target: target("ugv2") }, at(3.0)).unwrap();
        assert_eq!(op.operator_mode(&ugv2), RobotOrders { mode: OperatorMode::Recall, by: Some(recall) });
        op.issue_command(OperatorAction::Hold { target: target("all") }, at(4.0)).unwrap();
        assert_eq!(op.operator_mode(&ugv2).mode, OperatorMode::Hold);
        let mut ugv1 = member("ugv1", 1);
        exchange(&mut op, &mut ugv1).unwrap();
        // ugv1 acknowledges the commands addressing it (resume all, hold all), not ugv2's.
        assert_eq!(ugv1.commands_to_acknowledge().iter().map(|c| c.seq).collect::<Vec<_>>(), vec![2, 4]);
    }

    fn secured_team() -> (Arc<TeamKeys>, [TeamSecurity; 3]) {
        let mut keys = TeamKeys::new("t");
        keys.add(RobotId::new("ugv1"), &TeamSecurity::public_key_of(&[1; 32])).unwrap();
        keys.add(RobotId::new("ugv2"), &TeamSecurity::public_key_of(&[2; 32])).unwrap();
        keys.add_operator(RobotId::new(OPERATOR_ID), &TeamSecurity::public_key_of(&[9; 32])).unwrap();
        let keys = Arc::new(keys);
        let sec = |id: &str, seed: u8| TeamSecurity::new(RobotId::new(id), &[seed; 32], keys.clone()).unwrap();
        let secs = [sec("ugv1", 1), sec("ugv2", 2), sec(OPERATOR_ID, 9)];
        (keys, secs)
    }

    #[test]
    fn on_a_secured_team_only_the_operator_key_issues_commands_and_forgeries_are_counted() {
        let (_, [s1, s2, sop]) = secured_team();
        let mut op = member(OPERATOR_ID, 0);
        op.set_security(Arc::new(sop.clone())).unwrap();
        let (mut a, mut b) = (member("ugv1", 1), member("ugv2", 2));
        a.set_security(Arc::new(s1.clone())).unwrap();
        b.set_security(Arc::new(s2)).unwrap();
        // The operator member's commands, and one a robot serving a viewer writes as the operator.
        op.issue_command(add_goal(40.0, 1), at(1.0)).unwrap();
        exchange(&mut op, &mut a).unwrap();
        a.issue_command_as(&sop, OperatorAction::Hold { target: CommandTarget::All }, at(2.0)).unwrap();
        exchange(&mut a, &mut b).unwrap();
        assert_eq!(b.commands().len(), 2, "relayed with the operator's signatures");
        assert_eq!(b.operator_mode(&RobotId::new("ugv2")).mode, OperatorMode::Hold);
        assert_eq!(b.refused_operator_records(), 0);
        // A robot's key cannot issue commands, under its own id ...
        assert!(a.issue_command(add_goal(90.0, 0), at(3.0)).is_err());
        assert!(a.issue_command_as(&s1, add_goal(90.0, 0), at(3.0)).is_err());
        // ... nor forge the operator's: a command record under the operator's id signed by ugv1.
        let forged = Record {
            key: RecordKey::Command(CommandId { operator: RobotId::new(OPERATOR_ID), seq: 7 }),
            dot: 1,
            body: RecordBody::Command(Box::new(OperatorCommand {
                action: OperatorAction::Recall { target: CommandTarget::All },
                issued_at: at(3.0),
            })),
            sig: None,
        };
        let mut evil = a.clone();
        let sig = s1.sign_record(&crate::state::record_bytes(&forged));
        evil.put_record(Record { sig: Some(Box::new(sig)), ..forged.clone() });
        let before = b.table_sizes();
        let err = exchange(&mut evil, &mut b).unwrap_err();
        assert_eq!(err.kind(), "bad_signature", "{err}");
        assert_eq!(b.refused_operator_records(), 1);
        assert_eq!(b.table_sizes(), before, "a refused message changes nothing");
        // A command record under a robot's own id, properly signed by it, is refused too.
        let mut evil = a.clone();
        let own = Record { key: RecordKey::Command(CommandId { operator: RobotId::new("ugv1"), seq: 8 }), ..forged };
        evil.put_record(own);
        let err = exchange(&mut evil, &mut b).unwrap_err();
        assert_eq!(err.kind(), "invalid_record", "{err}");
        assert_eq!(b.refused_operator_records(), 2);
        assert_eq!(b.operator_mode(&RobotId::new("ugv2")).mode, OperatorMode::Hold, "unchanged");
    }
}
