//! One measurement update with 300 particles (the most, and the start) and with 100 (what KLD
//! sampling keeps while tracking) on a 256 × 1024 panorama against an 800 × 600 aerial map
//! (the town of the tests, tiled), and the parts of it.

#[path = "../tests/common/mod.rs"]
mod common;

use std::hint::black_box;

use common::{World, frame, render};
use criterion::Criterion;
use criterion::measurement::Measurement;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use spomp_core::{ClassTable, PanoramaGeometry, Pose2, Time};
use spomp_localization::{CrossViewLocalizer, LocalizationParams, PosePrior};

fn bench_update<M: Measurement>(c: &mut Criterion<M>, label: &str) {
    let world = World::tiled(800, 600);
    let classes = ClassTable::default_table();
    let mut rng = ChaCha8Rng::seed_from_u64(1);
    let truth = Pose2::new(40.0, 31.0, 0.3);
    let geometry = PanoramaGeometry::default_lidar();
    let pano = render(&world, truth, geometry, 0.4, 0.03, &mut rng);
    let f = frame(1, 1.0, Pose2::default(), 0.4, pano);

    let mut loc = CrossViewLocalizer::new(LocalizationParams::default()).expect("default params are valid");
    let prior = PosePrior { pose: truth, std_xy_m: 2.0, std_yaw_rad: 5f64.to_radians() };
    loc.initialize(&prior, Pose2::default(), Time::ZERO, &mut rng).expect("prior is valid");
    loc.prepare_map(&world.map, &classes).expect("map is valid");
    let report = loc.update(&f, &world.map, &classes, &mut rng).expect("update works");
    eprintln!("observed cells per panorama: {}", report.observed_cells);

    let mut group = c.benchmark_group(format!("localization_{label}"));
    group.bench_function("update_300_particles_256x1024_on_800x600", |b| {
        b.iter(|| {
            // Same particles every time: re-spread them so resampling does not collapse the set.
            loc.initialize(&prior, Pose2::default(), Time::ZERO, &mut rng).expect("prior is valid");
            black_box(loc.update(black_box(&f), &world.map, &classes, &mut rng).expect("update works"))
        })
    });
    // The set KLD sampling keeps while tracking (median 103 in the closed-loop test).
    let mut tracking =
        CrossViewLocalizer::new(LocalizationParams { num_particles: 100, ..Default::default() }).expect("valid params");
    tracking.initialize(&prior, Pose2::default(), Time::ZERO, &mut rng).expect("prior is valid");
    tracking.prepare_map(&world.map, &classes).expect("map is valid");
    group.bench_function("update_100_particles_256x1024_on_800x600", |b| {
        b.iter(|| {
            tracking.initialize(&prior, Pose2::default(), Time::ZERO, &mut rng).expect("prior is valid");
            black_box(tracking.update(black_box(&f), &world.map, &classes, &mut rng).expect("update works"))
        })
    });
    group.bench_function("initialize_300_particles", |b| {
        b.iter(|| loc.initialize(&prior, Pose2::default(), Time::ZERO, &mut rng).expect("prior is valid"))
    });
    // A new version each time: nobody holds its planes, so they are built.
    let mut versioned = world.map.clone();
    group.bench_function("prepare_map_800x600", |b| {
        b.iter(|| {
            versioned.version += 1;
            let mut fresh = CrossViewLocalizer::new(LocalizationParams::default()).expect("valid");
            fresh.prepare_map(black_box(&versioned), &classes).expect("map is valid");
            fresh
        })
    });
    // The map `loc` holds: its planes are shared, not built (two fingerprints and a lookup).
    group.bench_function("prepare_map_800x600_shared", |b| {
        b.iter(|| {
            let mut fresh = CrossViewLocalizer::new(LocalizationParams::default()).expect("valid");
            fresh.prepare_map(black_box(&world.map), &classes).expect("map is valid");
            fresh
        })
    });
    group.finish();
}

fn main() {
    // `SPOMP_BENCH_CLOCK=cpu` reports the thread's CPU time (see spomp-bench-clock).
    spomp_bench_clock::run_with_requested_clock(|c| bench_update(c, "thread_cpu"), |c| bench_update(c, "wall"));
}
