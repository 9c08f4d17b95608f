//! The shipped goal cycle (`missions/subtrees/goal-cycle.yaml`) run on one UGV: with nothing
//! claimable the robot heads home, but a goal that becomes claimable on the way is claimed at
//! once instead of after the whole trip home and the wait (issue 19: five UGVs spent a third
//! of a run driving home between goals).

#![allow(clippy::unwrap_used, clippy::expect_used)] // tests fail loudly by design

use std::path::PathBuf;

use spomp_behaviors::mission::{BuildOptions, build_executor, load_mission};
use spomp_behaviors::{BbValue, Status, TreeExecutor};
use spomp_core::{GoalId, Point2, Pose2, PoseEstimate, RobotId, RobotKind, Time};
use spomp_robot::RobotRuntime;
use spomp_robot::registry as builtin_registry;
use spomp_robot::runtime::DrivenRuntime;
use spomp_teamstate::TeamStateParams;

/// The shipped subtrees, as the missions include them.
const GOAL_CYCLE: &str = include_str!("../../missions/subtrees/goal-cycle.yaml");

/// The visitor role of `missions/visit-all-vehicle-clusters.yaml`.
const MISSION: &str = r#"
mission: goal-cycle
include: [subtrees/goal-cycle.yaml]
team:
  - { id: ugv1, kind: ugv, role: visitor, priority: 1, start: { x_m: 0, y_m: 0 } }
roles:
  visitor:
    tree:
      repeat:
        child:
          fallback:
            - sequence:
                - detect_goals:
                - subtree: claim_and_visit
            - subtree: nothing_left
            - succeed:
complete_when: all_goals_visited
time_limit_s: 600
"#;

struct Robot {
    rt: DrivenRuntime,
    ex: TreeExecutor<RobotRuntime>,
}

/// One UGV whose home is the origin, 60 m away from it, with no goal known.
fn robot_away_from_home(folder: &str) -> Robot {
    let dir: PathBuf = std::env::temp_dir().join(format!("spomp-goal-cycle-{folder}-{}", std::process::id()));
    std::fs::create_dir_all(dir.join("subtrees")).unwrap();
    std::fs::write(dir.join("subtrees/goal-cycle.yaml"), GOAL_CYCLE).unwrap();
    let path = dir.join("mission.yaml");
    std::fs::write(&path, MISSION).unwrap();
    let registry = builtin_registry();
    let loaded = load_mission(&path, &registry);
    assert!(loaded.diagnostics.is_empty(), "{:#?}", loaded.diagnostics);
    let home = Pose2::new(0.0, 0.0, 0.0);
    let mut rt: DrivenRuntime =
        RobotRuntime::new(RobotId::new("ugv1"), RobotKind::Ugv, 1, home, TeamStateParams::default()).unwrap().into();
    rt.on_external_pose(PoseEstimate { pose: Pose2::new(60.0, 0.0, 0.0), confidence: 1.0, ..Default::default() });
    let ex = build_executor(&loaded.roles["visitor"], &registry, rt.id(), home, BuildOptions::default()).unwrap();
    Robot { rt, ex }
}

fn held_goal(r: &Robot) -> Option<GoalId> {
    match r.ex.blackboard().get_by_name("goal") {
        Some(BbValue::Goal(g)) => Some(g.clone()),
        _ => None,
    }
}

/// Ticks at 10 Hz over `[from_ms, to_ms)`.
fn run(r: &mut Robot, from_ms: i64, to_ms: i64) -> Status {
    let mut status = Status::Running;
    for ms in (from_ms..to_ms).step_by(100) {
        status = r.ex.tick(Time::from_millis(ms), &mut r.rt, None);
    }
    status
}

#[test]
fn a_goal_found_while_heading_home_is_claimed_at_once() {
    let mut r = robot_away_from_home("claim-on-the-way");
    // Nothing to claim: the robot is on its way home (no map, no panoramas: it does not move,
    // and the stuck watchdog is far off).
    assert_eq!(run(&mut r, 0, 2_000), Status::Running);
    assert_eq!(held_goal(&r), None);
    assert!(r.rt.team().goals().is_empty());

    // A teammate's goal arrives (here written straight into the team state).
    let goal = r.rt.team_state_mut().add_mission_goal(0, Point2::new(80.0, 0.0)).unwrap();
    run(&mut r, 2_000, 2_300);
    // `claim_goal` wrote it: the trip home was abandoned within a few ticks (before, the robot
    // drove all the way home and waited 10 s first). What follows the claim is not looked at:
    // this runtime has no navigation stack, so the drive itself fails.
    assert_eq!(held_goal(&r), Some(goal), "the trip home is abandoned for the new goal");
}

#[test]
fn with_nothing_to_claim_the_robot_keeps_heading_home() {
    let mut r = robot_away_from_home("keep-going");
    let goal = r.rt.team_state_mut().add_mission_goal(0, Point2::new(80.0, 0.0)).unwrap();
    // The only goal failed for this robot: it is not claimable until the robot has been home
    // and waited, so the robot keeps going home and does not take it.
    r.rt.team_mut().mark_unreachable(&goal, Time::ZERO).unwrap();
    assert_eq!(run(&mut r, 0, 3_000), Status::Running);
    assert_eq!(held_goal(&r), None);
    assert!(!r.rt.team().goal(&goal).unwrap().is_held_by(r.rt.id()));
}
