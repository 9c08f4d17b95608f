//! The panoramas the terrain benchmark and the timing examples run on, in one place: included
//! with `#[path]` by `benches/terrain.rs` and the examples (they are separate crates).

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use spomp_core::{DepthPanorama, PanoramaGeometry};
use spomp_local_planner::synthetic::{Scene, add_noise};

/// Metres per count of the stored simulator panorama (the `spomp world pano` default).
const SIM_RANGE_SCALE_M: f64 = 1.0 / 512.0;

/// The synthetic street: 256 × 1024, 1 cm noise, 2 % dropouts.
pub fn street_panorama() -> DepthPanorama {
    let mut pano = Scene::street(0.4).render(PanoramaGeometry::default_lidar());
    add_noise(&mut pano, 0.01, 0.02, &mut ChaCha8Rng::seed_from_u64(7));
    pano
}

/// The panorama the simulator rendered in a parking lot of its default city
/// (`benches/data/sim-parking-lot.png`).
pub fn simulator_panorama() -> Result<DepthPanorama, String> {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/benches/data/sim-parking-lot.png");
    let image = image::open(path).map_err(|e| format!("{path}: {e}"))?.into_luma16();
    // Rows and columns from the image; the 90° vertical field of view the simulator renders.
    let geometry = PanoramaGeometry {
        rows: image.height() as usize,
        cols: image.width() as usize,
        ..PanoramaGeometry::default_lidar()
    };
    DepthPanorama::from_counts(geometry, image.as_raw(), SIM_RANGE_SCALE_M).ok_or_else(|| format!("{path}: wrong size"))
}
