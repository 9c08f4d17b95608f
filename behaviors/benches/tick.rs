//! Ticking a 1000-node tree: the engine's per-node overhead (docs/design.md §8: ≤ 20 ns per node
//! tick on one core). The tree is built from a mission through the real loader, so the figure
//! includes port bindings and the blackboard. `SPOMP_BENCH_CLOCK=cpu` reports thread CPU time.
//!
//! Instruction counts, stable under load: `SPOMP_TICKS=N` ticks the tree N times without
//! criterion; run it under `valgrind --tool=callgrind` for two N and divide the difference of
//! the totals by the extra ticks times the node count (`behaviors/README.md` has the figures).

use std::hint::black_box;
use std::io::Write;

use criterion::measurement::Measurement;
use criterion::{Criterion, Throughput};
use spomp_behaviors::mission::{BuildOptions, build_executor, load_mission};
use spomp_behaviors::{TreeExecutor, engine_registry};
use spomp_core::{Pose2, RobotId, Time};

/// A mission whose one role is a `parallel` over `groups` reactive sequences, each of `leaves`
/// `check_flag` conditions (true) and one running `wait`: every node is ticked every tick.
fn mission(groups: usize, leaves: usize) -> String {
    let mut s = String::from(
        "mission: bench\nteam:\n  - { id: r, kind: ugv, role: r, priority: 1, start: { x_m: 0, y_m: 0 } }\nroles:\n  r:\n    blackboard: { ok: true }\n    tree:\n      parallel:\n        children:\n",
    );
    for _ in 0..groups {
        s.push_str("          - reactive_sequence:\n");
        for _ in 0..leaves {
            s.push_str("              - check_flag: { flag: \"{ok}\" }\n");
        }
        s.push_str("              - wait: { duration_s: 1e9 }\n");
    }
    s.push_str("complete_when: all_trees_done\ntime_limit_s: 10\n");
    s
}

fn executor(groups: usize, leaves: usize) -> (TreeExecutor, usize) {
    let dir = std::env::temp_dir().join(format!("spomp-bench-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    let path = dir.join("bench.yaml");
    std::fs::File::create(&path)
        .and_then(|mut f| f.write_all(mission(groups, leaves).as_bytes()))
        .expect("write mission");
    let registry = engine_registry::<()>();
    let loaded = load_mission(&path, &registry);
    assert!(loaded.diagnostics.is_empty(), "{:#?}", loaded.diagnostics);
    let role = &loaded.roles["r"];
    let ex =
        build_executor(role, &registry, &RobotId::new("r"), Pose2::default(), BuildOptions::default()).expect("build");
    let n = ex.root().count();
    (ex, n)
}

fn bench_tick<M: Measurement>(c: &mut Criterion<M>) {
    // 1 parallel + 83 × (1 reactive sequence + 10 conditions + 1 wait) = 997 nodes.
    let (mut ex, nodes) = executor(83, 10);
    assert!((990..=1010).contains(&nodes), "tree has {nodes} nodes");
    let mut group = c.benchmark_group("tick");
    group.throughput(Throughput::Elements(nodes as u64));
    let mut t = 0i64;
    group.bench_function(format!("{nodes}_nodes_all_ticked"), |b| {
        b.iter(|| {
            t += 1;
            black_box(ex.tick(Time::from_millis(t), &mut (), None))
        })
    });
    group.finish();
}

/// Ticks the bench tree `ticks` times (for callgrind), no criterion.
fn tick_only(ticks: i64) {
    let (mut ex, nodes) = executor(83, 10);
    let mut last = None;
    for t in 1..=ticks {
        last = Some(black_box(ex.tick(Time::from_millis(t), &mut (), None)));
    }
    println!("{nodes} nodes ticked {ticks} times, root {last:?}");
}

fn main() {
    match std::env::var("SPOMP_TICKS").ok().and_then(|n| n.parse().ok()) {
        Some(ticks) => tick_only(ticks),
        None => spomp_bench_clock::run_with_requested_clock(bench_tick, bench_tick),
    }
}
