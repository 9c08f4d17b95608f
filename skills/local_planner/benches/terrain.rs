//! Terrain analysis (stages 1–6) on a 256 × 1024 street-like synthetic panorama.

use std::hint::black_box;

use criterion::Criterion;
use criterion::measurement::Measurement;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use spomp_core::PanoramaGeometry;
use spomp_local_planner::synthetic::{Scene, add_noise};
use spomp_local_planner::{SafeRegion, TerrainAnalyzer, TerrainParams, TerrainStage};

fn street_panorama() -> spomp_core::DepthPanorama {
    let mut pano = Scene::street(0.4).render(PanoramaGeometry::default_lidar());
    add_noise(&mut pano, 0.01, 0.02, &mut ChaCha8Rng::seed_from_u64(7));
    pano
}

fn bench<M: Measurement + 'static>(c: &mut Criterion<M>) {
    // Machine calibration: 10⁶ dependent xorshift-multiply steps, 5 cycles each (shift, xor,
    // 3-cycle multiply): 5·10⁶ cycles. Read other figures against it on a shared machine.
    c.bench_function("calibration/xorshift_mul_chain_1e6", |b| {
        b.iter(|| {
            let mut x = black_box(1u64);
            for _ in 0..1_000_000 {
                x = (x ^ (x >> 29)).wrapping_mul(0x9E37_79B9_7F4A_7C15);
            }
            black_box(x)
        })
    });
    let depth = street_panorama();
    let params = TerrainParams::default();
    let mut analyzer = TerrainAnalyzer::new(depth.geometry, params.clone()).expect("analyzer");
    c.bench_function("terrain/stages_1_to_6", |b| {
        b.iter(|| {
            let out = analyzer.analyze(black_box(&depth)).expect("analyze");
            black_box(out.reach_range_m()[0]);
        })
    });
    c.bench_function("terrain/stages_1_to_6_staged", |b| {
        b.iter(|| {
            let out = analyzer.analyze_observed(black_box(&depth), |_| {}).expect("analyze");
            black_box(out.reach_range_m()[0]);
        })
    });
    analyzer.analyze(&depth).expect("analyze");
    for stage in TerrainStage::ALL {
        c.bench_function(&format!("terrain/stage/{}", stage.name()), |b| {
            b.iter(|| {
                analyzer.run_single_stage(stage, black_box(&depth)).expect("stage");
            })
        });
    }
    c.bench_function("terrain/safe_region_from_terrain", |b| {
        b.iter(|| {
            let region = SafeRegion::from_terrain(analyzer.output(), &params).expect("region");
            black_box(region.area_m2());
        })
    });
}

fn main() {
    // `SPOMP_BENCH_CLOCK=cpu` reports the thread's CPU time (see spomp-bench-clock).
    spomp_bench_clock::run_with_requested_clock(bench, bench);
}
