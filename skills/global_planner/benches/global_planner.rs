//! Benchmarks against the brief's bars (one core): graph construction on a 400 m × 300 m city
//! (800×600 cells) ≤ 1 s and on 1750×2000 cells ≤ 5 s, a path query ≤ 1 ms, a training round
//! plus edge reweighting ≤ 20 ms.

use std::hint::black_box;

use criterion::{Criterion, criterion_group, criterion_main};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use spomp_core::{AerialMap, ClassTable, MapTile, Point2, Pose2, Time};
use spomp_global_planner::synthetic::{self, CityLayout};
use spomp_global_planner::{GlobalPlanner, GlobalPlannerParams, TrainOutcome, forget_shared_routes};

/// CPU time of this thread so far, seconds (user + system, from /proc; 10 ms resolution). The
/// machine is shared, so wall-clock figures are inflated; CPU time is what one core spends.
fn thread_cpu_s() -> f64 {
    let stat = std::fs::read_to_string("/proc/thread-self/stat").unwrap_or_default();
    let after = stat.rsplit(')').next().unwrap_or("");
    let fields: Vec<&str> = after.split_whitespace().collect();
    let tick = |k: usize| fields.get(k).and_then(|v| v.parse::<f64>().ok()).unwrap_or(f64::NAN);
    // After the command name: state is field 0, utime 11, stime 12 (clock ticks of 1/100 s).
    (tick(11) + tick(12)) / 100.0
}

fn cpu_per_iteration(label: &str, iterations: usize, mut f: impl FnMut()) {
    let t0 = thread_cpu_s();
    for _ in 0..iterations {
        f();
    }
    eprintln!("{label}: {:.2} ms CPU per iteration", (thread_cpu_s() - t0) * 1e3 / iterations as f64);
}

fn build(width: u32, height: u32) -> GlobalPlanner {
    let map = synthetic::city_map(width, height, CityLayout::default(), 1);
    let mut p = GlobalPlanner::new(GlobalPlannerParams::default(), ClassTable::default_table()).expect("params");
    p.update_map(&map).expect("map");
    p
}

fn construction(c: &mut Criterion) {
    let mut g = c.benchmark_group("construction");
    g.sample_size(10);
    for (w, h) in [(800u32, 600u32), (1750, 2000)] {
        let map = synthetic::city_map(w, h, CityLayout::default(), 1);
        let p = build(w, h);
        eprintln!("{w}×{h}: {:?}", p.graph_stats());
        // Routes around steps are remembered process-wide (a team's robots search each once):
        // the plain figure is a planner on its own, every route searched; `_routes_known` is
        // the next robot of a team on the same map.
        cpu_per_iteration(&format!("update_map_{w}x{h}"), if w > 1000 { 3 } else { 10 }, || {
            forget_shared_routes();
            black_box(build(w, h));
        });
        let fresh_planner_on = |map: &AerialMap| {
            let mut p =
                GlobalPlanner::new(GlobalPlannerParams::default(), ClassTable::default_table()).expect("params");
            p.update_map(black_box(map)).expect("map");
            p
        };
        g.bench_function(format!("update_map_{w}x{h}"), |b| {
            b.iter(|| {
                forget_shared_routes();
                fresh_planner_on(&map)
            })
        });
        g.bench_function(format!("update_map_{w}x{h}_routes_known"), |b| b.iter(|| fresh_planner_on(&map)));
    }
    g.finish();
}

/// Map growth on the large map: half known, then 200×200-cell tiles revealed one at a time.
fn growth(c: &mut Criterion) {
    let full = synthetic::city_map(1750, 2000, CityLayout::default(), 1);
    let mut map = AerialMap::unknown(full.spec);
    let tile = |col0: u32, row0: u32, width: u32, height: u32| {
        let cells = (row0..row0 + height).flat_map(|r| (col0..col0 + width).map(move |c| (r * 1750 + c) as usize));
        let idx: Vec<usize> = cells.collect();
        MapTile {
            col0,
            row0,
            width,
            height,
            class: idx.iter().map(|&i| full.class[i]).collect(),
            rgb: idx.iter().map(|&i| full.rgb[i]).collect(),
            elevation: idx.iter().map(|&i| full.elevation[i]).collect(),
        }
    };
    map.apply_tile(&tile(0, 0, 875, 2000));
    let mut p = GlobalPlanner::new(GlobalPlannerParams::default(), ClassTable::default_table()).expect("params");
    p.update_map(&map).expect("map");
    let tiles: Vec<MapTile> =
        (0..8).flat_map(|k| (0..4).map(move |j| (875 + 200 * j, 250 * k))).map(|(c, r)| tile(c, r, 200, 250)).collect();
    let mut next = tiles.iter();
    cpu_per_iteration("update_map_1750x2000_one_200x250_tile", 20, || {
        if let Some(t) = next.next() {
            map.apply_tile(t);
            black_box(p.update_map(&map).expect("map"));
        }
    });
    let _ = c;
}

fn query(c: &mut Criterion) {
    let mut p = build(800, 600);
    // Opposite corners of the city, both on roads.
    let (a, b) = (Point2::new(3.0, 3.0), Point2::new(353.0, 253.0));
    let path = p.plan(a, b).expect("path");
    eprintln!("path: {} waypoints, {:.0} m", path.waypoints.len(), path.length_m);
    cpu_per_iteration("plan_800x600", 5000, || {
        black_box(p.plan(a, b).ok());
    });
    c.bench_function("plan_800x600_corner_to_corner", |bench| bench.iter(|| p.plan(black_box(a), black_box(b))));
}

fn training(c: &mut Criterion) {
    let map = synthetic::city_map(800, 600, CityLayout::default(), 1);
    let mut p = build(800, 600);
    let truth = synthetic::city_probe(&map);
    for k in 0..60 {
        let pose = Pose2::new(2.0 + 2.0 * k as f64, 5.0, 0.0);
        let scan = synthetic::raycast_scan("ugv1", Time::ZERO, pose, 1024, 30.0, 0.25, &truth);
        p.add_scan(&scan, true).expect("scan");
    }
    let mut rng = ChaCha8Rng::seed_from_u64(1);
    let mut now = 0.0;
    let first = p.train(Time::from_secs_f64(now), &mut rng);
    eprintln!("first round: {first:?}, {:?}", p.graph_stats());
    cpu_per_iteration("train_round_and_reweight_800x600", 100, || {
        now += 10.0;
        black_box(p.train(Time::from_secs_f64(now), &mut rng));
    });
    c.bench_function("train_round_and_reweight_800x600", |b| {
        b.iter(|| {
            now += 10.0;
            let out = p.train(Time::from_secs_f64(now), &mut rng);
            assert!(matches!(out, TrainOutcome::Trained { .. }));
            out
        })
    });
    let scan = synthetic::raycast_scan("ugv1", Time::ZERO, Pose2::new(60.0, 5.0, 0.0), 1024, 30.0, 0.25, &truth);
    c.bench_function("add_scan_1024_bins", |b| b.iter(|| p.add_scan(black_box(&scan), false)));
}

criterion_group!(benches, construction, growth, query, training);
criterion_main!(benches);
