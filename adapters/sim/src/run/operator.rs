//! The simulator's operator (issue 37): `sim.operator:` commands issued at their simulated
//! times by an operator member of the team (reserved id `operator`), which reaches the robots
//! over the modelled radio like any member. It sits at the basestation's start (the operator's
//! console is at the base), or at the first robot's start in a team without a basestation; its
//! radio link to a robot is up when a robot's would be at that place. Unsigned, as the whole
//! simulated team: its commands are believed like every record.

use std::collections::BTreeSet;

use spomp_behaviors::mission::MissionSection;
use spomp_teamstate::{CommandId, CommandTarget, OPERATOR_ID, OperatorAction, SyncMessage, TeamState};
use spomp_world::mission_section::SimSpec;
use spomp_world::operator_script::{ScriptedCommand, ScriptedGoalRef};

use super::*;

/// The operator member and its script.
pub(super) struct SimOperator {
    pub(super) id: RobotId,
    pub(super) team: TeamState,
    pub(super) position: Point2,
    /// The script, in order of time (stable: entries at one time keep the file's order).
    script: Vec<ScriptedCommand>,
    /// Entries issued or waiting: the script's first `next` entries.
    next: usize,
    /// Due entries whose goal the operator does not know yet (retried every step).
    waiting: Vec<ScriptedCommand>,
    /// Acknowledgements shown as events already: (command, robot).
    acks_shown: BTreeSet<(CommandId, RobotId)>,
    /// Each robot's operator-records version when its acknowledgements were last looked at
    /// (by robot index): while it stands, the robot holds no new one.
    acks_looked: Vec<Option<u64>>,
    /// The mission's named goals (`goals.manual`): name → id, as every robot loads them.
    mission_names: Vec<(String, GoalId)>,
    /// What crossed the operator's links.
    pub(super) traffic: OperatorTraffic,
}

/// The team-state traffic between the robots and the simulator's operator over its radio links,
/// for the run's summary: what an operator's console would have to receive.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, serde::Deserialize)]
pub struct OperatorTraffic {
    /// Messages the robots sent the operator.
    pub received_messages: u64,
    /// Bytes the robots sent the operator.
    pub received_bytes: u64,
    /// Those bytes by the tier they carried (coordination, scans, maps); a message's header
    /// counts as coordination. The operator is sent coordination records only
    /// (`TeamState::tiers_taken_by`).
    pub received_bytes_by_tier: [u64; 3],
    /// Messages the operator sent the robots.
    pub sent_messages: u64,
    /// Bytes the operator sent the robots.
    pub sent_bytes: u64,
}

impl OperatorTraffic {
    pub(super) fn count_received(&mut self, bytes: &[u8]) {
        self.received_messages += 1;
        self.received_bytes += bytes.len() as u64;
        // A message that does not decode is refused by the operator's team state; its bytes
        // count with coordination (the header's tier).
        let by_tier = match SyncMessage::decode(bytes) {
            Ok(m) => m.bytes_by_tier(bytes.len()),
            Err(_) => [bytes.len() as u64, 0, 0],
        };
        for (total, b) in self.received_bytes_by_tier.iter_mut().zip(by_tier) {
            *total += b;
        }
    }
}

/// A command's issue and acknowledgements, for the run's summary.
#[derive(Clone, Debug, PartialEq, Serialize, serde::Deserialize)]
pub struct OperatorCommandSummary {
    /// Command id (`operator#3`).
    pub id: String,
    /// What it asked.
    pub action: String,
    /// When the operator issued it, simulated seconds.
    pub issued_s: f64,
    /// The robots that applied it, with when (simulated seconds), as the robots' own team
    /// states hold it at the end.
    pub acked_by: Vec<(String, f64)>,
}

impl SimOperator {
    /// The operator of `mission`, or None without `sim.operator` entries.
    pub(super) fn for_mission(mission: &MissionFile) -> Result<Option<SimOperator>, SimError> {
        let script =
            SimSpec::of_mission(mission).map_err(|e| SimError::invalid("sim.operator", e.to_string()))?.operator;
        if script.is_empty() {
            return Ok(None);
        }
        let robots: Vec<&str> = mission.team.iter().map(|r| r.id.as_str()).collect();
        for (i, entry) in script.iter().enumerate() {
            entry
                .check(&robots)
                .map_err(|(field, why)| SimError::invalid("sim.operator", format!("entry {i}: {field}: {why}")))?;
        }
        let mut script = script;
        script.sort_by(|a, b| a.at_s.total_cmp(&b.at_s));
        let base = mission.team.iter().find(|r| r.kind == RobotKind::Basestation).or(mission.team.first());
        let position = base.map_or(Point2::new(0.0, 0.0), |r| Point2::new(r.start.x_m, r.start.y_m));
        let id = RobotId::new(OPERATOR_ID);
        let team = TeamState::new(id.clone(), u32::MAX, spomp_robot::setup::team_params(mission))
            .map_err(|e| SimError::invalid("sim.operator", e.to_string()))?;
        let mission_names = spomp_robot::setup::mission_goal_names(mission);
        Ok(Some(SimOperator {
            id,
            team,
            position,
            script,
            next: 0,
            waiting: Vec::new(),
            acks_shown: BTreeSet::new(),
            acks_looked: Vec::new(),
            mission_names,
            traffic: OperatorTraffic::default(),
        }))
    }

    /// Issues the entries due by `now` whose goal is known; returns (command, action) issued.
    pub(super) fn issue_due(&mut self, now: Time) -> (Vec<(CommandId, OperatorAction)>, Vec<String>) {
        self.team.advance_clock(now);
        while self.next < self.script.len() && Time::from_secs_f64(self.script[self.next].at_s) <= now {
            self.waiting.push(self.script[self.next].clone());
            self.next += 1;
        }
        let mut issued = Vec::new();
        let mut problems = Vec::new();
        let waiting = std::mem::take(&mut self.waiting);
        for entry in waiting {
            match self.action_of(&entry) {
                Some(action) => match self.team.issue_command(action.clone(), now) {
                    Ok(id) => issued.push((id, action)),
                    Err(e) => problems.push(format!("operator: {e}")),
                },
                None => self.waiting.push(entry),
            }
        }
        (issued, problems)
    }

    /// The action of an entry, None while the goal it addresses is not known to the operator.
    fn action_of(&self, entry: &ScriptedCommand) -> Option<OperatorAction> {
        if let Some(add) = &entry.goal_add {
            return Some(OperatorAction::AddGoal {
                position: Point2::new(add.at[0], add.at[1]),
                name: add.name.clone(),
                priority: add.priority,
                class: add.class.clone(),
            });
        }
        if let Some(r) = &entry.goal_cancel {
            return self.goal_of(r).map(|goal| OperatorAction::CancelGoal { goal });
        }
        if let Some(p) = &entry.goal_priority {
            return self.goal_of(&p.goal_ref()).map(|goal| OperatorAction::SetPriority { goal, priority: p.priority });
        }
        let target = |t: &String| CommandTarget::parse(t);
        if let Some(t) = &entry.recall {
            return Some(OperatorAction::Recall { target: target(t) });
        }
        if let Some(t) = &entry.hold {
            return Some(OperatorAction::Hold { target: target(t) });
        }
        entry.resume.as_ref().map(|t| OperatorAction::Resume { target: target(t) })
    }

    /// The canonical id of the goal a reference names, as the operator knows the goals.
    fn goal_of(&self, r: &ScriptedGoalRef) -> Option<GoalId> {
        if let Some(at) = r.at {
            return self.team.goal_near(Point2::new(at[0], at[1])).map(|v| v.id.clone());
        }
        let name = r.goal.as_deref()?;
        if let Some((_, id)) = self.mission_names.iter().find(|(n, _)| n == name) {
            return self.team.goal(id).map(|v| v.id.clone());
        }
        self.team
            .goals()
            .iter()
            .find(|v| {
                v.name.as_deref() == Some(name)
                    || v.id.to_string() == name
                    || v.aliases.iter().any(|a| a.to_string() == name)
            })
            .map(|v| v.id.clone())
    }

    /// The scripted entries never issued (their goal never became known).
    pub(super) fn never_issued(&self) -> usize {
        self.waiting.len() + (self.script.len() - self.next)
    }
}

impl Simulation {
    /// The operator's step: issues what is due (each a `/team/events` event).
    pub(super) fn operator_step(&mut self, observer: &mut dyn SimObserver) {
        let now = self.now;
        let Some(op) = self.operator.as_mut() else { return };
        let (issued, problems) = op.issue_due(now);
        for (id, action) in issued {
            observer.on_event(
                now,
                &SimEvent::OperatorCommand {
                    command: id.to_string(),
                    kind: action.kind().to_string(),
                    action: action.to_string(),
                },
            );
        }
        let op_id = op.id.clone();
        for p in problems {
            observer.on_problem(&op_id, now, &p);
            note_problem(&mut self.problems, &op_id, p, now);
        }
    }

    /// Once a second: each robot's new acknowledgements of operator commands, as events.
    pub(super) fn track_acknowledgements(&mut self, observer: &mut dyn SimObserver) {
        let now = self.now;
        let Some(op) = self.operator.as_mut() else { return };
        op.acks_looked.resize(self.robots.len(), None);
        for (r, looked) in self.robots.iter().zip(op.acks_looked.iter_mut()) {
            let version = r.robot.team().operator_records_version();
            if looked.replace(version) == Some(version) {
                continue;
            }
            for c in r.robot.team().commands() {
                if c.acked_by(&r.id) && op.acks_shown.insert((c.id.clone(), r.id.clone())) {
                    observer.on_event(
                        now,
                        &SimEvent::OperatorAcknowledged { command: c.id.to_string(), robot: r.id.to_string() },
                    );
                }
            }
        }
    }

    /// The operator's commands and their acknowledgements at the end (empty without one).
    pub(super) fn operator_summary(&self) -> Vec<OperatorCommandSummary> {
        let Some(op) = &self.operator else { return Vec::new() };
        op.team
            .commands()
            .into_iter()
            .map(|c| {
                let mut acked_by: Vec<(String, f64)> = self
                    .robots
                    .iter()
                    .filter_map(|r| {
                        let held = r.robot.team().command(&c.id)?;
                        let at = held.acked_by.iter().find(|(who, _)| who == &r.id)?.1;
                        Some((r.id.to_string(), at.as_secs_f64()))
                    })
                    .collect();
                acked_by.sort_by(|a, b| a.0.cmp(&b.0));
                OperatorCommandSummary {
                    id: c.id.to_string(),
                    action: c.command.action.to_string(),
                    issued_s: c.command.issued_at.as_secs_f64(),
                    acked_by,
                }
            })
            .collect()
    }
}
