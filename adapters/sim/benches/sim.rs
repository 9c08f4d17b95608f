//! Simulator benchmarks: panorama synthesis (bar: ≤ 2 ms for 256 × 1024 on one core), city
//! generation, a UGV step, and the whole team (1 UAV + 5 UGVs, full stack) per 10 simulated
//! seconds (docs/design.md §8: ≥ 100× real time, i.e. ≤ 100 ms per 10 s).
//!
//! `cargo bench -p spomp-sim --bench sim -- --warm-up-time 1 --measurement-time 3`; with
//! `SPOMP_BENCH_CLOCK=cpu` the figures are the benchmark thread's CPU time (spomp-bench-clock),
//! steadier on a loaded machine.

use std::hint::black_box;

use criterion::Criterion;
use criterion::measurement::Measurement;
use spomp_core::{DepthPanorama, PanoramaGeometry, Pose2, SemanticPanorama, Twist2, UNKNOWN_CLASS};
use spomp_sim::run::{NoObserver, SimOptions, Simulation};
use spomp_sim::{PanoramaRenderer, Ugv, UgvParams};
use spomp_world::world_for_mission;
use spomp_world::{CityParams, generate_city};
use std::sync::Arc;

fn panorama<M: Measurement + 'static>(c: &mut Criterion<M>) {
    let world = generate_city(&CityParams::default(), 1).expect("city");
    let g = PanoramaGeometry::default_lidar();
    let renderer = PanoramaRenderer::new(g, 0.4, 50.0).expect("renderer");
    let mut depth = DepthPanorama::empty(g);
    let mut sem = spomp_core::SemanticPanorama { geometry: g, class: vec![UNKNOWN_CLASS; g.len()] };
    // Among the buildings (a crossing in the middle of the city) and at the start.
    let start = world.meta.start_poses[0];
    let spec = world.spec();
    let mid = Pose2::new(spec.size_m().0 / 2.0, 5.0, 0.3);
    c.bench_function("panorama_256x1024_start", |b| {
        b.iter(|| renderer.render(&world, black_box(start), &mut depth, &mut sem));
    });
    c.bench_function("panorama_256x1024_street", |b| {
        b.iter(|| renderer.render(&world, black_box(mid), &mut depth, &mut sem));
    });
    let _: &SemanticPanorama = &sem;
}

fn city<M: Measurement + 'static>(c: &mut Criterion<M>) {
    let params = CityParams::default();
    let mut group = c.benchmark_group("city");
    group.sample_size(10);
    group.bench_function("generate_400x300m", |b| b.iter(|| generate_city(&params, black_box(7)).expect("city")));
    group.finish();
}

fn ugv<M: Measurement + 'static>(c: &mut Criterion<M>) {
    let world = generate_city(&CityParams::default(), 1).expect("city");
    let start = world.meta.start_poses[0];
    let mut robot = Ugv::new(&world, UgvParams::default(), start).expect("robot");
    let cmd = Twist2 { v: 1.5, omega: 0.3 };
    c.bench_function("ugv_step_0.1s", |b| {
        b.iter(|| {
            robot.step(&world, black_box(cmd), 0.1);
            // Keep the robot in open road: start over every lap.
            if robot.pose().position().distance(start.position()) > 3.0 {
                robot = Ugv::new(&world, UgvParams::default(), start).expect("robot");
            }
        });
    });
}

/// The paper's mission with 1 UAV + 5 UGVs, past the first map delivery (UGVs driving to goals),
/// 10 simulated seconds per iteration. The run goes on from iteration to iteration.
fn team<M: Measurement + 'static>(c: &mut Criterion<M>) {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("benches/missions/team-1uav-5ugv.yaml");
    let registry = spomp_robot::registry();
    // The bench mission includes the shipped subtree and plan (as with `--allow-dir missions`).
    let options = spomp_behaviors::mission::LoadOptions {
        allowed_dirs: vec![std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../missions")],
    };
    let loaded = spomp_behaviors::mission::load_mission_with(&path, &registry, &options);
    assert!(loaded.is_valid(), "{:?}", loaded.diagnostics);
    let mission = loaded.mission.as_ref().expect("mission");
    // Robots stepped in order on this thread: the CPU clock (`SPOMP_BENCH_CLOCK=cpu`) sees
    // only this thread's work. Whole runs give the parallel speed-up.
    let options = SimOptions { seed: 1, time_limit_s: Some(1e6), parallel_robots: false, ..SimOptions::default() };
    let world = world_for_mission(mission, &loaded.base_dir(), options.seed).expect("world");
    let mut sim = Simulation::new(&loaded, &registry, Arc::new(world), options).expect("simulation");
    while sim.now().as_secs_f64() < 200.0 {
        sim.step(&mut NoObserver);
    }
    let mut group = c.benchmark_group("team");
    group.sample_size(10);
    group.bench_function("1uav_5ugv_10_sim_seconds", |b| {
        b.iter(|| {
            for _ in 0..100 {
                sim.step(&mut NoObserver);
            }
        });
    });
    group.finish();
}

fn all<M: Measurement + 'static>(c: &mut Criterion<M>) {
    panorama(c);
    city(c);
    ugv(c);
    team(c);
}

fn main() {
    // `SPOMP_BENCH_CLOCK=cpu` reports the thread's CPU time (see spomp-bench-clock).
    spomp_bench_clock::run_with_requested_clock(all, all);
}
