//! A robot's operator orders are redone only when a command or an acknowledgement arrives
//! (`TeamState::operator_records_version`), not walked every tick: this checks that nothing is
//! missed that way — with 50 commands held and idle ticks in between, an acknowledgement that
//! arrives alone reaches the log, a command relayed by a teammate is applied and acknowledged
//! at the next tick, and a later one lifts it. (What the skip saves is measured by the
//! `operator_tick` bench.)

#![allow(clippy::unwrap_used, clippy::expect_used)] // tests fail loudly by design

use spomp_behaviors::Status;
use spomp_behaviors::mission::load_mission_str;
use spomp_core::{ClassTable, GridSpec, Odometry, Point2, Pose2, PoseEstimate, RobotId, Time};
use spomp_robot::operator_log::{OperatorEvent, OperatorLog};
use spomp_robot::{OperatingArea, Robot};
use spomp_teamstate::{CommandTarget, OPERATOR_ID, OperatorAction, OperatorMode, TeamState, TeamStateParams, TierSet};

const MISSION: &str = "mission: operator-orders\n\
    team:\n\
    \x20 - { id: ugv1, kind: ugv, role: r, priority: 1, start: { x_m: 5, y_m: 5 }, localization: { mode: ground_truth } }\n\
    \x20 - { id: ugv2, kind: ugv, role: r, priority: 2, start: { x_m: 9, y_m: 5 } }\n\
    roles:\n  r: { tree: { reactive_sequence: [ { inverter: { child: { operator_hold: } } }, { wait: { duration_s: 1e9 } } ] } }\n\
    complete_when: time_limit\ntime_limit_s: 100000\n";

fn t(s: f64) -> Time {
    Time::from_secs_f64(s)
}

fn ugv1() -> Robot {
    let registry = spomp_robot::registry();
    let loaded =
        load_mission_str(MISSION, std::path::Path::new("operator-orders.yaml"), &registry, &Default::default());
    assert!(loaded.is_valid(), "{:#?}", loaded.diagnostics);
    let area = OperatingArea::new(ClassTable::default_table(), GridSpec::new(Point2::new(0.0, 0.0), 0.5, 40, 40));
    let mut robot = Robot::from_mission(&loaded, "ugv1", &area, 1, &registry).unwrap();
    let pose = PoseEstimate { stamp: t(1.0), pose: Pose2::new(5.0, 5.0, 0.0), confidence: 1.0, ..Default::default() };
    robot.on_external_pose(t(1.0), pose);
    robot.on_odometry(t(1.0), Odometry { stamp: t(1.0), ..Default::default() });
    robot
}

fn deliver(from: &mut TeamState, robot: &mut Robot, now: Time) {
    if let Some(m) = from.make_sync(robot.id(), TierSet::ALL, usize::MAX) {
        robot.on_team_message(now, &from.self_id().clone(), m.encode()).unwrap();
    }
}

fn pass(from: &mut TeamState, to: &mut TeamState) {
    if let Some(m) = from.make_sync(to.self_id(), TierSet::ALL, usize::MAX) {
        to.apply_bytes(&from.self_id().clone(), &m.encode()).unwrap();
    }
}

fn acks(events: &[OperatorEvent], robot: &str) -> usize {
    events.iter().filter(|e| matches!(e, OperatorEvent::OperatorAcknowledged { robot: r, .. } if r == robot)).count()
}

#[test]
fn orders_redone_only_when_operator_records_arrive_miss_nothing() {
    let mut robot = ugv1();
    let mut op = TeamState::new(RobotId::new(OPERATOR_ID), u32::MAX, TeamStateParams::default()).unwrap();
    let mut ugv2 = TeamState::new(RobotId::new("ugv2"), 2, TeamStateParams::default()).unwrap();
    let mut log = OperatorLog::default();
    let mut now = 2.0;
    // Running until the tree sees a hold (then it fails: `inverter` over `operator_hold`).
    let mut tick = |robot: &mut Robot, n: usize| {
        for _ in 0..n {
            now += 0.1;
            robot.tick(t(now), None);
        }
        t(now)
    };
    for k in 0..50 {
        let position = Point2::new(100.0 + 30.0 * f64::from(k), 50.0);
        op.issue_command(OperatorAction::AddGoal { position, name: None, priority: 0, class: None }, t(1.0)).unwrap();
    }
    deliver(&mut op, &mut robot, t(1.5));
    let version = robot.team().operator_records_version();
    tick(&mut robot, 1);
    assert_eq!(robot.tree().status(), Status::Running);
    assert!(robot.team().operator_records_version() > version, "its own acknowledgements are records too");
    let events = log.poll(robot.team());
    assert_eq!((events.len(), acks(&events, "ugv1")), (100, 50), "50 heard, 50 acknowledged by ugv1");
    tick(&mut robot, 20);
    assert!(log.poll(robot.team()).is_empty(), "nothing new");
    assert_eq!(robot.tree().status(), Status::Running);

    // ugv2's acknowledgements arrive on their own (no new command): the log has them.
    pass(&mut op, &mut ugv2);
    for id in ugv2.commands_to_acknowledge() {
        ugv2.acknowledge(&id, t(3.0)).unwrap();
    }
    let at = tick(&mut robot, 1);
    deliver(&mut ugv2, &mut robot, at);
    tick(&mut robot, 1);
    assert_eq!(acks(&log.poll(robot.team()), "ugv2"), 50);

    // A hold relayed by ugv2 is applied and acknowledged at the next tick.
    let hold = op.issue_command(OperatorAction::Hold { target: CommandTarget::All }, t(9.0)).unwrap();
    pass(&mut op, &mut ugv2);
    let at = tick(&mut robot, 5);
    deliver(&mut ugv2, &mut robot, at);
    tick(&mut robot, 1);
    assert_eq!(robot.team().operator_mode(robot.id()).mode, OperatorMode::Hold);
    assert_eq!(robot.tree().status(), Status::Failure, "the tree saw the hold at that tick");
    assert!(robot.team().command(&hold).unwrap().acked_by(robot.id()));
    let events = log.poll(robot.team());
    assert_eq!((events.len(), acks(&events, "ugv1")), (2, 1), "{events:?}");

    // Idle ticks change nothing; a resume from the operator is applied at the next tick.
    tick(&mut robot, 20);
    assert!(log.poll(robot.team()).is_empty());
    let resume = op.issue_command(OperatorAction::Resume { target: CommandTarget::All }, t(12.0)).unwrap();
    let at = tick(&mut robot, 1);
    deliver(&mut op, &mut robot, at);
    tick(&mut robot, 1);
    assert!(robot.team().command(&resume).unwrap().acked_by(robot.id()));
    assert_eq!(robot.team().operator_mode(robot.id()).mode, OperatorMode::Mission);
}
