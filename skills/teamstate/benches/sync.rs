//! make_sync + encode + decode + apply on a realistic team state: 50 goals, 6 robots, 500
#![allow(clippy::unwrap_used)] // tests and benchmarks may unwrap
//! reachability scans of 1024 bins, one 300 kB map.

use criterion::{BatchSize, Criterion, criterion_group, criterion_main};
use spomp_core::{Point2, Pose2, ReachabilityScan, RobotId, Time};
use spomp_teamstate::{GoalOrigin, TeamState, TeamStateParams, TierSet};

const ROBOTS: [&str; 6] = ["ugv1", "ugv2", "ugv3", "ugv4", "ugv5", "uav"];

fn realistic_team() -> (TeamState, TeamState) {
    let mut states: Vec<TeamState> = ROBOTS
        .iter()
        .enumerate()
        .map(|(i, r)| TeamState::new(RobotId::new(r), i as u32, TeamStateParams::default()).unwrap())
        .collect();
    for (i, ts) in states.iter_mut().enumerate() {
        let t = Time::from_secs_f64(i as f64);
        ts.set_pose(Pose2::new(i as f64 * 10.0, 0.0, 0.0), t).unwrap();
        // 50 goals in all, spread over the robots, 25 m apart.
        for k in 0..50 {
            if k % ROBOTS.len() == i {
                let p = Point2::new((k % 10) as f64 * 25.0, (k / 10) as f64 * 25.0);
                ts.identify_goal(p, GoalOrigin::Detected, t).unwrap();
            }
        }
        // 100 scans per UGV, 3 m apart.
        if i < 5 {
            for k in 0..100 {
                let scan = ReachabilityScan {
                    robot: RobotId::new(ROBOTS[i]),
                    stamp: Time::from_secs_f64(k as f64),
                    pose: Pose2::new(k as f64 * 3.0, i as f64 * 50.0, 0.0),
                    range_m: (0..1024).map(|b| 2.0 + (b % 37) as f32 * 0.25).collect(),
                    obstacle: (0..1024).map(|b| b % 5 == 0).collect(),
                };
                ts.add_scan(scan).unwrap();
            }
        } else {
            ts.add_map_version(1, t, (0..300_000u32).map(|b| (b * 7 % 251) as u8).collect()).unwrap();
        }
    }
    // Gather everything at ugv1 through pairwise syncs.
    let (first, rest) = states.split_at_mut(1);
    for other in rest.iter_mut() {
        for _ in 0..4 {
            if let Some(m) = other.make_sync(first[0].self_id(), TierSet::ALL, usize::MAX) {
                first[0].apply(&other.self_id().clone(), &m).unwrap();
            }
            if let Some(m) = first[0].make_sync(other.self_id(), TierSet::ALL, usize::MAX) {
                other.apply(&first[0].self_id().clone(), &m).unwrap();
            }
        }
    }
    let full = states.swap_remove(0);
    let fresh = TeamState::new(RobotId::new("ugv9"), 9, TeamStateParams::default()).unwrap();
    (full, fresh)
}

fn bench(c: &mut Criterion) {
    let (full, fresh) = realistic_team();
    assert_eq!(full.goals().len(), 50);
    assert_eq!(full.scan_count(), 500);
    let peer = fresh.self_id().clone();
    let me = full.self_id().clone();

    c.bench_function("full sync to a new peer (make_sync+encode+decode+apply)", |b| {
        b.iter_batched(
            || (full.clone(), fresh.clone()),
            |(mut a, mut p)| {
                let m = a.make_sync(&peer, TierSet::ALL, usize::MAX).unwrap();
                let bytes = m.encode();
                p.apply_bytes(&me, &bytes).unwrap();
                bytes.len()
            },
            BatchSize::LargeInput,
        )
    });

    c.bench_function("tier 0 only, 16 kB budget, to a new peer", |b| {
        b.iter_batched(
            || (full.clone(), fresh.clone()),
            |(mut a, mut p)| {
                let m = a.make_sync(&peer, TierSet::only(spomp_teamstate::Tier::Coordination), 16 * 1024).unwrap();
                p.apply_bytes(&me, &m.encode()).unwrap();
            },
            BatchSize::LargeInput,
        )
    });

    // Steady state between synced robots: one pose update, one message each way.
    let (mut a, mut p) = (full.clone(), fresh.clone());
    for _ in 0..4 {
        if let Some(m) = a.make_sync(&peer, TierSet::ALL, usize::MAX) {
            p.apply(&me, &m).unwrap();
        }
        if let Some(m) = p.make_sync(&me, TierSet::ALL, usize::MAX) {
            a.apply(&peer, &m).unwrap();
        }
    }
    let mut tick = 0i64;
    c.bench_function("steady state: pose update + round trip", |b| {
        b.iter(|| {
            tick += 1;
            a.set_pose(Pose2::new(tick as f64 * 0.01, 0.0, 0.0), Time::from_millis(10_000 + tick)).unwrap();
            let m = a.make_sync(&peer, TierSet::ALL, usize::MAX).unwrap();
            p.apply_bytes(&me, &m.encode()).unwrap();
            if let Some(back) = p.make_sync(&me, TierSet::ALL, usize::MAX) {
                a.apply_bytes(&peer, &back.encode()).unwrap();
            }
        })
    });
    let m = full.clone().make_sync(&peer, TierSet::ALL, usize::MAX).unwrap();
    eprintln!("full-state message: {} records, {} bytes", m.records.len(), m.encode().len());
}

criterion_group!(benches, bench);
criterion_main!(benches);
