//! One measurement update with 300 particles on a 256 × 1024 panorama against an 800 × 600
//! aerial map (the town of the tests, tiled), and the parts of it.

#[path = "../tests/common/mod.rs"]
mod common;

use std::hint::black_box;

use common::{World, frame, render};
use criterion::measurement::{Measurement, ValueFormatter};
use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use spomp_core::{ClassTable, PanoramaGeometry, Pose2, Time};
use spomp_localization::{CrossViewLocalizer, LocalizationParams, PosePrior};

/// CPU time of the benchmarking thread, from the kernel's scheduler statistics (nanoseconds on
/// a CPU). The machine these figures come from is shared and loaded, so wall-clock time
/// overstates the cost; this counts only the time the thread actually ran.
struct ThreadCpuTime;

fn thread_cpu_ns() -> u64 {
    std::fs::read_to_string("/proc/thread-self/schedstat")
        .ok()
        .and_then(|s| s.split_whitespace().next().and_then(|v| v.parse().ok()))
        .unwrap_or(0)
}

struct NanosFormatter;

impl ValueFormatter for NanosFormatter {
    fn scale_values(&self, typical: f64, values: &mut [f64]) -> &'static str {
        let (div, unit) = if typical < 1e3 {
            (1.0, "ns")
        } else if typical < 1e6 {
            (1e3, "µs")
        } else if typical < 1e9 {
            (1e6, "ms")
        } else {
            (1e9, "s")
        };
        values.iter_mut().for_each(|v| *v /= div);
        unit
    }

    fn scale_throughputs(&self, _typical: f64, _throughput: &Throughput, values: &mut [f64]) -> &'static str {
        values.iter_mut().for_each(|v| *v = 1e9 / *v);
        "iter/s"
    }

    fn scale_for_machines(&self, _values: &mut [f64]) -> &'static str {
        "ns"
    }
}

impl Measurement for ThreadCpuTime {
    type Intermediate = u64;
    type Value = u64;
    fn start(&self) -> u64 {
        thread_cpu_ns()
    }
    fn end(&self, start: u64) -> u64 {
        thread_cpu_ns().saturating_sub(start)
    }
    fn add(&self, a: &u64, b: &u64) -> u64 {
        a + b
    }
    fn zero(&self) -> u64 {
        0
    }
    fn to_f64(&self, v: &u64) -> f64 {
        *v as f64
    }
    fn formatter(&self) -> &dyn ValueFormatter {
        &NanosFormatter
    }
}

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
    group.bench_function("initialize_300_particles", |b| {
        b.iter(|| loc.initialize(&prior, Pose2::default(), Time::ZERO, &mut rng).expect("prior is valid"))
    });
    group.bench_function("prepare_map_800x600", |b| {
        b.iter(|| {
            let mut fresh = CrossViewLocalizer::new(LocalizationParams::default()).expect("valid");
            fresh.prepare_map(black_box(&world.map), &classes).expect("map is valid");
            fresh
        })
    });
    group.finish();
}

fn wall(c: &mut Criterion) {
    bench_update(c, "wall");
}

fn cpu(c: &mut Criterion<ThreadCpuTime>) {
    bench_update(c, "thread_cpu");
}

criterion_group!(wall_time, wall);
criterion_group! {
    name = cpu_time;
    config = Criterion::default().with_measurement(ThreadCpuTime);
    targets = cpu
}
criterion_main!(wall_time, cpu_time);
