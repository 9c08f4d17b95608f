//! One DWA step (10 × 4 samples, 15 roll-out steps) against the safe region of a street-like
//! panorama, and local goal selection (1000 samples).

use std::hint::black_box;

use criterion::Criterion;
use criterion::measurement::Measurement;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use spomp_core::{PanoramaGeometry, Point2, Pose2, Twist2};
use spomp_local_planner::synthetic::Scene;
use spomp_local_planner::{
    Dwa, DwaParams, LocalGoalParams, SafeRegion, TerrainAnalyzer, TerrainParams, select_local_goal,
};

fn bench<M: Measurement + 'static>(c: &mut Criterion<M>) {
    let geometry = PanoramaGeometry::default_lidar();
    let params = TerrainParams::default();
    let mut analyzer = TerrainAnalyzer::new(geometry, params.clone()).expect("analyzer");
    let out = analyzer.analyze(&Scene::street(0.4).render(geometry)).expect("analyze");
    let region = SafeRegion::from_terrain(out, &params).expect("region");
    let mut dwa = Dwa::new(DwaParams::default()).expect("dwa");
    let current = Twist2 { v: 0.8, omega: 0.1 };
    let robot = Pose2::new(0.3, 0.05, 0.05);
    let goal = Point2::new(4.0, 1.0);
    c.bench_function("dwa/step", |b| {
        b.iter(|| dwa.step_in_region(black_box(current), black_box(robot), black_box(goal), &region))
    });
    let goal_params = LocalGoalParams::default();
    let mut rng = ChaCha8Rng::seed_from_u64(11);
    c.bench_function("local_goal/select_1000", |b| {
        b.iter(|| select_local_goal(&region, black_box(Point2::new(20.0, 3.0)), Some(goal), &goal_params, &mut rng))
    });
}

fn main() {
    // `SPOMP_BENCH_CLOCK=cpu` reports the thread's CPU time (see spomp-bench-clock).
    spomp_bench_clock::run_with_requested_clock(bench, bench);
}
