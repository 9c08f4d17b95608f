//! Merge rules of operator commands (issue 37), as properties over random command scripts
//! delivered in random orders with duplicates: the same commands give the same goals
//! (priorities, cancels) and robot modes whatever the order (idempotent, commutative); a
//! cancelled goal is never claimable and a claim on it is released on hearing the cancel; the
//! latest command by sequence number wins.
#![allow(clippy::unwrap_used)] // tests may unwrap

mod common;

use common::*;
use proptest::prelude::*;
use spomp_core::{GoalId, Point2};
use spomp_teamstate::{
    Ack, CommandTarget, OPERATOR_ID, OperatorAction, OperatorMode, Record, RecordKey, SyncMessage, TeamState,
};

const ROBOTS: [&str; 2] = ["ugv1", "ugv2"];

#[derive(Clone, Debug)]
enum Cmd {
    Add { x: u8, priority: i8 },
    Cancel { goal: usize },
    Priority { goal: usize, priority: i8 },
    Robot { kind: u8, target: usize },
}

fn cmd() -> impl Strategy<Value = Cmd> {
    prop_oneof![
        2 => (any::<u8>(), -2i8..3).prop_map(|(x, priority)| Cmd::Add { x, priority }),
        1 => any::<usize>().prop_map(|goal| Cmd::Cancel { goal }),
        1 => (any::<usize>(), -2i8..3).prop_map(|(goal, priority)| Cmd::Priority { goal, priority }),
        2 => (0u8..3, 0usize..3).prop_map(|(kind, target)| Cmd::Robot { kind, target }),
    ]
}

/// Four mission goals every robot loads, 30 m apart.
fn with_mission_goals(mut ts: TeamState) -> TeamState {
    for k in 0..4u32 {
        ts.add_mission_goal(k, Point2::new(30.0 * f64::from(k), 200.0)).unwrap();
    }
    ts
}

/// The operator's state after the script, and the mode the reference model expects per robot.
fn issue(script: &[Cmd]) -> (TeamState, Vec<OperatorMode>) {
    let mut op = with_mission_goals(robot(OPERATOR_ID, u32::MAX));
    let mut modes = vec![OperatorMode::Mission; ROBOTS.len()];
    for (k, c) in script.iter().enumerate() {
        let goals: Vec<GoalId> = op.goals().iter().map(|v| v.id.clone()).collect();
        let action = match c {
            Cmd::Add { x, priority } => OperatorAction::AddGoal {
                position: Point2::new(f64::from(*x) * 3.0, 0.0),
                name: None,
                priority: i32::from(*priority),
                class: None,
            },
            Cmd::Cancel { goal } => OperatorAction::CancelGoal { goal: goals[goal % goals.len()].clone() },
            Cmd::Priority { goal, priority } => {
                OperatorAction::SetPriority { goal: goals[goal % goals.len()].clone(), priority: i32::from(*priority) }
            }
            Cmd::Robot { kind, target } => {
                let t = match target {
                    0 | 1 => CommandTarget::Robot(id(ROBOTS[*target])),
                    _ => CommandTarget::All,
                };
                let mode = [OperatorMode::Hold, OperatorMode::Recall, OperatorMode::Mission][*kind as usize];
                for (r, m) in modes.iter_mut().enumerate() {
                    if t.includes(&id(ROBOTS[r])) {
                        *m = mode;
                    }
                }
                match kind {
                    0 => OperatorAction::Hold { target: t },
                    1 => OperatorAction::Recall { target: t },
                    _ => OperatorAction::Resume { target: t },
                }
            }
        };
        op.issue_command(action, t(k as f64)).unwrap();
    }
    (op, modes)
}

/// Delivers `records` from the operator one per message in the order given.
fn deliver(to: &mut TeamState, records: &[Record], seq: &mut u32) {
    for r in records {
        *seq += 1;
        let msg = SyncMessage {
            from: id(OPERATOR_ID),
            to: to.self_id().clone(),
            seq: *seq,
            ack: Ack::default(),
            peer_has_all: false,
            wants_ack: true,
            records: vec![r.clone()],
            session: 0,
            signature: None,
        };
        to.apply_bytes(&id(OPERATOR_ID), &msg.encode()).unwrap();
    }
}

/// What the commands derive, for comparing two states.
fn derived(ts: &TeamState) -> Vec<(GoalId, i32, bool)> {
    ts.goals().iter().map(|v| (v.id.clone(), v.priority, v.cancelled.is_some())).collect()
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(96))]

    #[test]
    fn commands_converge_in_any_order_and_the_latest_wins(
        script in prop::collection::vec(cmd(), 1..24),
        order_a in Just(()).prop_perturb(|_, mut rng| rng.random::<u64>()),
        order_b in Just(()).prop_perturb(|_, mut rng| rng.random::<u64>()),
        claim_first in any::<usize>(),
    ) {
        let (op, modes) = issue(&script);
        let commands: Vec<Record> =
            op.records().filter(|r| matches!(r.key, RecordKey::Command(_))).cloned().collect();
        // Two orders, each with every record delivered twice at random places.
        let shuffled = |seed: u64| {
            let mut all: Vec<Record> = commands.iter().chain(&commands).cloned().collect();
            let mut s = seed | 1;
            for i in (1..all.len()).rev() {
                s ^= s << 13; s ^= s >> 7; s ^= s << 17;
                all.swap(i, (s % (i as u64 + 1)) as usize);
            }
            all
        };
        let mut a = with_mission_goals(robot("ugv1", 1));
        let mut b = with_mission_goals(robot("ugv2", 2));
        // ugv1 claims a mission goal first: if that goal ends cancelled, the claim is gone.
        let first = a.goals()[claim_first % 4].id.clone();
        a.claim(&first, t(0.0)).unwrap();
        let (mut sa, mut sb) = (0, 0);
        deliver(&mut a, &shuffled(order_a), &mut sa);
        deliver(&mut b, &shuffled(order_b), &mut sb);
        prop_assert_eq!(derived(&a), derived(&op));
        prop_assert_eq!(derived(&b), derived(&op));
        for (r, name) in ROBOTS.iter().enumerate() {
            prop_assert_eq!(a.operator_mode(&id(name)).mode, modes[r]);
            prop_assert_eq!(b.operator_mode(&id(name)).mode, modes[r]);
            prop_assert_eq!(op.operator_mode(&id(name)).mode, modes[r]);
        }
        let cancelled = a.goal(&first).unwrap().cancelled.is_some();
        prop_assert_eq!(a.goal(&first).unwrap().is_held_by(&id("ugv1")), !cancelled);
        for ts in [&a, &b] {
            let claimable = ts.claimable_goals_for(ts.self_id(), Point2::new(0.0, 0.0));
            prop_assert!(claimable.iter().all(|v| v.cancelled.is_none()));
            // Most urgent first.
            prop_assert!(claimable.windows(2).all(|w| w[0].priority >= w[1].priority));
        }
        // Each robot acknowledges every goal command and the robot commands addressing it.
        let due = a.commands_to_acknowledge();
        for c in op.commands() {
            prop_assert_eq!(due.contains(&c.id), c.command.action.concerns(&id("ugv1")));
        }
    }
}

/// The operator takes the coordination tier only (goals, claims, poses, commands,
/// acknowledgements), whatever the link allows: a robot's scans and map versions are never sent
/// to it, never wait for it (the robot's pending set for it does not grow with them), and the
/// sync between them still completes. Robots still send each other everything. Regression: a
/// robot sent the operator every tier while it was reachable.
#[test]
fn an_operator_is_sent_coordination_records_only_and_its_sync_completes() {
    use spomp_core::Pose2;
    use spomp_teamstate::{GoalOrigin, Tier, TierSet};
    let mut ugv1 = robot("ugv1", 1);
    let mut ugv2 = robot("ugv2", 2);
    let mut op = robot(OPERATOR_ID, u32::MAX);
    ugv1.identify_goal(Point2::new(40.0, 0.0), GoalOrigin::Detected, t(1.0)).unwrap();
    ugv1.set_pose(Pose2::new(1.0, 2.0, 0.0), t(1.0)).unwrap();
    for k in 0..3 {
        assert!(ugv1.add_scan(scan("ugv1", 5.0 * f64::from(k), 0.0, 2.0 + f64::from(k))).unwrap());
    }
    ugv1.add_map_version(1, t(3.0), vec![7; 1000]).unwrap();
    let msg = ugv1.make_sync(&id(OPERATOR_ID), TierSet::ALL, usize::MAX).unwrap();
    assert!(!msg.records.is_empty());
    assert!(
        msg.records.iter().all(|r| r.tier() == Tier::Coordination),
        "{:?}",
        msg.records.iter().map(|r| r.key.clone()).collect::<Vec<_>>()
    );
    op.apply_bytes(&id("ugv1"), &msg.encode()).unwrap();
    sync_fully(&mut ugv1, &mut op);
    assert!(op.scans_since(0).0.is_empty() && op.newest_map().is_none(), "no scans, no maps at the operator");
    assert_eq!(op.goals().len(), 1);
    assert!(op.robot_pose(&id("ugv1")).is_some());
    assert!(ugv1.sync_complete_with(&id(OPERATOR_ID)), "complete without the tiers the operator does not take");
    assert!(op.sync_complete_with(&id("ugv1")));
    // More scans: nothing for the operator, and nothing kept waiting for it.
    let before = ugv1.table_sizes();
    for k in 3..6 {
        assert!(ugv1.add_scan(scan("ugv1", 5.0 * f64::from(k), 0.0, 10.0 + f64::from(k))).unwrap());
    }
    assert!(ugv1.make_sync(&id(OPERATOR_ID), TierSet::ALL, usize::MAX).is_none_or(|m| m.records.is_empty()));
    assert_eq!(ugv1.table_sizes().peer_entries, before.peer_entries);
    assert!(ugv1.sync_complete_with(&id(OPERATOR_ID)));
    // A robot is sent every tier.
    sync_fully(&mut ugv1, &mut ugv2);
    assert_eq!(ugv2.scans_since(0).0.len(), 6);
    assert!(ugv2.newest_map().is_some());
}
