//! Terrain analysis (stages 1–6) on a 256 × 1024 street-like synthetic panorama, on a
//! panorama the simulator rendered in a parking lot of its default city
//! (`benches/data/sim-parking-lot.png`, written by
//! `spomp world generate --seed 1 --out W && spomp world pano W --at 237,141,-1.5708 --out …`),
//! and on both with the dropouts of a real OS1-64 panorama (`common/panoramas.rs`: sky, glass,
//! dark cars and ground, clusters, single pixels; 24 % and 34 % of the pixels without a return).

use std::hint::black_box;

use criterion::Criterion;
use criterion::measurement::Measurement;
use spomp_local_planner::{SafeRegion, TerrainAnalyzer, TerrainParams, TerrainStage};

#[path = "common/panoramas.rs"]
mod panoramas;

use panoramas::{street_dropouts_panorama, street_panorama};

fn simulator_panorama() -> spomp_core::DepthPanorama {
    panoramas::simulator_panorama().unwrap_or_else(|e| panic!("{e}"))
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
    let simulated = simulator_panorama();
    let mut sim_analyzer = TerrainAnalyzer::new(simulated.geometry, params.clone()).expect("analyzer");
    c.bench_function("terrain/stages_1_to_6_simulator_panorama", |b| {
        b.iter(|| {
            let out = sim_analyzer.analyze(black_box(&simulated)).expect("analyze");
            black_box(out.reach_range_m()[0]);
        })
    });
    let dropouts = street_dropouts_panorama();
    let mut dropout_analyzer = TerrainAnalyzer::new(dropouts.geometry, params.clone()).expect("analyzer");
    c.bench_function("terrain/stages_1_to_6_dropouts", |b| {
        b.iter(|| {
            let out = dropout_analyzer.analyze(black_box(&dropouts)).expect("analyze");
            black_box(out.reach_range_m()[0]);
        })
    });
    let sim_dropouts = panoramas::simulator_dropouts_panorama().unwrap_or_else(|e| panic!("{e}"));
    let mut sim_dropout_analyzer = TerrainAnalyzer::new(sim_dropouts.geometry, params.clone()).expect("analyzer");
    c.bench_function("terrain/stages_1_to_6_simulator_panorama_dropouts", |b| {
        b.iter(|| {
            let out = sim_dropout_analyzer.analyze(black_box(&sim_dropouts)).expect("analyze");
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
    dropout_analyzer.analyze(&dropouts).expect("analyze");
    for stage in [TerrainStage::FillHoles, TerrainStage::Obstacles] {
        c.bench_function(&format!("terrain/stage_dropouts/{}", stage.name()), |b| {
            b.iter(|| {
                dropout_analyzer.run_single_stage(stage, black_box(&dropouts)).expect("stage");
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
