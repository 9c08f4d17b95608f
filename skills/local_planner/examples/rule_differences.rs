//! What each remaining difference from the authors' implementation (the local planner README's
//! rule table) changes on the benchmark's panoramas: the pipeline is run from the public stages
//! once as spomp runs it and once per authors' rule, and the obstacle pixels, traversable pixels
//! and reachability bins that differ are counted.
//!
//! ```sh
//! cargo run --release -p spomp-local-planner --example rule_differences [--simulation]
//! ```
//!
//! The authors' rules, as the README states them: the signed noise term η·sin θ (spomp:
//! η·|sin θ|); obstacle runs shorter than max(3 px, 0.3 m of arc at the run's last pixel,
//! at most A/5 px) dropped (spomp: `min_obstacle_run_px` / `min_obstacle_run_m`); each bin's
//! range the last safe pixel's (spomp: the largest).

use std::f32::consts::TAU;

use spomp_core::DepthPanorama;
use spomp_local_planner::stages::{self, DistanceScratch, GradientScratch, GradientWindow, ReachScratch, Tables};
use spomp_local_planner::{TerrainAnalyzer, TerrainParams};

#[path = "../benches/common/panoramas.rs"]
mod panoramas;

/// Which of the authors' rules a run uses.
#[derive(Clone, Copy, Default)]
struct Variant {
    signed_noise: bool,
    combined_runs: bool,
    last_range: bool,
}

/// The outputs compared.
struct Result {
    obstacle: Vec<bool>,
    traversable: Vec<bool>,
    reach_range_m: Vec<f32>,
    reach_obstacle: Vec<bool>,
}

/// The authors' run filter: along each row (wrapping), a run of obstacle pixels is cleared when
/// it is shorter than ⌊0.3 m / s⌋ pixels, s the arc per column at its last pixel, that count
/// clamped to [3, A/5].
fn combined_run_filter(obstacle: &mut [bool], ranges: &[f32], cols: usize, min_run_m: f32) {
    let step = TAU / cols as f32;
    for (obs, rho) in obstacle.chunks_exact_mut(cols).zip(ranges.chunks_exact(cols)) {
        let Some(free) = obs.iter().position(|&o| !o) else { continue };
        let mut k = 1;
        while k < cols {
            if !obs[(free + k) % cols] {
                k += 1;
                continue;
            }
            let start = k;
            while obs[(free + k) % cols] {
                k += 1;
            }
            let last = (free + k - 1) % cols;
            let window = ((min_run_m / (rho[last] * step)) as usize).clamp(3, (cols / 5).max(3));
            if k - start < window {
                (start..k).for_each(|j| obs[(free + j) % cols] = false);
            }
        }
    }
}

fn run(depth: &DepthPanorama, p: &TerrainParams, variant: Variant) -> Result {
    let g = depth.geometry;
    let (n, cols) = (g.len(), g.cols);
    let mut tables = Tables::new(
        g.rows,
        cols,
        |row| g.elevation_of_row(row),
        p.sensor_height_m,
        p.gradient_window_m,
        p.range_noise_m,
    );
    if variant.signed_noise {
        for (row, noise) in tables.noise_z_m.iter_mut().enumerate() {
            *noise = (p.range_noise_m * g.elevation_of_row(row).sin()) as f32;
        }
    }
    let (mut ranges, mut z, mut r, mut gradient) = (vec![0.0; n], vec![0.0; n], vec![0.0; n], vec![0.0; n]);
    stages::fill_holes(&depth.range_m, &mut ranges, cols, p.hole_fill_max_m as f32);
    stages::project(&ranges, &tables, &mut z, &mut r);
    let window = GradientWindow {
        window_m: p.gradient_window_m as f32,
        max_window_px: (p.gradient_window_max_fraction * cols as f64) as f32,
    };
    stages::gradients(&z, &r, &tables, window, &mut GradientScratch::default(), &mut gradient);
    let mut obstacle = vec![false; n];
    let slope = p.slope_threshold as f32;
    if variant.combined_runs {
        stages::obstacles(&gradient, &ranges, cols, slope, stages::RunFilter::default(), &mut obstacle);
        combined_run_filter(&mut obstacle, &ranges, cols, 0.3);
    } else {
        stages::obstacles(&gradient, &ranges, cols, slope, p.run_filter(), &mut obstacle);
    }
    let (mut along, mut distance, mut traversable) = (vec![0.0; n], vec![0.0; n], vec![false; n]);
    let d_max = p.max_obstacle_distance_m as f32;
    stages::distance_transform(
        &ranges,
        &obstacle,
        cols,
        d_max,
        &mut DistanceScratch::default(),
        &mut along,
        &mut distance,
    );
    stages::traversable(&ranges, &distance, p.inflation_m as f32, &mut traversable);
    let (mut reach_range_m, mut reach_obstacle, mut last_row) = (vec![0.0; cols], vec![false; cols], vec![0; cols]);
    stages::reachability(
        &r,
        &ranges,
        &traversable,
        cols,
        p.reach_gap_m as f32,
        p.min_reach_range_m as f32,
        &mut ReachScratch::default(),
        &mut reach_range_m,
        &mut reach_obstacle,
        &mut last_row,
    );
    if variant.last_range {
        for (c, (range, &row)) in reach_range_m.iter_mut().zip(&last_row).enumerate() {
            let last = r.get(row as usize * cols + c).copied().unwrap_or(0.0);
            *range = if last.is_finite() { last.max(p.min_reach_range_m as f32) } else { *range };
        }
    }
    Result { obstacle, traversable, reach_range_m, reach_obstacle }
}

fn main() -> std::result::Result<(), String> {
    let simulation = std::env::args().any(|a| a == "--simulation");
    let params = if simulation { TerrainParams::simulation() } else { TerrainParams::default() };
    let panoramas = [
        ("street", panoramas::street_panorama()),
        ("street with dropouts", panoramas::street_dropouts_panorama()),
        ("simulator parking lot", panoramas::simulator_panorama()?),
        ("parking lot with dropouts", panoramas::simulator_dropouts_panorama()?),
    ];
    println!("profile: {}", if simulation { "simulation" } else { "default (robot)" });
    for (name, depth) in &panoramas {
        let ours = run(depth, &params, Variant::default());
        // The stages run one by one here must be the analyzer's result.
        let mut analyzer = TerrainAnalyzer::new(depth.geometry, params.clone()).map_err(|e| e.to_string())?;
        let out = analyzer.analyze(depth).map_err(|e| e.to_string())?;
        if out.reach_range_m() != ours.reach_range_m.as_slice() || out.obstacle() != ours.obstacle.as_slice() {
            return Err(format!("{name}: the stages differ from the analyzer"));
        }
        let count = |a: &[bool]| a.iter().filter(|&&x| x).count();
        println!(
            "{name}: {} obstacle pixels, {} traversable, {} of {} bins end at an obstacle",
            count(&ours.obstacle),
            count(&ours.traversable),
            count(&ours.reach_obstacle),
            ours.reach_obstacle.len()
        );
        let variants = [
            ("signed noise η·sin θ", Variant { signed_noise: true, ..Variant::default() }),
            ("combined run rule", Variant { combined_runs: true, ..Variant::default() }),
            ("last range reached", Variant { last_range: true, ..Variant::default() }),
            ("all three", Variant { signed_noise: true, combined_runs: true, last_range: true }),
        ];
        for (label, variant) in variants {
            let other = run(depth, &params, variant);
            let differ = |a: &[bool], b: &[bool]| a.iter().zip(b).filter(|(x, y)| x != y).count();
            let bins: Vec<f32> = ours
                .reach_range_m
                .iter()
                .zip(&other.reach_range_m)
                .zip(ours.reach_obstacle.iter().zip(&other.reach_obstacle))
                .filter(|((a, b), (oa, ob))| (*a - *b).abs() > 0.01 || oa != ob)
                .map(|((a, b), _)| b - a)
                .collect();
            let (shorter, longer) =
                (bins.iter().filter(|d| **d < -0.01).count(), bins.iter().filter(|d| **d > 0.01).count());
            let worst = bins.iter().fold(0.0f32, |w, d| if d.abs() > w.abs() { *d } else { w });
            println!(
                "  {label:<22} obstacle px {:+6} ({} differ), traversable px {:+6}, bins differing {:4} ({shorter} shorter, {longer} longer, largest change {worst:+.2} m), obstacle bins {:+4}",
                count(&other.obstacle) as i64 - count(&ours.obstacle) as i64,
                differ(&ours.obstacle, &other.obstacle),
                count(&other.traversable) as i64 - count(&ours.traversable) as i64,
                bins.len(),
                count(&other.reach_obstacle) as i64 - count(&ours.reach_obstacle) as i64,
            );
        }
    }
    Ok(())
}
