//! Runs the fused terrain pipeline (stages 1–6) a given number of times on one of the terrain
//! benchmark's panoramas, for instruction counts under `valgrind --tool=callgrind`, which stay
//! stable on a loaded machine where wall times do not. The difference between two repeat counts
//! divided by the difference of the counts is the cost of one analysis, without the setup:
//!
//! ```sh
//! cargo build --release -p spomp-local-planner --example terrain_instructions
//! valgrind --tool=callgrind target/release/examples/terrain_instructions street 1
//! valgrind --tool=callgrind target/release/examples/terrain_instructions street 11
//! ```
//!
//! `INSTRUCTION_SET=baseline|avx2|avx512` picks the code path (default: the widest available).
//! With `STAGE_TIMES=1` it also prints each stage's smallest wall time over the repeats.
//!
//! (Valgrind reports a processor without AVX-512, so the run measures the AVX2 code path.)

use std::hint::black_box;
use std::time::Instant;

use spomp_local_planner::{InstructionSet, TerrainAnalyzer, TerrainParams, TerrainStage};

#[path = "../benches/common/panoramas.rs"]
mod panoramas;

use panoramas::{simulator_panorama, street_panorama};

fn main() -> Result<(), String> {
    let mut args = std::env::args().skip(1);
    let pano = match args.next().as_deref() {
        Some("street") | None => street_panorama(),
        Some("sim") => simulator_panorama()?,
        Some(other) => return Err(format!("panorama `{other}`: expected `street` or `sim`")),
    };
    let repeats: usize = match args.next() {
        Some(arg) => arg.parse().map_err(|e| format!("REPEATS `{arg}`: {e}"))?,
        None => 1,
    };
    let mut analyzer = TerrainAnalyzer::new(pano.geometry, TerrainParams::default()).map_err(|e| e.to_string())?;
    if let Some(set) = std::env::var_os("INSTRUCTION_SET") {
        let set = match set.to_str() {
            Some("baseline") => InstructionSet::Baseline,
            Some("avx2") => InstructionSet::Avx2,
            Some("avx512") => InstructionSet::Avx512,
            _ => return Err(format!("INSTRUCTION_SET {set:?}: expected baseline, avx2 or avx512")),
        };
        if !analyzer.select_instruction_set(set) {
            return Err(format!("this processor lacks {set:?}"));
        }
    }
    let mut checksum = 0.0f64;
    for _ in 0..repeats {
        let out = analyzer.analyze(black_box(&pano)).map_err(|e| e.to_string())?;
        checksum += out.reach_range_m().iter().map(|&r| f64::from(r)).sum::<f64>();
    }
    println!("{repeats} analyses, reach checksum {checksum:.3}");
    if std::env::var_os("STAGE_TIMES").is_some() {
        // Smallest and median wall time of the fused pipeline over the repeats, microseconds.
        let mut fused: Vec<f64> = (0..repeats)
            .map(|_| {
                let start = Instant::now();
                black_box(analyzer.analyze(black_box(&pano)).map(|out| out.reach_range_m()[0]).ok());
                start.elapsed().as_secs_f64() * 1e6
            })
            .collect();
        fused.sort_by(f64::total_cmp);
        if let (Some(min), Some(median)) = (fused.first(), fused.get(fused.len() / 2)) {
            println!("{:<20} {min:>8.1} µs (median {median:.1})", "fused 1-6");
        }
        // Smallest wall time of each stage over the repeats (staged pipeline), microseconds.
        let mut best = [f64::INFINITY; TerrainStage::ALL.len()];
        for _ in 0..repeats {
            let mut last = Instant::now();
            analyzer
                .analyze_observed(black_box(&pano), |stage| {
                    let now = Instant::now();
                    let slot = &mut best[stage as usize];
                    *slot = slot.min((now - last).as_secs_f64() * 1e6);
                    last = now;
                })
                .map_err(|e| e.to_string())?;
        }
        for (stage, micros) in TerrainStage::ALL.iter().zip(best) {
            println!("{:<20} {micros:>8.1} µs", stage.name());
        }
    }
    Ok(())
}
