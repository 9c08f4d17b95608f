//! A robot's tick once operator commands exist (issue 37's follow-up): a UGV whose team state
//! holds 50 operator commands and 150 acknowledgements (its own and two teammates' of each), and
//! nothing new arrives. What the tick costs beyond the tree is what the operator's commands add
//! to it: the robot's orders and acknowledgements, and a robot log's poll of them
//! (`OperatorLog::poll`, each state publish in `spomp run`). Both are redone only when a command
//! or acknowledgement arrives, so this tick costs what a tick without commands does.
//!
//! `cargo bench -p spomp-robot --bench operator_tick` prints the wall time per tick (a rough
//! figure on a shared machine). Instruction counts, stable under load: `SPOMP_TICKS=N` runs N
//! ticks and exits; run it under `valgrind --tool=callgrind` for two N and divide the
//! difference of the totals by the difference of N (`robot/README.md` has the figures).

#![allow(clippy::unwrap_used, clippy::expect_used)] // a bench fails loudly

use std::hint::black_box;
use std::time::Instant;

use spomp_behaviors::mission::load_mission_str;
use spomp_core::{ClassTable, GridSpec, Odometry, Point2, Pose2, PoseEstimate, RobotId, Time};
use spomp_robot::operator_log::OperatorLog;
use spomp_robot::{OperatingArea, Robot};
use spomp_teamstate::{CommandTarget, OPERATOR_ID, OperatorAction, TeamState, TeamStateParams, TierSet};

const MISSION: &str = "mission: operator-tick\n\
    team:\n\
    \x20 - { id: ugv1, kind: ugv, role: r, priority: 1, start: { x_m: 5, y_m: 5 }, localization: { mode: ground_truth } }\n\
    \x20 - { id: ugv2, kind: ugv, role: r, priority: 2, start: { x_m: 9, y_m: 5 } }\n\
    \x20 - { id: ugv3, kind: ugv, role: r, priority: 3, start: { x_m: 13, y_m: 5 } }\n\
    roles:\n  r: { tree: { reactive_sequence: [ { inverter: { child: { operator_hold: } } }, { wait: { duration_s: 1e9 } } ] } }\n\
    complete_when: time_limit\ntime_limit_s: 100000\n";

/// Commands held (`SPOMP_COMMANDS=N` for another count; 0 gives the tick without commands).
fn commands() -> usize {
    std::env::var("SPOMP_COMMANDS").ok().and_then(|v| v.parse().ok()).unwrap_or(50)
}

fn t(s: f64) -> Time {
    Time::from_secs_f64(s)
}

/// Sends everything `from` has for `to`'s team state.
fn send(from: &mut TeamState, to: &mut TeamState) {
    if let Some(m) = from.make_sync(to.self_id(), TierSet::ALL, usize::MAX) {
        to.apply_bytes(&from.self_id().clone(), &m.encode()).unwrap();
    }
}

/// ugv1 as a robot, holding `commands` commands and the acknowledgements of all three UGVs.
fn robot(commands: usize) -> Robot {
    let registry = spomp_robot::registry();
    let loaded = load_mission_str(MISSION, std::path::Path::new("operator-tick.yaml"), &registry, &Default::default());
    assert!(loaded.is_valid(), "{:#?}", loaded.diagnostics);
    let area = OperatingArea::new(ClassTable::default_table(), GridSpec::new(Point2::new(0.0, 0.0), 0.5, 40, 40));
    let mut robot = Robot::from_mission(&loaded, "ugv1", &area, 1, &registry).unwrap();
    let mut op = TeamState::new(RobotId::new(OPERATOR_ID), u32::MAX, TeamStateParams::default()).unwrap();
    for k in 0..commands {
        let action = match k % 5 {
            0 => OperatorAction::Hold { target: CommandTarget::All },
            1 => OperatorAction::Resume { target: CommandTarget::All },
            _ => OperatorAction::AddGoal {
                position: Point2::new(100.0 + 30.0 * k as f64, 50.0),
                name: None,
                priority: (k % 3) as i32,
                class: None,
            },
        };
        op.issue_command(action, t(k as f64)).unwrap();
    }
    // Two teammates hear and acknowledge every command.
    let mut mates: Vec<TeamState> = ["ugv2", "ugv3"]
        .into_iter()
        .enumerate()
        .map(|(k, id)| TeamState::new(RobotId::new(id), k as u32 + 2, TeamStateParams::default()).unwrap())
        .collect();
    for mate in &mut mates {
        send(&mut op, mate);
        for id in mate.commands_to_acknowledge() {
            mate.acknowledge(&id, t(60.0)).unwrap();
        }
    }
    let to = robot.id().clone();
    let now = t(61.0);
    for from in std::iter::once(&mut op).chain(mates.iter_mut()) {
        if let Some(m) = from.make_sync(&to, TierSet::ALL, usize::MAX) {
            robot.on_team_message(now, &from.self_id().clone(), m.encode()).unwrap();
        }
    }
    let pose = PoseEstimate { stamp: now, pose: Pose2::new(5.0, 5.0, 0.0), confidence: 1.0, ..Default::default() };
    robot.on_external_pose(now, pose);
    robot.on_odometry(now, Odometry { stamp: now, ..Default::default() });
    // The first tick applies and acknowledges them all.
    robot.tick(now, None);
    let held = robot.team().commands();
    assert_eq!(held.len(), commands);
    assert_eq!(held.iter().map(|c| c.acked_by.len()).sum::<usize>(), 3 * commands, "each acknowledged by 3 robots");
    assert_eq!(robot.tree().status(), spomp_behaviors::Status::Running, "the tree runs");
    robot
}

fn main() {
    let commands = commands();
    let mut robot = robot(commands);
    let mut log = OperatorLog::default();
    let mut now = 62.0;
    black_box(log.poll(robot.team()));
    let mut step = |robot: &mut Robot, log: &mut OperatorLog| {
        now += 0.1;
        black_box(robot.tick(t(now), None));
        black_box(log.poll(robot.team()));
    };
    if let Some(n) = std::env::var("SPOMP_TICKS").ok().and_then(|v| v.parse::<u64>().ok()) {
        for _ in 0..n {
            step(&mut robot, &mut log);
        }
        return;
    }
    // `cargo bench` passes `--bench`; a plain run (`cargo test --benches`) just checks it runs.
    let n = if std::env::args().any(|a| a == "--bench") { 200_000 } else { 10 };
    let start = Instant::now();
    for _ in 0..n {
        step(&mut robot, &mut log);
    }
    let per = start.elapsed().as_secs_f64() / n as f64;
    println!(
        "operator_tick: {n} ticks of a robot holding {commands} commands and {} acks: {:.2} µs per tick (tick + log poll)",
        3 * commands,
        per * 1e6
    );
}
