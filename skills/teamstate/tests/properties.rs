//! Property tests over random operations and random partition / delivery schedules.
#![allow(clippy::unwrap_used)] // tests and benchmarks may unwrap

mod common;

use std::collections::BTreeSet;

use common::*;
use proptest::prelude::*;
use spomp_core::{GoalId, Point2, Pose2};
use spomp_teamstate::{GoalOrigin, SyncMessage, TeamState, Tier, TierSet};

const NAMES: [&str; 3] = ["ugv1", "ugv2", "uav"];

#[derive(Clone, Debug)]
enum Op {
    Identify {
        robot: usize,
        x: u8,
        y: u8,
    },
    Claim {
        robot: usize,
        goal: usize,
    },
    Release {
        robot: usize,
        goal: usize,
    },
    Visit {
        robot: usize,
        goal: usize,
    },
    Unreachable {
        robot: usize,
        goal: usize,
    },
    ClearUnreachable {
        robot: usize,
    },
    Pose {
        robot: usize,
        x: u8,
    },
    Scan {
        robot: usize,
        x: u8,
    },
    Map {
        robot: usize,
        len: u16,
    },
    /// Make a message; `budget` 0 = unlimited; `coord_only` = a position-only link.
    Send {
        from: usize,
        to: usize,
        budget: u16,
        coord_only: bool,
    },
    Deliver {
        pick: usize,
    },
    Duplicate {
        pick: usize,
    },
    Drop {
        pick: usize,
    },
}

fn op() -> impl Strategy<Value = Op> {
    let r = 0..3usize;
    let ugv = 0..2usize;
    prop_oneof![
        2 => (r.clone(), any::<u8>(), any::<u8>()).prop_map(|(robot, x, y)| Op::Identify { robot, x, y }),
        2 => (ugv.clone(), any::<usize>()).prop_map(|(robot, goal)| Op::Claim { robot, goal }),
        1 => (ugv.clone(), any::<usize>()).prop_map(|(robot, goal)| Op::Release { robot, goal }),
        1 => (ugv.clone(), any::<usize>()).prop_map(|(robot, goal)| Op::Visit { robot, goal }),
        1 => (ugv.clone(), any::<usize>()).prop_map(|(robot, goal)| Op::Unreachable { robot, goal }),
        1 => ugv.clone().prop_map(|robot| Op::ClearUnreachable { robot }),
        3 => (r.clone(), any::<u8>()).prop_map(|(robot, x)| Op::Pose { robot, x }),
        1 => (ugv.clone(), any::<u8>()).prop_map(|(robot, x)| Op::Scan { robot, x }),
        1 => (2..3usize, 1..600u16).prop_map(|(robot, len)| Op::Map { robot, len }),
        6 => (r.clone(), r.clone(), prop_oneof![Just(0u16), 200..2000u16], any::<bool>())
            .prop_map(|(from, to, budget, coord_only)| Op::Send { from, to, budget, coord_only }),
        5 => any::<usize>().prop_map(|pick| Op::Deliver { pick }),
        2 => any::<usize>().prop_map(|pick| Op::Duplicate { pick }),
        1 => any::<usize>().prop_map(|pick| Op::Drop { pick }),
    ]
}

struct World {
    robots: Vec<TeamState>,
    /// Messages on the air: (from, to, bytes).
    air: Vec<(usize, usize, Vec<u8>)>,
    now: f64,
    /// Goal ids each robot has ever known; visited ones.
    known: Vec<BTreeSet<GoalId>>,
    visited: Vec<BTreeSet<GoalId>>,
    /// The last pose each robot set (oracle for "newest wins").
    last_pose: Vec<Option<(Pose2, spomp_core::Time)>>,
}

impl World {
    fn new() -> Self {
        World {
            robots: vec![robot("ugv1", 1), robot("ugv2", 2), robot("uav", 9)],
            air: Vec::new(),
            now: 0.0,
            known: vec![BTreeSet::new(); 3],
            visited: vec![BTreeSet::new(); 3],
            last_pose: vec![None; 3],
        }
    }

    fn pick_goal(&self, robot: usize, pick: usize) -> Option<GoalId> {
        let goals = self.robots[robot].goals();
        if goals.is_empty() { None } else { Some(goals[pick % goals.len()].id.clone()) }
    }

    /// Invariants that hold at every step, for robot `i`.
    fn check(&mut self, i: usize) {
        let ts = &self.robots[i];
        for g in &self.known[i] {
            assert!(ts.goal(g).is_some(), "{} lost goal {g}", NAMES[i]);
        }
        for g in &self.visited[i] {
            assert!(ts.goal(g).unwrap().visited.is_some(), "{} un-visited {g}", NAMES[i]);
        }
        for v in ts.goals() {
            self.known[i].insert(v.id.clone());
            self.known[i].extend(v.aliases.iter().cloned());
            if v.visited.is_some() {
                self.visited[i].insert(v.id.clone());
            }
        }
    }

    fn run(&mut self, op: &Op) {
        self.now += 1.0;
        let at = t(self.now);
        match *op {
            Op::Identify { robot, x, y } => {
                let p = Point2::new(x as f64, y as f64);
                self.robots[robot].identify_goal(p, GoalOrigin::Detected, at).unwrap();
            }
            Op::Claim { robot, goal } => {
                if let Some(g) = self.pick_goal(robot, goal) {
                    let _ = self.robots[robot].claim(&g, at);
                }
            }
            Op::Release { robot, goal } => {
                if let Some(g) = self.pick_goal(robot, goal) {
                    self.robots[robot].release(&g, at).unwrap();
                }
            }
            Op::Visit { robot, goal } => {
                if let Some(g) = self.pick_goal(robot, goal) {
                    self.robots[robot].mark_visited(&g, at).unwrap();
                }
            }
            Op::Unreachable { robot, goal } => {
                if let Some(g) = self.pick_goal(robot, goal) {
                    self.robots[robot].mark_unreachable(&g, at).unwrap();
                }
            }
            Op::ClearUnreachable { robot } => self.robots[robot].clear_unreachable(),
            Op::Pose { robot, x } => {
                let pose = Pose2::new(x as f64, 0.0, 0.0);
                self.robots[robot].set_pose(pose, at).unwrap();
                self.last_pose[robot] = Some((pose, at));
            }
            Op::Scan { robot, x } => {
                let s = scan(NAMES[robot], x as f64 * 3.0, 0.0, self.now);
                self.robots[robot].add_scan(s).unwrap();
            }
            Op::Map { robot, len } => {
                let v = self.now as u64;
                self.robots[robot].add_map_version(v, at, vec![(v % 251) as u8; len as usize]).unwrap();
            }
            Op::Send { from, to, budget, coord_only } => {
                if from != to {
                    let tiers = if coord_only { TierSet::up_to(Tier::Coordination) } else { TierSet::ALL };
                    let budget = if budget == 0 { usize::MAX } else { budget as usize };
                    let peer = self.robots[to].self_id().clone();
                    if let Some(m) = self.robots[from].make_sync(&peer, tiers, budget) {
                        let bytes = m.encode();
                        assert!(bytes.len() <= budget);
                        self.air.push((from, to, bytes));
                    }
                }
            }
            Op::Deliver { pick } | Op::Duplicate { pick } => {
                if !self.air.is_empty() {
                    let k = pick % self.air.len();
                    let (from, to, bytes) =
                        if matches!(op, Op::Deliver { .. }) { self.air.remove(k) } else { self.air[k].clone() };
                    let sender = self.robots[from].self_id().clone();
                    self.robots[to].apply_bytes(&sender, &bytes).unwrap();
                    self.check(to);
                }
            }
            Op::Drop { pick } => {
                if !self.air.is_empty() {
                    let k = pick % self.air.len();
                    self.air.remove(k);
                }
            }
        }
        for i in 0..3 {
            self.check(i);
        }
    }

    /// Reliable pairwise exchange over all pairs until nobody has anything to say.
    fn sync_all(&mut self) {
        for _ in 0..30 {
            let mut any = false;
            for a in 0..3 {
                for b in 0..3 {
                    if a == b {
                        continue;
                    }
                    let peer = self.robots[b].self_id().clone();
                    if let Some(m) = self.robots[a].make_sync(&peer, TierSet::ALL, usize::MAX) {
                        any = true;
                        let sender = self.robots[a].self_id().clone();
                        self.robots[b].apply_bytes(&sender, &m.encode()).unwrap();
                    }
                }
            }
            for i in 0..3 {
                self.check(i);
            }
            if !any {
                return;
            }
        }
        panic!("sync did not quiesce");
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 128, ..ProptestConfig::default() })]

    /// Random operations under random partitions, loss, duplication and reordering: goals are
    /// never lost, visits never undone (checked at every step); after everyone syncs fully, all
    /// hold identical records and at most one claim per goal, and every sync reports complete.
    #[test]
    fn replicas_converge_under_any_schedule(ops in prop::collection::vec(op(), 1..120)) {
        let mut w = World::new();
        for op in &ops {
            w.run(op);
        }
        w.sync_all();
        for i in 1..3 {
            prop_assert!(w.robots[0].same_records(&w.robots[i]));
            prop_assert_eq!(w.robots[0].goals(), w.robots[i].goals());
        }
        for (k, last) in w.last_pose.iter().enumerate() {
            for ts in &w.robots {
                prop_assert_eq!(ts.robot_pose(&id(NAMES[k])), *last, "pose of {} at {}", NAMES[k], ts.self_id());
            }
        }
        for v in w.robots[0].goals() {
            prop_assert!(v.claims.len() <= 1, "goal {} claimed by {:?}", v.id, v.claims);
        }
        let union: BTreeSet<GoalId> = w.known.iter().flatten().cloned().collect();
        for g in &union {
            prop_assert!(w.robots[0].goal(g).is_some(), "goal {} lost", g);
        }
        for a in 0..3 {
            for b in 0..3 {
                if a != b {
                    let peer = w.robots[b].self_id().clone();
                    prop_assert!(w.robots[a].sync_complete_with(&peer));
                }
            }
        }
    }

    /// Both UGVs claim goals concurrently; after one exchange each way, no goal is held by two
    /// robots (each robot's own view of whether it holds a goal is what drives it).
    #[test]
    fn one_round_settles_claims(
        goals in prop::collection::vec((0..200u8, 0..200u8), 1..6),
        picks in prop::collection::vec((0..2usize, any::<usize>()), 1..6),
    ) {
        let mut w = World::new();
        for (k, (x, y)) in goals.iter().enumerate() {
            w.robots[k % 3].identify_goal(Point2::new(*x as f64, *y as f64), GoalOrigin::Detected, t(k as f64)).unwrap();
        }
        w.sync_all();
        for (robot, pick) in &picks {
            if let Some(g) = w.pick_goal(*robot, *pick) {
                let _ = w.robots[*robot].claim(&g, t(100.0));
            }
        }
        let m01 = w.robots[0].make_sync(&id("ugv2"), TierSet::ALL, usize::MAX);
        let m10 = w.robots[1].make_sync(&id("ugv1"), TierSet::ALL, usize::MAX);
        if let Some(m) = m01 { w.robots[1].apply(&id("ugv1"), &m).unwrap(); }
        if let Some(m) = m10 { w.robots[0].apply(&id("ugv2"), &m).unwrap(); }
        for v in w.robots[0].goals() {
            let holders = (0..2)
                .filter(|&r| {
                    let me = w.robots[r].self_id().clone();
                    w.robots[r].goal(&v.id).is_some_and(|own| own.claims.iter().any(|c| c.robot == me))
                })
                .count();
            prop_assert!(holders <= 1, "goal {} held by {} robots", v.id, holders);
        }
    }

    /// Arbitrary bytes never panic and never change the state.
    #[test]
    fn garbage_bytes_are_harmless(bytes in prop::collection::vec(any::<u8>(), 0..400), prefix in any::<bool>()) {
        let mut w = World::new();
        w.robots[0].identify_goal(Point2::new(1.0, 1.0), GoalOrigin::Detected, t(1.0)).unwrap();
        let mut input = if prefix { b"SPTS\x01".to_vec() } else { Vec::new() };
        input.extend_from_slice(&bytes);
        let before: Vec<_> = w.robots[1].records().cloned().collect();
        if w.robots[1].apply_bytes(&id("ugv1"), &input).is_err() {
            let after: Vec<_> = w.robots[1].records().cloned().collect();
            prop_assert_eq!(before, after);
        }
    }

    /// Valid messages with random bytes flipped either apply cleanly or are rejected without a
    /// change.
    #[test]
    fn corrupted_messages_are_harmless(flips in prop::collection::vec((any::<usize>(), any::<u8>()), 1..8)) {
        let mut w = World::new();
        w.robots[0].identify_goal(Point2::new(1.0, 1.0), GoalOrigin::Detected, t(1.0)).unwrap();
        w.robots[0].add_scan(scan("ugv1", 0.0, 0.0, 1.0)).unwrap();
        w.robots[0].set_pose(Pose2::new(1.0, 2.0, 3.0), t(1.0)).unwrap();
        let m: SyncMessage = w.robots[0].make_sync(&id("ugv2"), TierSet::ALL, usize::MAX).unwrap();
        let mut bytes = m.encode();
        for (pos, val) in flips {
            let n = bytes.len();
            bytes[pos % n] ^= val | 1;
        }
        let before: Vec<_> = w.robots[1].records().cloned().collect();
        if w.robots[1].apply_bytes(&id("ugv1"), &bytes).is_err() {
            let after: Vec<_> = w.robots[1].records().cloned().collect();
            prop_assert_eq!(before, after);
        }
    }
}

/// Regression (found by `replicas_converge_under_any_schedule` in CI): the first message each
/// way — each carrying its sender's "you have all" — is lost and nothing happens afterwards.
/// The flag used to go out only when it changed, so neither robot said anything again and
/// "sync complete" stayed false; now a flag is repeated until acknowledged.
#[test]
fn sync_completes_after_the_first_messages_both_ways_are_lost() {
    let mut w = World::new();
    w.run(&Op::Send { from: 1, to: 0, budget: 0, coord_only: false });
    w.run(&Op::Send { from: 0, to: 1, budget: 0, coord_only: false });
    assert_eq!(w.air.len(), 2, "both robots had something to say");
    w.run(&Op::Drop { pick: 0 });
    w.run(&Op::Drop { pick: 0 });
    w.sync_all();
    for a in 0..3 {
        for b in 0..3 {
            if a != b {
                let peer = w.robots[b].self_id().clone();
                assert!(w.robots[a].sync_complete_with(&peer), "{a} with {b}");
            }
        }
    }
}
