//! `spomp operator`'s body: a member of the Zenoh team link (the `deploy` feature).

use std::collections::{BTreeMap, BTreeSet};
use std::process::ExitCode;
use std::sync::Arc;
use std::time::{Duration, Instant};

use anyhow::{Context, Result, bail};
use serde::Serialize;
use spomp_behaviors::NodeRegistry;
use spomp_behaviors::mission::{LoadOptions, MissionFile, load_mission_with};
use spomp_core::{GoalId, Point2, RobotId, Time};
use spomp_robot::RobotRuntime;
use spomp_teamstate::{
    CommandId, CommandTarget, CommandView, GoalView, OPERATOR_ID, OperatorAction, TeamState, Tier, TierSet,
};
use spomp_zenoh::{KeyDir, LinkConfig, TeamLink};

/// How often the operator syncs with the robots it reaches (wall time).
const SYNC_PERIOD: Duration = Duration::from_millis(50);
/// The largest sync message the operator sends (it writes one small record; the rest is
/// acknowledgements).
const SYNC_BUDGET_BYTES: usize = 64 * 1024;

use super::{GoalArg, OperatorArgs, OperatorCommandArg};

/// The operator's member of the team: its team state and its end of the link.
struct Member {
    state: TeamState,
    /// The mission's named goals: (name, id).
    mission_names: Vec<(String, GoalId)>,
    link: TeamLink,
    robots: BTreeSet<RobotId>,
    /// Robots reached at some point during this run.
    reached: BTreeSet<RobotId>,
    /// Messages from each robot taken into the team state.
    heard: BTreeMap<RobotId, u64>,
    /// Messages refused (bad signature, replay, …), by kind.
    refused: BTreeMap<&'static str, u64>,
}

impl Member {
    fn join(args: &OperatorArgs, registry: &NodeRegistry<RobotRuntime>) -> Result<Member> {
        let loaded = load_mission_with(&args.mission, registry, &LoadOptions::default());
        if !loaded.is_valid() {
            crate::commands::print_diagnostics(&loaded);
            bail!("{}: the mission does not validate", args.mission.display());
        }
        let Some(mission) = loaded.mission.as_ref() else {
            bail!("{}: the mission did not load", args.mission.display())
        };
        let keys = KeyDir::load(&args.keys)?;
        if keys.team() != mission.mission {
            bail!(
                "{}: the keys are of team `{}`, the mission is `{}`",
                args.keys.display(),
                keys.team(),
                mission.mission
            );
        }
        let operator = RobotId::new(OPERATOR_ID);
        let security = keys.operator_security().with_context(|| {
            format!("{}: the operator's key (operator.key.json) is needed to issue commands", args.keys.display())
        })?;
        let mut state = operator_state(mission)?;
        let mission_names = spomp_robot::setup::mission_goal_names(mission);
        state.set_security(Arc::new(security)).context("securing the operator's team state")?;
        let now = wall_now();
        // Every run a larger session (robots take each session's messages once), and command
        // numbers above any an earlier run (or a robot serving a viewer) used: the numbers
        // order commands, so a later command wins.
        state.set_session(now.as_nanos() as u64);
        state.set_command_seq_floor(u32::try_from(now.as_secs()).unwrap_or(u32::MAX));
        let mut config = LinkConfig::new(&mission.mission, operator.clone());
        for e in &args.connect {
            spomp_zenoh::mission_section::check_endpoint(e).map_err(|why| anyhow::anyhow!("--connect: {why}"))?;
        }
        config.connect = args.connect.clone();
        config.multicast_scouting = false;
        config.members = Some(keys.members().cloned().collect());
        config.credentials = Some(keys.operator_credentials().with_context(|| {
            format!("{}: the operator's transport password (operator.key.json) is needed", args.keys.display())
        })?);
        let link = TeamLink::open(&config)?;
        let robots = mission.team.iter().map(|r| RobotId::new(&r.id)).collect();
        Ok(Member {
            state,
            mission_names,
            link,
            robots,
            reached: BTreeSet::new(),
            heard: BTreeMap::new(),
            refused: BTreeMap::new(),
        })
    }

    /// The team's robots the link reaches now.
    fn reachable(&self) -> BTreeSet<RobotId> {
        self.link.reachable().intersection(&self.robots).cloned().collect()
    }

    /// One sync round: what arrived is applied, and each reachable robot is sent what it lacks
    /// (and acknowledgements).
    fn sync(&mut self) {
        for (from, bytes) in self.link.receive() {
            match self.state.apply_bytes(&from, &bytes) {
                Ok(_) => *self.heard.entry(from).or_default() += 1,
                Err(e) => *self.refused.entry(e.kind()).or_default() += 1,
            }
        }
        let reachable = self.reachable();
        for robot in &reachable {
            if let Some(m) = self.state.make_sync(robot, TierSet::only(Tier::Coordination), SYNC_BUDGET_BYTES) {
                self.link.send(robot, Tier::Coordination, m.encode());
            }
        }
        self.reached.extend(reachable);
    }

    /// Syncs until `done` holds or `deadline` passes; whether `done` held.
    fn sync_until(&mut self, deadline: Instant, mut done: impl FnMut(&Member) -> bool) -> bool {
        loop {
            self.sync();
            if done(self) {
                return true;
            }
            if Instant::now() >= deadline {
                return false;
            }
            std::thread::sleep(SYNC_PERIOD);
        }
    }

    /// Joins: waits until a robot is reachable, then until every reachable robot has exchanged
    /// everything with the operator (it holds what they hold).
    fn catch_up(&mut self, deadline: Instant) -> bool {
        self.sync_until(deadline, |m| {
            let reachable = m.reachable();
            !reachable.is_empty() && reachable.iter().all(|r| m.heard.contains_key(r) && m.state.sync_complete_with(r))
        })
    }

    /// The team's time as the operator knows it: the newest robot stamp heard (the robots'
    /// clock, simulated in a farm), for the command's `issued_at`.
    fn team_time(&self) -> Time {
        self.state.robots().iter().map(|(_, s)| s.stamp).max().unwrap_or(Time::ZERO)
    }
}

/// The operator member's team state for `mission`: the team-state parameters every robot of
/// the mission uses (its deconfliction radius above all: the operator's goal view, which names
/// and statuses are read from, must group goals as the robots' do), and the mission's goals as
/// every robot adds them (`mission/<index>`: the team's claims and visits of them refer to
/// them, and their names address them).
fn operator_state(mission: &MissionFile) -> Result<TeamState> {
    let mut state = TeamState::new(RobotId::new(OPERATOR_ID), u32::MAX, spomp_robot::setup::team_params(mission))
        .context("the operator's team state")?;
    for (k, g) in mission.goals.iter().flat_map(|g| g.manual.iter()).enumerate() {
        state.add_mission_goal(k as u32, Point2::new(g.x_m, g.y_m)).with_context(|| format!("goals.manual[{k}]"))?;
    }
    Ok(state)
}

fn wall_now() -> Duration {
    std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).unwrap_or_default()
}

/// The goal `name` names: its operator name, its name in the mission (`mission_names`), its
/// canonical id or an alias (`origin/seq`).
fn resolve_goal(goals: &[GoalView], mission_names: &[(String, GoalId)], name: &str) -> Result<GoalId> {
    let by_name: Vec<&GoalView> = goals
        .iter()
        .filter(|g| g.name.as_deref() == Some(name) || mission_names.iter().any(|(n, id)| n == name && g.includes(id)))
        .collect();
    match by_name.as_slice() {
        [one] => return Ok(one.id.clone()),
        [] => {}
        many => bail!(
            "{} goals are named `{name}` ({}): give an id",
            many.len(),
            many.iter().map(|g| g.id.to_string()).collect::<Vec<_>>().join(", ")
        ),
    }
    if let Some(g) = goals.iter().find(|g| g.id.to_string() == name || g.aliases.iter().any(|a| a.to_string() == name))
    {
        return Ok(g.id.clone());
    }
    let known: Vec<String> = goals
        .iter()
        .map(|g| match &g.name {
            Some(n) => format!("{} ({n})", g.id),
            None => match mission_names.iter().find(|(_, id)| g.includes(id)) {
                Some((n, _)) => format!("{} ({n})", g.id),
                None => g.id.to_string(),
            },
        })
        .collect();
    bail!(
        "no goal named `{name}` among the {} the team knows{}",
        goals.len(),
        if known.is_empty() { String::new() } else { format!(": {}", known.join(", ")) }
    )
}

/// Who did what with the command, as printed.
#[derive(Serialize)]
struct Outcome {
    command: Option<String>,
    id: Option<String>,
    /// Robots that applied it, with their clock at the time.
    acknowledged: BTreeMap<String, f64>,
    /// Robots the command concerns that were reachable but did not acknowledge it in time.
    not_acknowledged: Vec<String>,
    /// Robots the command concerns that were never reachable during the wait: they apply it
    /// when a teammate that holds it comes into range.
    not_reached: Vec<String>,
    /// Messages from each robot taken.
    heard: BTreeMap<String, u64>,
    /// Messages refused, by kind.
    refused: BTreeMap<&'static str, u64>,
}

/// What to issue, as far as it is known before joining: a goal named by the operator is looked
/// up in the team's goals once synced.
enum Request {
    Status,
    Ready(OperatorAction),
    Cancel(String),
    Priority(String, i32),
}

fn request_of(args: &OperatorArgs, robots: &BTreeSet<RobotId>) -> Result<Request> {
    let target = |text: &str| target_of(robots, text);
    Ok(match &args.command {
        OperatorCommandArg::Status => Request::Status,
        OperatorCommandArg::Goal { action: GoalArg::Add { at, name, priority, class } } => {
            Request::Ready(OperatorAction::AddGoal {
                position: *at,
                name: name.clone(),
                priority: *priority,
                class: class.clone(),
            })
        }
        OperatorCommandArg::Goal { action: GoalArg::Cancel { goal } } => Request::Cancel(goal.clone()),
        OperatorCommandArg::Goal { action: GoalArg::Priority { goal, priority } } => {
            Request::Priority(goal.clone(), *priority)
        }
        OperatorCommandArg::Recall { target: t } => Request::Ready(OperatorAction::Recall { target: target(t)? }),
        OperatorCommandArg::Hold { target: t } => Request::Ready(OperatorAction::Hold { target: target(t)? }),
        OperatorCommandArg::Resume { target: t } => Request::Ready(OperatorAction::Resume { target: target(t)? }),
    })
}

/// `spomp operator`.
pub fn operator(args: &OperatorArgs, registry: &NodeRegistry<RobotRuntime>) -> Result<ExitCode> {
    let mut member = Member::join(args, registry)?;
    // Everything that can be checked without the robots is, before waiting for them.
    let request = request_of(args, &member.robots)?;
    let deadline = Instant::now() + Duration::from_secs_f64(args.wait_s);
    let caught_up = member.catch_up(deadline);
    if !caught_up && !args.json {
        let reached: Vec<String> = member.reached.iter().map(ToString::to_string).collect();
        errln!(
            "note: not in sync with every reachable robot after {:.0} s (reached: [{}])",
            args.wait_s,
            reached.join(", ")
        );
    }
    let action = match request {
        Request::Status => return Ok(status(&member, args.json)),
        Request::Ready(action) => action,
        Request::Cancel(goal) => {
            OperatorAction::CancelGoal { goal: resolve_goal(member.state.goals(), &member.mission_names, &goal)? }
        }
        Request::Priority(goal, priority) => OperatorAction::SetPriority {
            goal: resolve_goal(member.state.goals(), &member.mission_names, &goal)?,
            priority,
        },
    };
    let issued_at = member.team_time();
    let id = member.state.issue_command(action.clone(), issued_at).context("issuing the command")?;
    // A fresh deadline: the command deserves the whole wait whatever joining took.
    let deadline = Instant::now() + Duration::from_secs_f64(args.wait_s);
    let concerned: BTreeSet<RobotId> = member.robots.iter().filter(|r| action.concerns(r)).cloned().collect();
    member.sync_until(deadline, |m| {
        let reachable: BTreeSet<RobotId> = m.reachable().intersection(&concerned).cloned().collect();
        let view = m.state.command(&id);
        !reachable.is_empty() && reachable.iter().all(|r| view.as_ref().is_some_and(|v| v.acked_by(r)))
    });
    let outcome = outcome_of(&member, &id, &action, &concerned);
    let all_reached_acked = !outcome.acknowledged.is_empty() && outcome.not_acknowledged.is_empty();
    if args.json {
        out!("{}", serde_json::to_string_pretty(&outcome)?);
    } else {
        print_outcome(&outcome);
    }
    member.link.close();
    Ok(if all_reached_acked { ExitCode::SUCCESS } else { ExitCode::from(2) })
}

fn target_of(robots: &BTreeSet<RobotId>, text: &str) -> Result<CommandTarget> {
    let target = CommandTarget::parse(text);
    if let CommandTarget::Robot(r) = &target
        && !robots.contains(r)
    {
        let robots: Vec<String> = robots.iter().map(ToString::to_string).collect();
        bail!("`{text}` is no robot of the team ({}) nor `all`", robots.join(", "));
    }
    Ok(target)
}

fn outcome_of(member: &Member, id: &CommandId, action: &OperatorAction, concerned: &BTreeSet<RobotId>) -> Outcome {
    let view = member.state.command(id);
    let acknowledged: BTreeMap<String, f64> = view
        .as_ref()
        .map(|v| v.acked_by.iter().map(|(r, t)| (r.to_string(), t.as_secs_f64())).collect())
        .unwrap_or_default();
    let mut not_acknowledged = Vec::new();
    let mut not_reached = Vec::new();
    for r in concerned {
        if acknowledged.contains_key(r.as_str()) {
            continue;
        }
        if member.reached.contains(r) {
            not_acknowledged.push(r.to_string());
        } else {
            not_reached.push(r.to_string());
        }
    }
    Outcome {
        command: Some(action.to_string()),
        id: Some(id.to_string()),
        acknowledged,
        not_acknowledged,
        not_reached,
        heard: member.heard.iter().map(|(r, n)| (r.to_string(), *n)).collect(),
        refused: member.refused.clone(),
    }
}

fn print_outcome(o: &Outcome) {
    out!("{} ({})", o.command.as_deref().unwrap_or("?"), o.id.as_deref().unwrap_or("?"));
    let acked: Vec<String> = o.acknowledged.iter().map(|(r, t)| format!("{r} (at {t:.1} s)")).collect();
    out!("  acknowledged:     {}", if acked.is_empty() { "nobody".to_string() } else { acked.join(", ") });
    if !o.not_acknowledged.is_empty() {
        out!("  not acknowledged: {} (reachable, no acknowledgement in time)", o.not_acknowledged.join(", "));
    }
    if !o.not_reached.is_empty() {
        out!(
            "  not reached:      {} (they apply it when a teammate that holds it comes into range)",
            o.not_reached.join(", ")
        );
    }
    if o.acknowledged.is_empty() && o.not_acknowledged.is_empty() {
        out!("  no robot was reached: no robot holds the command; issue it again when one is in range");
    }
    for (kind, n) in &o.refused {
        out!("  refused {n} message(s): {kind}");
    }
}

/// What `status` prints.
#[derive(Serialize)]
struct Status<'a> {
    goals: &'a [GoalView],
    robots: Vec<RobotLine>,
    commands: Vec<CommandView>,
}

#[derive(Serialize)]
struct RobotLine {
    robot: String,
    /// Reachable from the operator now.
    reachable: bool,
    /// Its newest pose and the robot time it was measured at, as the team holds it.
    x_m: Option<f64>,
    y_m: Option<f64>,
    last_heard_s: Option<f64>,
    current_goal: Option<String>,
    /// `mission`, `hold` or `recall`, as the operator's commands held say.
    mode: &'static str,
}

fn status(member: &Member, json: bool) -> ExitCode {
    let reachable = member.reachable();
    let robots: Vec<RobotLine> = member
        .robots
        .iter()
        .map(|r| {
            let s = member.state.robot_status(r);
            RobotLine {
                robot: r.to_string(),
                reachable: reachable.contains(r),
                x_m: s.and_then(|s| s.pose).map(|p| p.x),
                y_m: s.and_then(|s| s.pose).map(|p| p.y),
                last_heard_s: s.map(|s| s.stamp.as_secs_f64()),
                current_goal: s.and_then(|s| s.current_goal.as_ref()).map(ToString::to_string),
                mode: member.state.operator_mode(r).mode.as_str(),
            }
        })
        .collect();
    let report = Status { goals: member.state.goals(), robots, commands: member.state.commands() };
    if json {
        match serde_json::to_string_pretty(&report) {
            Ok(text) => out!("{text}"),
            Err(e) => errln!("error: {e}"),
        }
    } else {
        print_status(&report);
    }
    if member.heard.is_empty() { ExitCode::from(2) } else { ExitCode::SUCCESS }
}

fn print_status(s: &Status<'_>) {
    out!("goals ({}):", s.goals.len());
    out!("  {:<22} {:<12} {:>8} {:>8} {:>4}  {:<10} {}", "id", "name", "x_m", "y_m", "prio", "status", "by");
    for g in s.goals {
        let (status, by) = if let Some(c) = &g.cancelled {
            ("cancelled", c.to_string())
        } else if let Some((t, r)) = &g.visited {
            ("visited", format!("{r} at {:.1} s", t.as_secs_f64()))
        } else if let Some(c) = &g.claimant {
            ("claimed", format!("{} since {:.1} s", c.robot, c.stamp.as_secs_f64()))
        } else {
            ("open", String::new())
        };
        out!(
            "  {:<22} {:<12} {:>8.1} {:>8.1} {:>4}  {:<10} {}",
            g.id.to_string(),
            g.name.as_deref().unwrap_or("-"),
            g.position.x,
            g.position.y,
            g.priority,
            status,
            by
        );
    }
    out!("robots:");
    out!("  {:<10} {:<9} {:>8} {:>8} {:>10}  {:<8} {}", "robot", "reachable", "x_m", "y_m", "heard_s", "mode", "goal");
    for r in &s.robots {
        let num = |v: Option<f64>| v.map_or("-".to_string(), |v| format!("{v:.1}"));
        out!(
            "  {:<10} {:<9} {:>8} {:>8} {:>10}  {:<8} {}",
            r.robot,
            if r.reachable { "yes" } else { "no" },
            num(r.x_m),
            num(r.y_m),
            num(r.last_heard_s),
            r.mode,
            r.current_goal.as_deref().unwrap_or("-")
        );
    }
    out!("commands ({}):", s.commands.len());
    for c in &s.commands {
        let acked: Vec<String> = c.acked_by.iter().map(|(r, _)| r.to_string()).collect();
        out!("  {:<22} {:<40} acknowledged by: {}", c.id.to_string(), c.command.action.to_string(), acked.join(", "));
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;
    use spomp_teamstate::TeamStateParams;

    /// A team state holding a mission goal and three operator goals, two of them named alike.
    fn team() -> TeamState {
        let mut s = TeamState::new(RobotId::new(OPERATOR_ID), u32::MAX, TeamStateParams::default()).unwrap();
        s.add_mission_goal(0, Point2::new(10.0, 10.0)).unwrap();
        for (x, name) in [(40.0, "east"), (80.0, "far"), (120.0, "far")] {
            let action = OperatorAction::AddGoal {
                position: Point2::new(x, 0.0),
                name: Some(name.into()),
                priority: 0,
                class: None,
            };
            s.issue_command(action, Time::ZERO).unwrap();
        }
        s
    }

    #[test]
    fn goals_are_found_by_name_or_id_and_an_ambiguous_or_unknown_name_says_what_there_is() {
        let s = team();
        let names = [("start".to_string(), GoalId { origin: RobotId::new("mission"), seq: 0 })];
        let resolve = |name: &str| resolve_goal(s.goals(), &names, name);
        assert_eq!(resolve("start").unwrap().to_string(), "mission/0");
        let east = resolve("east").unwrap();
        assert_eq!(s.goal(&east).unwrap().position, Point2::new(40.0, 0.0));
        assert_eq!(resolve("mission/0").unwrap().to_string(), "mission/0");
        assert_eq!(resolve(&east.to_string()).unwrap(), east);
        let err = resolve("far").unwrap_err().to_string();
        assert!(err.contains("2 goals are named `far`") && err.contains("give an id"), "{err}");
        let err = resolve("west").unwrap_err().to_string();
        assert!(err.contains("no goal named `west` among the 4") && err.contains("(east)"), "{err}");
        assert!(err.contains("mission/0 (start)"), "{err}");
        assert!(resolve_goal(&[], &[], "x").unwrap_err().to_string().ends_with("among the 0 the team knows"));
    }

    /// Regression: the operator's team state used the skill's default deconfliction radius
    /// (10 m), not the mission's, so two goals the robots keep apart were one goal to it.
    #[test]
    fn the_operator_groups_goals_with_the_missions_deconfliction_radius() {
        let text = "mission: radius\n\
             team:\n  - { id: ugv1, kind: ugv, role: idle, priority: 1, start: { x_m: 5, y_m: 5 } }\n\
             goals:\n  manual:\n    - { x_m: 50, y_m: 50, name: west }\n    - { x_m: 56, y_m: 50, name: east }\n\
             \x20 deconfliction_radius_m: 3\n\
             roles:\n  idle: { tree: { wait: { duration_s: 10 } } }\n\
             complete_when: time_limit\ntime_limit_s: 10\n";
        let loaded = spomp_behaviors::mission::load_mission_str(
            text,
            std::path::Path::new("radius.yaml"),
            &crate::registry(),
            &LoadOptions::default(),
        );
        assert!(loaded.is_valid(), "{:#?}", loaded.diagnostics);
        let mission = loaded.mission.as_ref().unwrap();
        let state = operator_state(mission).unwrap();
        assert_eq!(state.goals().len(), 2, "6 m apart with a 3 m radius: two goals, as the robots see them");
        let names = spomp_robot::setup::mission_goal_names(mission);
        assert_eq!(resolve_goal(state.goals(), &names, "east").unwrap().to_string(), "mission/1");
        // An operator goal 2 m from `east` is within the mission's radius: one goal with it.
        let mut state = state;
        let added = OperatorAction::AddGoal { position: Point2::new(58.0, 50.0), name: None, priority: 1, class: None };
        let id = state.issue_command(added, Time::ZERO).unwrap();
        assert_eq!(state.goal(&id.goal_id()).unwrap().id.to_string(), "mission/1");
        assert_eq!(state.goals().len(), 2);
    }

    #[test]
    fn a_target_must_be_a_robot_of_the_team_or_all() {
        let robots: BTreeSet<RobotId> = ["ugv1", "ugv2"].into_iter().map(RobotId::new).collect();
        assert_eq!(target_of(&robots, "all").unwrap(), CommandTarget::All);
        assert_eq!(target_of(&robots, "ugv2").unwrap(), CommandTarget::Robot(RobotId::new("ugv2")));
        let err = target_of(&robots, "ugv9").unwrap_err().to_string();
        assert!(err.contains("`ugv9` is no robot of the team (ugv1, ugv2) nor `all`"), "{err}");
    }
}
