//! Goal coordination between two UGVs through their replicated team states: concurrent claims
//! resolve by priority, a preempted robot releases without marking the goal unreachable and
//! takes the next one, a failed goal is marked unreachable for that robot only, and clearing
//! the marks makes it claimable again.

#![allow(clippy::unwrap_used, clippy::expect_used)] // tests fail loudly by design

use std::io::Write;

use spomp_behaviors::mission::{BuildOptions, build_executor, load_mission};
use spomp_behaviors::{BbValue, Status, TreeExecutor};
use spomp_core::{GoalId, Point2, Pose2, PoseEstimate, RobotId, RobotKind, Time};
use spomp_robot::RobotRuntime;
use spomp_robot::registry as builtin_registry;
use spomp_robot::runtime::DrivenRuntime;
use spomp_robot::runtime::RuntimeConfig;
use spomp_teamstate::{TeamStateParams, TierSet};

/// Claim, "drive" (a wait guarded by goal_still_mine), mark visited; on failure release.
const MISSION: &str = r#"
mission: coordination
team:
  - { id: ugv1, kind: ugv, role: visitor, priority: 1, start: { x_m: 0, y_m: 0 } }
  - { id: ugv2, kind: ugv, role: visitor, priority: 2, start: { x_m: 5, y_m: 0 } }
roles:
  visitor:
    blackboard: { drive_s: 5 }
    tree:
      repeat:
        child:
          fallback:
            - sequence:
                - claim_goal: { goal: "{goal}", goal_position: "{goal_position}" }
                - fallback:
                    - reactive_sequence:
                        - goal_still_mine: { goal: "{goal}" }
                        - wait: { duration_s: "{drive_s}" }
                    - force_failure: { child: { release_goal: { goal: "{goal}" } } }
                - mark_visited: { goal: "{goal}" }
            - succeed:
complete_when: all_goals_visited
time_limit_s: 100
"#;

struct Robot {
    rt: DrivenRuntime,
    ex: TreeExecutor<RobotRuntime>,
}

fn robots() -> (Robot, Robot) {
    let dir = std::env::temp_dir().join(format!("spomp-coord-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("coordination.yaml");
    std::fs::File::create(&path).unwrap().write_all(MISSION.as_bytes()).unwrap();
    let registry = builtin_registry();
    let loaded = load_mission(&path, &registry);
    assert!(loaded.diagnostics.is_empty(), "{:#?}", loaded.diagnostics);
    let role = &loaded.roles["visitor"];
    let make = |id: &str, priority: u32, x: f64| {
        let start = Pose2::new(x, 0.0, 0.0);
        let mut rt: DrivenRuntime =
            RobotRuntime::new(RobotId::new(id), RobotKind::Ugv, priority, start, TeamStateParams::default())
                .unwrap()
                .into();
        rt.on_external_pose(PoseEstimate { pose: start, confidence: 1.0, ..Default::default() });
        // Operator goals: A near both robots, B farther away.
        rt.team_state_mut().add_mission_goal(0, Point2::new(10.0, 0.0)).unwrap();
        rt.team_state_mut().add_mission_goal(1, Point2::new(60.0, 0.0)).unwrap();
        let ex = build_executor(role, &registry, rt.id(), start, BuildOptions::default()).unwrap();
        Robot { rt, ex }
    };
    (make("ugv1", 1, 0.0), make("ugv2", 2, 5.0))
}

fn tick(r: &mut Robot, t: Time) -> Status {
    r.ex.tick(t, &mut r.rt, None)
}

/// A full exchange both ways, as robots in radio contact would do.
fn exchange(a: &mut Robot, b: &mut Robot) {
    for _ in 0..3 {
        if let Some(m) = a.rt.team_state_mut().make_sync(b.rt.id(), TierSet::ALL, usize::MAX) {
            b.rt.team_state_mut().apply(a.rt.id(), &m).unwrap();
        }
        if let Some(m) = b.rt.team_state_mut().make_sync(a.rt.id(), TierSet::ALL, usize::MAX) {
            a.rt.team_state_mut().apply(b.rt.id(), &m).unwrap();
        }
    }
}

fn held_goal(r: &Robot) -> Option<GoalId> {
    match r.ex.blackboard().get_by_name("goal") {
        Some(BbValue::Goal(g)) => Some(g.clone()),
        _ => None,
    }
}

fn goal_at(r: &Robot, x: f64) -> GoalId {
    r.rt.team().goals().iter().find(|g| (g.position.x - x).abs() < 1e-9).unwrap().id.clone()
}

#[test]
fn concurrent_claims_resolve_by_priority_and_the_loser_moves_on() {
    let (mut u1, mut u2) = robots();
    let a = goal_at(&u1, 10.0);
    let b = goal_at(&u1, 60.0);
    // Out of contact, both claim the nearest goal.
    assert_eq!(tick(&mut u1, Time::ZERO), Status::Running);
    assert_eq!(tick(&mut u2, Time::ZERO), Status::Running);
    assert_eq!(held_goal(&u1), Some(a.clone()));
    assert_eq!(held_goal(&u2), Some(a.clone()));

    // They meet: the higher-priority claim wins at both.
    exchange(&mut u1, &mut u2);
    for r in [&u1, &u2] {
        let view = r.rt.team().goal(&a).unwrap();
        assert!(view.is_held_by(u1.rt.id()), "{} sees {:?}", r.rt.id(), view.claimant);
    }

    // ugv2 notices at its next tick, releases A (not unreachable: it was preempted) and claims B.
    let t = Time::from_millis(100);
    tick(&mut u1, t);
    tick(&mut u2, t);
    tick(&mut u2, Time::from_millis(200));
    assert_eq!(held_goal(&u2), Some(b.clone()));
    assert!(!u2.rt.team().goal(&a).unwrap().is_unreachable_for(u2.rt.id()));
    assert!(u2.rt.team().goal(&b).unwrap().is_held_by(u2.rt.id()));

    // Both arrive after their 5 s drives and mark their goals visited; the team agrees.
    for i in 3..=80 {
        let t = Time::from_millis(100 * i);
        tick(&mut u1, t);
        tick(&mut u2, t);
    }
    exchange(&mut u1, &mut u2);
    for r in [&u1, &u2] {
        assert_eq!(r.rt.team().goal(&a).unwrap().visited.as_ref().map(|v| v.1.clone()), Some(u1.rt.id().clone()));
        assert_eq!(r.rt.team().goal(&b).unwrap().visited.as_ref().map(|v| v.1.clone()), Some(u2.rt.id().clone()));
        assert!(r.rt.team().all_goals_visited());
    }
}

#[test]
fn failure_marks_unreachable_for_that_robot_only_until_cleared() {
    let (mut u1, mut u2) = robots();
    let a = goal_at(&u1, 10.0);
    // ugv1 claims A, then "fails" to reach it: release with the unreachable mark.
    tick(&mut u1, Time::ZERO);
    assert_eq!(held_goal(&u1), Some(a.clone()));
    u1.rt.team_mut().release(&a, Time::from_millis(50)).unwrap();
    u1.rt.team_mut().mark_unreachable(&a, Time::from_millis(50)).unwrap();
    let claimable: Vec<GoalId> =
        u1.rt.team().claimable_goals_for(u1.rt.id(), Point2::new(0.0, 0.0)).iter().map(|g| g.id.clone()).collect();
    assert!(!claimable.contains(&a), "A is unreachable for ugv1");
    exchange(&mut u1, &mut u2);
    let for_u2: Vec<GoalId> =
        u2.rt.team().claimable_goals_for(u2.rt.id(), Point2::new(5.0, 0.0)).iter().map(|g| g.id.clone()).collect();
    assert_eq!(for_u2.first(), Some(&a), "another robot may still try A");

    // Nothing else left for ugv1 would make it retry: clear_unreachable through the node.
    let registry = builtin_registry();
    let ports = spomp_behaviors::registry::PortBindings::declared(registry.get("clear_unreachable").unwrap());
    let mut node = (registry.factory("clear_unreachable").unwrap())(&ports).unwrap();
    let mut bb = spomp_behaviors::Blackboard::new();
    let mut ctx = spomp_behaviors::TickContext {
        now: Time::from_millis(60),
        tick: 1,
        blackboard: &mut bb,
        env: u1.rt.runtime_mut(),
        observer: None,
    };
    assert_eq!(node.tick(Status::Idle, &mut ctx), Status::Success);
    assert!(!u1.rt.team().goal(&a).unwrap().is_unreachable_for(u1.rt.id()));
}

mod detection {
    use super::*;
    use spomp_behaviors::{Blackboard, TickContext};
    use spomp_core::{AerialMap, GridSpec};
    use spomp_mapping::{CompressionParams, GoalDetectionParams, encode_layers};

    /// 100 m × 50 m of road with two rows of three parked cars, 50 m apart.
    fn parking_map() -> AerialMap {
        let spec = GridSpec::new(Point2::new(0.0, 0.0), 0.5, 200, 100);
        let mut map = AerialMap::unknown(spec);
        for i in 0..spec.len() {
            map.class[i] = 0;
            map.rgb[i] = [128, 64, 128];
            map.elevation[i] = 0.0;
        }
        for x0 in [20.0, 70.0] {
            for car in 0..3 {
                let cx = x0 + car as f64 * 5.5;
                for col in (cx / 0.5) as u32..((cx + 4.5) / 0.5) as u32 {
                    for row in 40..44 {
                        let i = spec.index(spomp_core::Cell::new(col, row));
                        map.class[i] = 4;
                        map.rgb[i] = [0, 0, 142];
                        map.elevation[i] = 1.5;
                    }
                }
            }
        }
        map.version = 1;
        map
    }

    fn detecting_runtime(id: &str, spec: GridSpec) -> spomp_robot::runtime::DrivenRuntime {
        let config = RuntimeConfig::basic(RobotId::new(id), RobotKind::Ugv, 1, Pose2::default())
            .with_detection(GoalDetectionParams::default())
            .with_map_spec(spec);
        RobotRuntime::from_config(config).unwrap().into()
    }

    /// Ticks a fresh `detect_goals` node once and returns (status, new_goals, reports).
    fn detect(rt: &mut RobotRuntime, t: Time) -> (Status, Option<i64>, Vec<String>) {
        let registry = builtin_registry();
        let mut bb = Blackboard::new();
        let key = bb.declare("new", spomp_behaviors::PortType::Int);
        let mut ports = spomp_behaviors::registry::PortBindings::declared(registry.get("detect_goals").unwrap());
        ports.insert("new_goals", spomp_behaviors::Binding::Entry(key));
        let mut node = (registry.factory("detect_goals").unwrap())(&ports).unwrap();
        let mut ctx = TickContext { now: t, tick: 1, blackboard: &mut bb, env: rt, observer: None };
        let status = node.tick(Status::Idle, &mut ctx);
        let n = match bb.get(key) {
            Some(BbValue::Int(n)) => Some(*n),
            _ => None,
        };
        (status, n, bb.take_reports())
    }

    #[test]
    fn goals_detected_from_a_shared_map_are_not_duplicated_by_a_second_robot() {
        let map = parking_map();
        let blob = encode_layers(&map, &CompressionParams::default()).unwrap().to_bytes();
        let mut a = detecting_runtime("ugv1", map.spec);
        let mut b = detecting_runtime("ugv2", map.spec);
        // No map yet: one pass, nothing found, no error.
        assert_eq!(detect(&mut a, Time::ZERO), (Status::Success, Some(0), vec![]));

        a.team_state_mut().add_map_version(map.version, Time::ZERO, blob).unwrap();
        let (status, n, reports) = detect(&mut a, Time::from_millis(100));
        assert_eq!((status, n), (Status::Success, Some(2)), "{reports:?}");
        let xs: Vec<f64> = a.team().goals().iter().map(|g| g.position.x).collect();
        assert!(xs.iter().any(|x| (15.0..40.0).contains(x)) && xs.iter().any(|x| (65.0..90.0).contains(x)), "{xs:?}");
        assert_eq!(detect(&mut a, Time::from_millis(200)).1, Some(0), "same map version: no second pass");

        // ugv2 receives the goals and the map through the team state, detects the same clusters,
        // and adds nothing.
        for _ in 0..3 {
            if let Some(m) = a.team_state_mut().make_sync(b.id(), TierSet::ALL, usize::MAX) {
                b.team_state_mut().apply(a.id(), &m).unwrap();
            }
            if let Some(m) = b.team_state_mut().make_sync(a.id(), TierSet::ALL, usize::MAX) {
                a.team_state_mut().apply(b.id(), &m).unwrap();
            }
        }
        assert_eq!(b.team().goals().len(), 2);
        let (status, n, reports) = detect(&mut b, Time::from_millis(300));
        assert_eq!((status, n), (Status::Success, Some(0)), "{reports:?}");
        assert!(b.map().is_some_and(|m| m.map().known_cells() == map.spec.len()));
        assert_eq!(b.team().goals().len(), 2);
    }

    #[test]
    fn a_corrupt_map_version_is_reported_and_changes_nothing() {
        let spec = GridSpec::new(Point2::new(0.0, 0.0), 0.5, 200, 100);
        let mut a = detecting_runtime("ugv1", spec);
        a.team_state_mut().add_map_version(1, Time::ZERO, vec![1, 2, 3, 4]).unwrap();
        let (status, n, reports) = detect(&mut a, Time::from_millis(100));
        assert_eq!((status, n), (Status::Success, Some(0)));
        assert!(reports.iter().any(|r| r.contains("unusable")), "{reports:?}");
        assert!(a.team().goals().is_empty());
    }
}
