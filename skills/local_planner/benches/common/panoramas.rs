//! The panoramas the terrain benchmark and the timing examples run on, in one place: included
//! with `#[path]` by `benches/terrain.rs`, the examples and `tests/optimised_matches_reference.rs`
//! (they are separate crates).

#![allow(dead_code)]

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use spomp_core::{DepthPanorama, PanoramaGeometry};
use spomp_local_planner::synthetic::{Primitive, Scene, add_noise};

/// Metres per count of the stored simulator panorama (the `spomp world pano` default).
pub const SIM_RANGE_SCALE_M: f64 = 1.0 / 512.0;

/// Sensor height of the synthetic street, metres.
const STREET_SENSOR_HEIGHT_M: f64 = 0.4;

/// The synthetic street: 256 × 1024, 1 cm noise, 2 % dropouts.
pub fn street_panorama() -> DepthPanorama {
    let mut pano = Scene::street(STREET_SENSOR_HEIGHT_M).render(PanoramaGeometry::default_lidar());
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

/// The synthetic street with the dropouts of a real OS1-64 depth panorama (about a fifth of the
/// pixels without a return; [`street_dropout_stats`] counts them by cause), stored at 1/512 m per
/// count ([`SIM_RANGE_SCALE_M`]) so that the PNG `spomp terrain` reads
/// (`examples/terrain_instructions write-png`) holds exactly these ranges.
pub fn street_dropouts_panorama() -> DepthPanorama {
    street_dropouts(17).0
}

/// Pixels of [`street_dropouts_panorama`] without a return, by cause (a pixel counts for the
/// first cause that removed it), and the total, as fractions of the panorama.
pub fn street_dropout_stats() -> DropoutStats {
    street_dropouts(17).1
}

/// The simulator's parking-lot panorama with the scene-independent part of the dropout model
/// (clusters, dark ground patches, grazing far ground, single pixels), stored as
/// [`street_dropouts_panorama`].
pub fn simulator_dropouts_panorama() -> Result<DepthPanorama, String> {
    let mut pano = simulator_panorama()?;
    let ground = vec![true; pano.range_m.len()];
    let mut stats = DropoutStats::default();
    // Fewer clusters than on the street: the simulator's panorama already lacks 30 % (sky).
    generic_dropouts(&mut pano, &ground, STREET_CLUSTERS / 3, &mut ChaCha8Rng::seed_from_u64(23), &mut stats);
    Ok(quantised(pano))
}

/// Fractions of a panorama's pixels without a return, by cause.
#[derive(Clone, Copy, Debug, Default)]
pub struct DropoutStats {
    /// Nothing within range (sky, beyond the scene).
    pub sky: f64,
    /// Windows: glass lets the beam through.
    pub glass: f64,
    /// Dark car paint.
    pub dark_cars: f64,
    /// Dark ground patches (wet asphalt, oil, shadowed grass).
    pub dark_ground: f64,
    /// Ground seen at grazing incidence far away.
    pub grazing: f64,
    /// Clusters of missing returns (edges, crosstalk, dust).
    pub clusters: f64,
    /// Isolated single pixels.
    pub single: f64,
    /// All of them.
    pub total: f64,
}

/// The street rendered with the primitive each pixel hit, then the dropout model, seeded.
fn street_dropouts(seed: u64) -> (DepthPanorama, DropoutStats) {
    let geometry = PanoramaGeometry::default_lidar();
    let scene = Scene::street(STREET_SENSOR_HEIGHT_M);
    let ground_z = -STREET_SENSOR_HEIGHT_M;
    let n = geometry.len() as f64;
    let mut pano = DepthPanorama::empty(geometry);
    // Primitive index of each pixel's hit (`None`: no return).
    let mut hit: Vec<Option<usize>> = vec![None; geometry.len()];
    let mut stats = DropoutStats::default();
    for row in 0..geometry.rows {
        let (se, ce) = geometry.elevation_of_row(row).sin_cos();
        for col in 0..geometry.cols {
            let (sa, ca) = geometry.azimuth_of_col(col).sin_cos();
            let dir = [ce * ca, ce * sa, se];
            let nearest =
                scene.primitives.iter().enumerate().filter_map(|(i, p)| p.intersect(dir).map(|t| (t, i))).fold(
                    None,
                    |best: Option<(f64, usize)>, (t, i)| match best {
                        Some((bt, _)) if bt <= t => best,
                        _ => Some((t, i)),
                    },
                );
            let i = row * geometry.cols + col;
            if let Some((t, p)) = nearest.filter(|(t, _)| *t <= scene.max_range_m) {
                pano.range_m[i] = t as f32;
                hit[i] = Some(p);
            }
        }
    }
    stats.sky = pano.range_m.iter().filter(|r| **r <= 0.0).count() as f64 / n;
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    // 1 cm range noise and no random dropouts yet: the model below places them.
    add_noise(&mut pano, 0.01, 0.0, &mut rng);

    // Which primitives are what (see `Scene::street`): the buildings are the boxes reaching 9 m
    // up, the cars the 1.5 m ones.
    let kind = |p: usize| match scene.primitives[p] {
        Primitive::Box { max, .. } if max[2] > ground_z + 8.0 => Kind::Building,
        Primitive::Box { max, min } if (max[2] - ground_z - 1.5).abs() < 1e-9 && max[0] - min[0] > 4.0 => {
            Kind::Car { centre_x_m: 0.5 * (min[0] + max[0]) }
        }
        Primitive::Ground { .. } => Kind::Ground,
        _ => Kind::Other,
    };
    let removed = |stats_slot: &mut f64, range: &mut f32| {
        if *range > 0.0 {
            *range = 0.0;
            *stats_slot += 1.0 / n;
        }
    };
    for (i, p) in hit.iter().enumerate() {
        let Some(p) = *p else { continue };
        let (row, col) = (i / geometry.cols, i % geometry.cols);
        let rho = f64::from(pano.range_m[i]);
        let (se, ce) = geometry.elevation_of_row(row).sin_cos();
        let (sa, ca) = geometry.azimuth_of_col(col).sin_cos();
        let point = [rho * ce * ca, rho * ce * sa, rho * se];
        match kind(p) {
            Kind::Building => {
                // Windows 1.2 m wide every 4 m along the street, 1.2 m tall on every 3 m storey
                // from 1 m up; glass returns nothing, except a few reflections.
                let along = point[0].rem_euclid(4.0);
                let up = point[2] - ground_z;
                let in_window = (1.0..2.2).contains(&along) && up > 1.0 && (up - 1.0).rem_euclid(3.0) < 1.2;
                if in_window && rng.random::<f64>() < 0.92 {
                    removed(&mut stats.glass, &mut pano.range_m[i]);
                }
            }
            Kind::Car { centre_x_m } => {
                // One dark car (the one at x = 6 m): most of its returns are lost; the others
                // are light.
                let dropout = if (centre_x_m - 6.0).abs() < 0.5 { 0.7 } else { 0.08 };
                if rng.random::<f64>() < dropout {
                    removed(&mut stats.dark_cars, &mut pano.range_m[i]);
                }
            }
            Kind::Ground | Kind::Other => {}
        }
    }
    let ground: Vec<bool> = hit.iter().map(|h| h.is_some_and(|p| kind(p) == Kind::Ground)).collect();
    generic_dropouts(&mut pano, &ground, STREET_CLUSTERS, &mut rng, &mut stats);
    stats.total = pano.range_m.iter().filter(|r| **r <= 0.0).count() as f64 / n;
    (quantised(pano), stats)
}

/// What a primitive of the street is.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Kind {
    Ground,
    Building,
    /// A car centred at x = `centre_x_m`.
    Car {
        centre_x_m: f64,
    },
    Other,
}

/// Clusters of missing returns placed on the street panorama.
const STREET_CLUSTERS: usize = 260;

/// The scene-independent dropouts: dark ground patches, far ground at grazing incidence
/// (`ground` marks the pixels on the ground), `clusters` clusters of missing returns, single
/// pixels.
fn generic_dropouts(
    pano: &mut DepthPanorama,
    ground: &[bool],
    clusters: usize,
    rng: &mut ChaCha8Rng,
    stats: &mut DropoutStats,
) {
    let g = pano.geometry;
    let n = g.len() as f64;
    let remove = |slot: &mut f64, range: &mut f32| {
        if *range > 0.0 {
            *range = 0.0;
            *slot += 1.0 / n;
        }
    };
    // Dark ground patches: discs on the ground plane, 1–5 m across, 2–20 m away, where 85 % of
    // the returns are lost (wet or dark asphalt, oil stains, shadowed grass).
    let patches: Vec<([f64; 2], f64)> = (0..14)
        .map(|_| {
            let (distance, azimuth) = (rng.random_range(2.0..20.0), rng.random_range(0.0..std::f64::consts::TAU));
            ([distance * azimuth.cos(), distance * azimuth.sin()], rng.random_range(0.5..2.5))
        })
        .collect();
    for i in 0..g.len() {
        let rho = f64::from(pano.range_m[i]);
        if rho <= 0.0 || !ground.get(i).copied().unwrap_or(false) {
            continue;
        }
        let (row, col) = (i / g.cols, i % g.cols);
        let elevation = g.elevation_of_row(row);
        if elevation >= 0.0 {
            continue;
        }
        let (r, azimuth) = (rho * elevation.cos(), g.azimuth_of_col(col));
        let xy = [r * azimuth.cos(), r * azimuth.sin()];
        let dark = patches.iter().any(|(c, radius)| (xy[0] - c[0]).hypot(xy[1] - c[1]) < *radius);
        if dark && rng.random::<f64>() < 0.85 {
            remove(&mut stats.dark_ground, &mut pano.range_m[i]);
            continue;
        }
        // Grazing incidence: from 12 m out, the ground loses returns, up to 50 % at 40 m.
        let grazing = ((rho - 12.0) / 28.0).clamp(0.0, 1.0) * 0.5;
        if rng.random::<f64>() < grazing {
            remove(&mut stats.grazing, &mut pano.range_m[i]);
        }
    }
    // Clusters: blobs 1–5 rows tall and 2–40 columns wide (elongated along the scan), anywhere.
    for _ in 0..clusters {
        let (row, col) = (rng.random_range(0..g.rows), rng.random_range(0..g.cols));
        let (half_rows, half_cols) = (rng.random_range(0..3usize), rng.random_range(1..20usize));
        for r in row.saturating_sub(half_rows)..(row + half_rows + 1).min(g.rows) {
            for k in 0..=2 * half_cols {
                // Elliptical blob, wrapping in azimuth.
                let dr = r.abs_diff(row) as f64 / (half_rows as f64 + 0.5);
                let dc = k.abs_diff(half_cols) as f64 / (half_cols as f64 + 0.5);
                if dr * dr + dc * dc <= 1.0 {
                    let c = (col + g.cols + k - half_cols) % g.cols;
                    remove(&mut stats.clusters, &mut pano.range_m[r * g.cols + c]);
                }
            }
        }
    }
    // Isolated single pixels.
    for range in pano.range_m.iter_mut() {
        if rng.random::<f64>() < 0.015 {
            remove(&mut stats.single, range);
        }
    }
}

/// The panorama after a round trip through 16-bit counts of [`SIM_RANGE_SCALE_M`]: what a PNG of
/// it holds.
fn quantised(pano: DepthPanorama) -> DepthPanorama {
    let counts = pano.to_counts(SIM_RANGE_SCALE_M);
    DepthPanorama::from_counts(pano.geometry, &counts, SIM_RANGE_SCALE_M).unwrap_or(pano)
}
