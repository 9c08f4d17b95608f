//! The operator's commands as a robot's log sees them: each command the robot's team state comes
//! to hold, and each acknowledgement (its own or one relayed from another robot), reported once.
//!
//! The simulator knows when its scripted operator issues a command; a robot process does not —
//! it learns of commands and acknowledgements as records arrive. An adapter polls
//! [`OperatorLog::poll`] after each tick and writes what it returns to its log (`spomp run
//! --record` writes them on `/team/events`, the channel the simulator uses), so every command and
//! its acknowledgements are in a robot's log as well as in its recorded team messages.

use std::collections::BTreeSet;

use serde::Serialize;
use spomp_core::RobotId;
use spomp_teamstate::{CommandId, TeamState};

/// One thing a robot's team state newly shows of the operator's commands (JSON on
/// `/team/events`, tagged by `event`).
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(tag = "event", rename_all = "snake_case")]
pub enum OperatorEvent {
    /// The robot's team state holds a command it did not hold before.
    OperatorCommandHeard {
        /// The command's id (`operator/seq`).
        command: String,
        /// Its kind (`goal_add`, `goal_cancel`, `goal_priority`, `recall`, `hold`, `resume`).
        kind: String,
        /// The command in words.
        action: String,
        /// The robot whose team state holds it.
        robot: String,
    },
    /// A robot applied a command (its acknowledgement record, as this robot's team state holds
    /// it: the robot's own, or another's relayed to it).
    OperatorAcknowledged {
        /// The command's id.
        command: String,
        /// The robot that applied it.
        robot: String,
    },
}

/// What has been reported so far; poll it with the same robot's team state.
#[derive(Debug, Default)]
pub struct OperatorLog {
    commands: BTreeSet<CommandId>,
    acks: BTreeSet<(CommandId, RobotId)>,
    /// The team state's operator-records version last polled: nothing new while it stands.
    seen: Option<u64>,
}

impl OperatorLog {
    /// The commands and acknowledgements `team` holds that were not reported before, commands
    /// first, each in command order.
    pub fn poll(&mut self, team: &TeamState) -> Vec<OperatorEvent> {
        let mut out = Vec::new();
        // Only a new command or acknowledgement record can add an event: until one arrives,
        // a poll (each state publish) looks at one number and allocates nothing.
        let version = team.operator_records_version();
        if self.seen == Some(version) {
            return out;
        }
        self.seen = Some(version);
        let views = team.commands();
        for c in &views {
            if self.commands.insert(c.id.clone()) {
                out.push(OperatorEvent::OperatorCommandHeard {
                    command: c.id.to_string(),
                    kind: c.command.action.kind().to_string(),
                    action: c.command.action.to_string(),
                    robot: team.self_id().to_string(),
                });
            }
        }
        for c in &views {
            for (robot, _) in &c.acked_by {
                if self.acks.insert((c.id.clone(), robot.clone())) {
                    out.push(OperatorEvent::OperatorAcknowledged {
                        command: c.id.to_string(),
                        robot: robot.to_string(),
                    });
                }
            }
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use spomp_core::{Point2, Time};
    use spomp_teamstate::{CommandTarget, OPERATOR_ID, OperatorAction, TeamStateParams, TierSet};

    use super::*;

    #[test]
    fn each_command_and_acknowledgement_is_reported_once() {
        let ugv1 = RobotId::new("ugv1");
        let mut operator = TeamState::new(RobotId::new(OPERATOR_ID), 0, TeamStateParams::default()).unwrap();
        let mut robot = TeamState::new(ugv1.clone(), 1, TeamStateParams::default()).unwrap();
        let mut log = OperatorLog::default();
        assert!(log.poll(&robot).is_empty());

        let add = OperatorAction::AddGoal { position: Point2::new(10.0, 5.0), name: None, priority: 2, class: None };
        operator.issue_command(add, Time::from_secs_f64(1.0)).unwrap();
        operator.issue_command(OperatorAction::Hold { target: CommandTarget::All }, Time::from_secs_f64(2.0)).unwrap();
        let bytes = operator.make_sync(&ugv1, TierSet::ALL, 1 << 20).unwrap().encode();
        robot.apply_bytes(&RobotId::new(OPERATOR_ID), &bytes).unwrap();

        let heard = log.poll(&robot);
        let kinds: Vec<&str> = heard
            .iter()
            .map(|e| match e {
                OperatorEvent::OperatorCommandHeard { kind, robot, .. } => {
                    assert_eq!(robot, "ugv1");
                    kind.as_str()
                }
                OperatorEvent::OperatorAcknowledged { .. } => "ack",
            })
            .collect();
        assert_eq!(kinds, ["goal_add", "hold"]);
        assert!(log.poll(&robot).is_empty(), "nothing new: nothing reported again");

        for id in robot.commands_to_acknowledge() {
            robot.acknowledge(&id, Time::from_secs_f64(3.0)).unwrap();
        }
        let acked = log.poll(&robot);
        assert_eq!(acked.len(), 2, "{acked:?}");
        assert!(
            acked.iter().all(|e| matches!(e, OperatorEvent::OperatorAcknowledged { robot, .. } if robot == "ugv1")),
            "{acked:?}"
        );
        assert!(log.poll(&robot).is_empty());
    }
}
