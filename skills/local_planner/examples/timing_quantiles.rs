//! Minimum, 10th percentile and median wall time of the terrain pipeline (stages 1–6, fused and
//! staged) and of one DWA step, on the benchmarks' inputs.
//!
//! On a shared virtual machine, neighbours' load makes criterion's mean drift by ±15 % between
//! runs; the minimum over many repetitions is the figure of an uncontended core, and the spread
//! to the percentiles shows how loaded the machine was. Run it pinned to one core:
//!
//! ```sh
//! cargo build --release -p spomp-local-planner --example timing_quantiles
//! taskset -c 0 target/release/examples/timing_quantiles [REPEATS]
//! ```

use std::hint::black_box;
use std::io::Write as _;
use std::time::Instant;

use spomp_core::{PanoramaGeometry, Point2, Pose2, Twist2};
use spomp_local_planner::synthetic::Scene;
use spomp_local_planner::{Dwa, DwaParams, SafeRegion, TerrainAnalyzer, TerrainParams};

#[path = "../benches/common/panoramas.rs"]
mod panoramas;

use panoramas::{simulator_panorama, street_panorama};

/// Times `f` `repeats` times (each call run `inner` times) and prints min / p10 / median per call.
fn report(name: &str, unit: &str, scale: f64, repeats: usize, inner: usize, mut f: impl FnMut()) {
    let mut times: Vec<f64> = (0..repeats)
        .map(|_| {
            let start = Instant::now();
            for _ in 0..inner {
                f();
            }
            start.elapsed().as_secs_f64() * scale / inner as f64
        })
        .collect();
    times.sort_by(f64::total_cmp);
    let at = |q: f64| times[((times.len() - 1) as f64 * q) as usize];
    // A closed pipe (`| head`) ends the output quietly instead of panicking.
    let _ = writeln!(
        std::io::stdout().lock(),
        "{name:<40} min {:>7.3}  p10 {:>7.3}  median {:>7.3} {unit}",
        at(0.0),
        at(0.1),
        at(0.5)
    );
}

fn main() -> Result<(), String> {
    let repeats: usize = match std::env::args().nth(1) {
        Some(arg) => arg.parse().map_err(|e| format!("REPEATS `{arg}`: {e}"))?,
        None => 2000,
    }
    .max(1);
    let params = TerrainParams::default();
    for (name, pano) in [("street (synthetic)", street_panorama()), ("parking lot (simulator)", simulator_panorama()?)]
    {
        let mut analyzer = TerrainAnalyzer::new(pano.geometry, params.clone()).map_err(|e| e.to_string())?;
        report(&format!("terrain fused, {name}"), "ms", 1e3, repeats, 1, || {
            black_box(analyzer.analyze(black_box(&pano)).map(|out| out.reach_range_m()[0]).ok());
        });
        report(&format!("terrain staged, {name}"), "ms", 1e3, repeats, 1, || {
            black_box(analyzer.analyze_observed(black_box(&pano), |_| {}).map(|out| out.reach_range_m()[0]).ok());
        });
    }
    // The DWA benchmark's step: the region of the noise-free street, a goal ahead to the left.
    let geometry = PanoramaGeometry::default_lidar();
    let mut analyzer = TerrainAnalyzer::new(geometry, params.clone()).map_err(|e| e.to_string())?;
    let out = analyzer.analyze(&Scene::street(0.4).render(geometry)).map_err(|e| e.to_string())?;
    let region = SafeRegion::from_terrain(out, &params).map_err(|e| e.to_string())?;
    let mut dwa = Dwa::new(DwaParams::default()).map_err(|e| e.to_string())?;
    let (current, robot, goal) = (Twist2 { v: 0.8, omega: 0.1 }, Pose2::new(0.3, 0.05, 0.05), Point2::new(4.0, 1.0));
    report("dwa step (10 × 4 samples, 15 steps)", "µs", 1e6, repeats, 10, || {
        black_box(dwa.step_in_region(black_box(current), black_box(robot), black_box(goal), &region));
    });
    Ok(())
}
