//! Runs the fused terrain pipeline (stages 1–6) a given number of times on one of the terrain
//! benchmark's panoramas, for instruction counts under `valgrind --tool=callgrind`, which stay
//! stable on a loaded machine where wall times do not. The difference between two repeat counts
//! divided by the difference of the counts is the cost of one analysis, without the setup:
//!
//! ```sh
//! cargo build --profile profiling -p spomp-local-planner --example terrain_instructions
//! valgrind --tool=callgrind target/profiling/examples/terrain_instructions street 1
//! valgrind --tool=callgrind target/profiling/examples/terrain_instructions street 11
//! ```
//!
//! Panoramas: `street` (the synthetic street, 2 % dropouts), `sim` (the simulator's parking lot),
//! `street-dropouts` and `sim-dropouts` (the same with the dropouts of a real OS1-64 panorama,
//! `benches/common/panoramas.rs`).
//!
//! `INSTRUCTION_SET=baseline|avx2|avx512` picks the code path (default: the widest available).
//! `ONLY_STAGE=fill_holes|project|gradients|obstacles|distance_transform|reachability` runs that
//! stage alone (`run_single_stage`, after one whole analysis) instead of the whole pipeline, for
//! one stage's instruction count.
//! With `STAGE_TIMES=1` it also prints each stage's smallest wall time over the repeats.
//!
//! `terrain_instructions write-png PANORAMA FILE.png` writes the panorama as a 16-bit PNG of range
//! counts (1/512 m per count, `spomp terrain`'s default scale) and prints its share of pixels
//! without a return, so that `spomp terrain FILE.png` analyses the very panorama the benchmark
//! does.
//!
//! (Valgrind reports a processor without AVX-512, so the run measures the AVX2 code path.)

use std::hint::black_box;
use std::time::Instant;

use spomp_local_planner::{InstructionSet, TerrainAnalyzer, TerrainParams, TerrainStage};

#[path = "../benches/common/panoramas.rs"]
mod panoramas;

use panoramas::{
    SIM_RANGE_SCALE_M, simulator_dropouts_panorama, simulator_panorama, street_dropout_stats, street_dropouts_panorama,
    street_panorama,
};

fn panorama(name: Option<&str>) -> Result<spomp_core::DepthPanorama, String> {
    match name {
        Some("street") | None => Ok(street_panorama()),
        Some("sim") => simulator_panorama(),
        Some("street-dropouts") => Ok(street_dropouts_panorama()),
        Some("sim-dropouts") => simulator_dropouts_panorama(),
        Some(other) => Err(format!("panorama `{other}`: expected street, sim, street-dropouts or sim-dropouts")),
    }
}

fn main() -> Result<(), String> {
    let mut args = std::env::args().skip(1).peekable();
    if args.peek().map(String::as_str) == Some("write-png") {
        args.next();
        let name = args.next();
        let pano = panorama(name.as_deref())?;
        let path = args.next().ok_or("write-png PANORAMA FILE.png: no file given")?;
        let g = pano.geometry;
        let image: image::ImageBuffer<image::Luma<u16>, Vec<u16>> =
            image::ImageBuffer::from_raw(g.cols as u32, g.rows as u32, pano.to_counts(SIM_RANGE_SCALE_M))
                .ok_or("panorama size")?;
        image.save(&path).map_err(|e| format!("{path}: {e}"))?;
        let missing = pano.range_m.iter().filter(|r| **r <= 0.0).count() as f64 / g.len() as f64;
        println!("wrote {path}: {} × {}, {:.1} % without a return", g.rows, g.cols, 100.0 * missing);
        if name.as_deref() == Some("street-dropouts") {
            println!("{:?}", street_dropout_stats());
        }
        return Ok(());
    }
    let pano = panorama(args.next().as_deref())?;
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
    if let Some(name) = std::env::var_os("ONLY_STAGE") {
        let stage = TerrainStage::ALL
            .into_iter()
            .find(|s| std::ffi::OsStr::new(s.name()) == name)
            .ok_or_else(|| format!("ONLY_STAGE {name:?}: no such stage"))?;
        analyzer.analyze(&pano).map_err(|e| e.to_string())?;
        for _ in 0..repeats {
            black_box(analyzer.run_single_stage(stage, black_box(&pano)).map_err(|e| e.to_string())?);
        }
        println!("{repeats} × {}", stage.name());
        return Ok(());
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
