//! The robot layer's checks of a mission (the mission language's `RobotChecks`): every robot
//! is set up as [`crate::RobotSetup`] will set it up, and each parameter is checked by its
//! skill's own `validate()`; problems point at the mission field the value came from.

use std::collections::{BTreeMap, BTreeSet};

use serde_json::Value;
use spomp_behaviors::mission::MissionFile;
use spomp_behaviors::mission::{RobotChecks, RobotProblem};
use spomp_core::RobotKind;
use spomp_mapping::{GoalDetectionParams, MappingError};
use spomp_teamstate::TeamStateError;

use crate::settings::NavigationSettings;
use crate::setup::team_params;

/// [`RobotChecks`] of this robot layer.
#[derive(Clone, Copy, Debug, Default)]
pub struct MissionRobotChecks;

fn path(segs: &[&str]) -> Vec<String> {
    segs.iter().map(|s| s.to_string()).collect()
}

impl RobotChecks for MissionRobotChecks {
    fn navigation_schema(&self) -> Value {
        NavigationSettings::json_schema()
    }

    fn check(&self, mission: &MissionFile) -> Vec<RobotProblem> {
        let mut problems = Vec::new();
        if let Err(e) = team_params(mission).validate() {
            let (field, message) = match e {
                TeamStateError::InvalidParams { name, reason } => (name, reason.to_string()),
                other => ("", other.to_string()),
            };
            problems.push(RobotProblem { path: path(&["goals", field]), message });
        }
        if let Some(d) = mission.goals.as_ref().and_then(|g| g.detect.as_ref()) {
            let defaults = GoalDetectionParams::default();
            let params = GoalDetectionParams {
                class: d.class.clone(),
                merge_distance_m: d.merge_distance_m.unwrap_or(defaults.merge_distance_m),
                min_size_m: d.min_size_m.unwrap_or(defaults.min_size_m),
                placement_region_m: d.placement_region_m.unwrap_or(defaults.placement_region_m),
                ..defaults
            };
            if let Err(MappingError::InvalidParams { name, reason }) = params.validate() {
                problems.push(RobotProblem { path: path(&["goals", "detect", name]), message: reason });
            }
        }
        for (i, robot) in mission.team.iter().enumerate() {
            let role_layer = mission.roles.get(&robot.role).and_then(|r| r.navigation.as_ref());
            let robot_layer = robot.navigation.as_ref();
            if robot.kind != RobotKind::Ugv {
                if robot_layer.is_some() {
                    problems.push(RobotProblem {
                        path: vec!["team".into(), i.to_string(), "navigation".into()],
                        message: format!("only UGVs navigate; `{}` is a {}", robot.id, robot.kind.as_str()),
                    });
                }
                continue;
            }
            let layers: Vec<&Value> = role_layer.into_iter().chain(robot_layer).collect();
            if let Err(e) = NavigationSettings::resolve(&layers) {
                // The layer the value came from: the role's is layer 0 when it has one.
                let from_robot = match e.layer {
                    Some(l) => role_layer.is_none() || l == 1,
                    None => robot_layer.is_some(),
                };
                let mut at = if from_robot {
                    vec!["team".to_string(), i.to_string(), "navigation".to_string()]
                } else {
                    vec!["roles".to_string(), robot.role.clone(), "navigation".to_string()]
                };
                at.extend(e.path.iter().cloned());
                let message = format!("{} (robot `{}`)", e.message, robot.id);
                if !problems.iter().any(|p: &RobotProblem| p.path == at) {
                    problems.push(RobotProblem { path: at, message });
                }
            }
        }
        problems.extend(operator_script_problems(mission));
        problems
    }

    fn warnings(&self, mission: &MissionFile, role_nodes: &BTreeMap<String, BTreeSet<String>>) -> Vec<RobotProblem> {
        roles_ignoring_the_operator(mission, role_nodes)
    }
}

/// `sim.operator` entries checked against the team (issue 37).
fn operator_script_problems(mission: &MissionFile) -> Vec<RobotProblem> {
    let robots: Vec<&str> = mission.team.iter().map(|r| r.id.as_str()).collect();
    let Some(sim) = &mission.sim else { return Vec::new() };
    let mut problems = Vec::new();
    for (i, entry) in sim.operator.iter().enumerate() {
        if let Err((field, message)) = entry.check(&robots) {
            let mut at = vec!["sim".to_string(), "operator".to_string(), i.to_string()];
            if !field.is_empty() {
                at.push(field);
            }
            problems.push(RobotProblem { path: at, message });
        }
    }
    if let Some(r) = mission.team.iter().position(|r| r.id == spomp_teamstate::OPERATOR_ID) {
        problems.push(RobotProblem {
            path: path(&["team", &r.to_string(), "id"]),
            message: format!("`{}` is reserved for the team's operator", spomp_teamstate::OPERATOR_ID),
        });
    }
    problems
}

/// In a mission with an operator in the loop (`sim.operator` entries or a robot's
/// `team_link`), roles of UGVs and UAVs whose tree (its subtrees expanded) has no
/// `operator_hold` or no `operator_recall` node: such a robot still stops when held (the command output's floor), but
/// a held mission's nodes keep running (a drive may time out) and a recall is not obeyed.
fn roles_ignoring_the_operator(
    mission: &MissionFile,
    role_nodes: &BTreeMap<String, BTreeSet<String>>,
) -> Vec<RobotProblem> {
    // Only where the mission file shows an operator in the loop: scripted commands, or a team
    // link (which `spomp operator` joins). Elsewhere nothing can issue a command.
    let scripted = mission.sim.as_ref().is_some_and(|s| !s.operator.is_empty());
    if !scripted && mission.team.iter().all(|r| r.team_link.is_none()) {
        return Vec::new();
    }
    let mut warnings = Vec::new();
    let mut done = BTreeSet::new();
    for robot in &mission.team {
        if !matches!(robot.kind, RobotKind::Ugv | RobotKind::Uav) || !done.insert(robot.role.clone()) {
            continue;
        }
        let Some(names) = role_nodes.get(&robot.role) else { continue };
        let missing: Vec<&str> = crate::nodes::OPERATOR_NODES.iter().copied().filter(|n| !names.contains(*n)).collect();
        if !missing.is_empty() {
            warnings.push(RobotProblem {
                path: path(&["roles", &robot.role, "tree"]),
                message: format!(
                    "role `{}` ignores the operator: no {} node (a held robot still stops, but its mission keeps running; see docs/missions.md, \"The operator\")",
                    robot.role,
                    missing.iter().map(|n| format!("`{n}`")).collect::<Vec<_>>().join(" or ")
                ),
            });
        }
    }
    warnings
}
