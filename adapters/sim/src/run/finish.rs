//! The end of a run: every tree halted and the summary of what happened.

use super::*;

/// Seconds from the first to the last second of a once-a-second trajectory in which the robot
/// moved at least 5 cm (see [`RobotSummary::travel_time_s`]).
fn travel_time_s(trajectory: &[Point2]) -> Option<f64> {
    const STILL_M: f64 = 0.05;
    let moved = |k: &usize| trajectory[*k].distance(trajectory[*k - 1]) >= STILL_M;
    let first = (1..trajectory.len()).find(moved)?;
    let last = (1..trajectory.len()).rev().find(moved)?;
    Some((last - first + 1) as f64)
}

impl Simulation {
    pub(super) fn finish(mut self, _observer: &mut dyn SimObserver, wall_s: f64) -> RunResult {
        let end_s = self.now.as_secs_f64();
        // Each tree's status at the end of the run, before the halt that stops it.
        let final_status: Vec<String> = self
            .robots
            .iter()
            .map(|r| match self.drivers.as_ref().filter(|_| r.external).and_then(|d| d.tree_status(&r.id)) {
                Some(status) => status,
                None => format!("{:?}", r.robot.tree().status()).to_lowercase(),
            })
            .collect();
        if let Some(d) = self.drivers.as_mut() {
            d.end_run();
        }
        for r in &mut self.robots {
            if r.alive() {
                r.robot.halt(self.now);
            }
        }
        let goals = self.merged_goals();
        let robots = self
            .robots
            .iter()
            .enumerate()
            .map(|(i, r)| {
                let visited_goals: Vec<&GoalSummary> =
                    goals.iter().filter(|g| g.visited_by.as_deref() == Some(r.id.as_str())).collect();
                let heading: f64 = r
                    .claim_time_s
                    .iter()
                    .filter(|(g, _)| visited_goals.iter().any(|v| v.id == g.to_string()))
                    .fold(0.0, |acc, (_, t)| acc + t);
                let (distance_m, collisions) = match &r.body {
                    Body::Ugv { ugv, .. } => (ugv.distance_m(), ugv.collisions()),
                    Body::Uav { uav, .. } => (uav.distance_m(), 0),
                    Body::Fixed { .. } => (0.0, 0),
                };
                RobotSummary {
                    id: r.id.to_string(),
                    kind: r.kind.to_string(),
                    distance_m,
                    heading_to_goal_fraction: if end_s > 0.0 { heading / end_s } else { 0.0 },
                    travel_time_s: travel_time_s(&r.trajectory),
                    collisions,
                    stuck_events: r.stuck_events,
                    longest_motionless_driving_s: r.longest_still_driving_s,
                    localization: match r.kind {
                        RobotKind::Ugv => r.pose_input.name().to_string(),
                        RobotKind::Uav => "gps".to_string(),
                        RobotKind::Basestation => "surveyed".to_string(),
                    },
                    localization_error_m: ErrorStats::of(&r.localization_errors),
                    goals_visited: visited_goals.len() as u32,
                    killed_s: r.killed_s,
                    tree_status: final_status.get(i).cloned().unwrap_or_default(),
                    navigation: r.robot.nav_params().map(|p| NavigationInForce {
                        learning: p.global.learning.enabled,
                        graph_updates: p.global.experience.graph_updates,
                        sharing: match p.global.sharing.mode {
                            spomp_global_planner::SharingMode::None => "none",
                            spomp_global_planner::SharingMode::Downsampled => "downsampled",
                            spomp_global_planner::SharingMode::All => "all",
                        }
                        .to_string(),
                        slope_threshold: p.local.terrain.slope_threshold,
                        inflation_m: p.local.terrain.inflation_m,
                        max_speed_mps: p.local.dwa.max_speed_mps,
                        stuck_timeout_s: p.watchdog.stuck_timeout_s,
                    }),
                }
            })
            .collect();
        let nodes_total = self.robots.iter().map(|r| r.ticked.len()).sum();
        let nodes_exercised = self.robots.iter().map(|r| r.ticked.iter().filter(|t| **t).count()).sum();
        let nodes_never_ticked = self
            .robots
            .iter()
            .flat_map(|r| {
                r.ticked.iter().zip(&r.node_paths).filter(|(t, _)| !**t).map(move |(_, p)| format!("{}: {p}", r.id))
            })
            .collect();
        let operator = self.operator_summary();
        if let Some(op) = self.operator.as_ref().filter(|op| op.never_issued() > 0) {
            let message = format!(
                "operator: {} scripted command(s) never issued (due after the end, or their goal never became known to the operator)",
                op.never_issued()
            );
            note_problem(&mut self.problems, &op.id, message, self.now);
        }
        let summary = RunSummary {
            mission: self.mission.mission.clone(),
            seed: self.options.seed,
            outcome: self.outcome.unwrap_or(Outcome::TimeLimit),
            end_s,
            time_limit_s: self.time_limit.as_secs_f64(),
            navigation: "skills (global planner graph + panorama local planner)".to_string(),
            goals_visited: goals.iter().filter(|g| g.visited_s.is_some()).count(),
            clusters: self.cluster_summary(&goals),
            goals,
            robots,
            wall_s,
            speedup: if wall_s > 0.0 { end_s / wall_s } else { 0.0 },
            nodes_exercised,
            nodes_total,
            nodes_never_ticked,
            problems: self.problems.into_values().collect(),
            operator,
            operator_link: self.operator.as_ref().map(|op| op.traffic),
        };
        let localization_errors = self
            .robots
            .iter()
            .filter(|r| r.kind == RobotKind::Ugv)
            .map(|r| (r.id.clone(), r.localization_error_series.clone()))
            .collect();
        let team_traffic = self.robots.iter().map(|r| (r.id.clone(), r.robot.team_traffic())).collect();
        let trajectories = self.robots.into_iter().map(|r| (r.id, r.kind, r.trajectory)).collect();
        RunResult { summary, world: self.world, trajectories, localization_errors, team_traffic }
    }
}
