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
//! (Valgrind reports a processor without AVX-512, so the run measures the AVX2 code path.)

use std::hint::black_box;

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use spomp_core::{DepthPanorama, PanoramaGeometry};
use spomp_local_planner::synthetic::{Scene, add_noise};
use spomp_local_planner::{TerrainAnalyzer, TerrainParams};

/// The terrain benchmark's synthetic panorama: a street, 1 cm noise, 2 % dropouts.
fn street_panorama() -> DepthPanorama {
    let mut pano = Scene::street(0.4).render(PanoramaGeometry::default_lidar());
    add_noise(&mut pano, 0.01, 0.02, &mut ChaCha8Rng::seed_from_u64(7));
    pano
}

/// The terrain benchmark's simulator panorama (a parking lot of the default city).
fn simulator_panorama() -> Result<DepthPanorama, String> {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/benches/data/sim-parking-lot.png");
    let image = image::open(path).map_err(|e| format!("{path}: {e}"))?.into_luma16();
    let geometry = PanoramaGeometry {
        rows: image.height() as usize,
        cols: image.width() as usize,
        ..PanoramaGeometry::default_lidar()
    };
    DepthPanorama::from_counts(geometry, image.as_raw(), 1.0 / 512.0).ok_or_else(|| format!("{path}: wrong size"))
}

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
    let mut checksum = 0.0f64;
    for _ in 0..repeats {
        let out = analyzer.analyze(black_box(&pano)).map_err(|e| e.to_string())?;
        checksum += out.reach_range_m().iter().map(|&r| f64::from(r)).sum::<f64>();
    }
    println!("{repeats} analyses, reach checksum {checksum:.3}");
    Ok(())
}
