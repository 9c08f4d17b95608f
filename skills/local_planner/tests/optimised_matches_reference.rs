//! The optimised terrain pipeline (fused `analyze` and staged `analyze_observed`) gives
//! bit-identical output to the straightforward reference stages kept in `tests/reference`.

#![allow(clippy::unwrap_used)]

#[path = "reference/stages.rs"]
mod reference;

#[path = "../benches/common/panoramas.rs"]
mod panoramas;

use proptest::prelude::*;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use spomp_core::{DepthPanorama, PanoramaGeometry};
use spomp_local_planner::synthetic::{Scene, add_noise};
use spomp_local_planner::{InstructionSet, TerrainAnalyzer, TerrainOutput, TerrainParams};

/// Every buffer the reference computes, in the analyzer's layout.
struct ReferenceOutput {
    ranges: Vec<f32>,
    z: Vec<f32>,
    r: Vec<f32>,
    gradient: Vec<f32>,
    obstacle: Vec<bool>,
    column_distance: Vec<f32>,
    distance: Vec<f32>,
    traversable: Vec<bool>,
    reach_range: Vec<f32>,
    reach_obstacle: Vec<bool>,
    reach_last_row: Vec<u32>,
}

fn run_reference(depth: &DepthPanorama, p: &TerrainParams) -> ReferenceOutput {
    let g = depth.geometry;
    let (n, cols) = (g.len(), g.cols);
    let tables = reference::Tables::new(
        g.rows,
        cols,
        |row| g.elevation_of_row(row),
        p.sensor_height_m,
        p.gradient_window_m,
        p.range_noise_m,
    );
    let mut o = ReferenceOutput {
        ranges: vec![0.0; n],
        z: vec![0.0; n],
        r: vec![0.0; n],
        gradient: vec![0.0; n],
        obstacle: vec![false; n],
        column_distance: vec![0.0; n],
        distance: vec![0.0; n],
        traversable: vec![false; n],
        reach_range: vec![0.0; cols],
        reach_obstacle: vec![false; cols],
        reach_last_row: vec![0; cols],
    };
    reference::fill_holes(&depth.range_m, &mut o.ranges, cols, p.hole_fill_max_m as f32);
    reference::project(&o.ranges, &tables, &mut o.z, &mut o.r);
    let window = reference::GradientWindow {
        window_m: p.gradient_window_m as f32,
        max_window_px: (p.gradient_window_max_fraction * cols as f64) as f32,
    };
    let mut gradient_scratch = reference::GradientScratch::default();
    reference::gradients(&o.z, &o.r, &tables, window, &mut gradient_scratch, &mut o.gradient);
    let (slope, run) = (p.slope_threshold as f32, (p.min_obstacle_run_px, p.min_obstacle_run_m as f32));
    reference::obstacles(&o.gradient, &o.ranges, cols, slope, run, &mut o.obstacle);
    let mut distance_scratch = reference::DistanceScratch::default();
    reference::distance_transform(
        &o.ranges,
        &o.obstacle,
        cols,
        p.max_obstacle_distance_m as f32,
        &mut distance_scratch,
        &mut o.column_distance,
        &mut o.distance,
    );
    reference::traversable(&o.ranges, &o.distance, p.inflation_m as f32, &mut o.traversable);
    let mut reach_scratch = reference::ReachScratch::default();
    reference::reachability(
        &o.r,
        &o.ranges,
        &o.traversable,
        cols,
        p.reach_gap_m as f32,
        p.min_reach_range_m as f32,
        &mut reach_scratch,
        &mut o.reach_range,
        &mut o.reach_obstacle,
        &mut o.reach_last_row,
    );
    o
}

/// Bitwise equality, treating any two NaNs as equal (NaN marks "no return").
fn assert_bits(name: &str, got: &[f32], want: &[f32]) {
    assert_eq!(got.len(), want.len(), "{name}: length");
    for (i, (a, b)) in got.iter().zip(want).enumerate() {
        assert!(a.to_bits() == b.to_bits() || (a.is_nan() && b.is_nan()), "{name}[{i}]: {a} vs reference {b}");
    }
}

fn assert_same(out: &TerrainOutput, reference: &ReferenceOutput) {
    assert_bits("ranges", out.ranges_m(), &reference.ranges);
    assert_bits("z", out.z_m(), &reference.z);
    assert_bits("r", out.r_m(), &reference.r);
    assert_bits("gradient", out.gradient(), &reference.gradient);
    assert_eq!(out.obstacle(), &reference.obstacle[..], "obstacle");
    assert_bits("column distance", out.column_distance_m(), &reference.column_distance);
    assert_bits("distance", out.distance_m(), &reference.distance);
    assert_eq!(out.traversable(), &reference.traversable[..], "traversable");
    assert_bits("reach range", out.reach_range_m(), &reference.reach_range);
    assert_eq!(out.reach_obstacle(), &reference.reach_obstacle[..], "reach obstacle");
    assert_eq!(out.reach_last_row(), &reference.reach_last_row[..], "reach last row");
}

/// The benchmark's panorama: `Scene::street` with 1 cm noise and 2 % dropouts.
fn street_panorama(dropout: f64, seed: u64) -> DepthPanorama {
    let mut pano = Scene::street(0.4).render(PanoramaGeometry::default_lidar());
    add_noise(&mut pano, 0.01, dropout, &mut ChaCha8Rng::seed_from_u64(seed));
    pano
}

fn check(depth: &DepthPanorama, params: TerrainParams) {
    let reference = run_reference(depth, &params);
    // The obstacle and distance stages must have something to do for the comparison to mean much.
    assert!(reference.obstacle.iter().any(|&o| o));
    assert!(reference.distance.iter().any(|&d| d > 0.0 && d < params.max_obstacle_distance_m as f32));
    let mut analyzer = TerrainAnalyzer::new(depth.geometry, params).unwrap();
    assert_same(analyzer.analyze(depth).unwrap(), &reference);
    assert_same(analyzer.analyze_observed(depth, |_| {}).unwrap(), &reference);
    // Buffers reused across panoramas: a second run gives the same again.
    assert_same(analyzer.analyze(depth).unwrap(), &reference);
    // Every instruction set this processor has (the baseline always).
    let mut checked = 0;
    for set in InstructionSet::ALL {
        if analyzer.select_instruction_set(set) {
            assert_same(analyzer.analyze(depth).unwrap(), &reference);
            assert_same(analyzer.analyze_observed(depth, |_| {}).unwrap(), &reference);
            checked += 1;
        }
    }
    assert!(checked >= 1);
}

#[test]
fn bench_street_panorama_matches_reference_bit_for_bit() {
    check(&street_panorama(0.02, 7), TerrainParams::default());
}

#[test]
fn street_with_simulation_params_and_heavy_dropouts_matches_reference() {
    check(&street_panorama(0.02, 7), TerrainParams::simulation());
    check(&street_panorama(0.2, 11), TerrainParams::default());
}

/// The benchmark's panoramas with a real sensor's dropouts (a quarter and a third of the pixels
/// without a return: sky, glass, dark surfaces, clusters): many holes and short obstacle runs
/// per row, the work the hole and run searches do on real data.
#[test]
fn realistic_dropout_panoramas_match_reference() {
    let street = panoramas::street_dropouts_panorama();
    let missing = street.range_m.iter().filter(|r| **r <= 0.0).count() as f64 / street.range_m.len() as f64;
    assert!((0.1..=0.3).contains(&missing), "{missing}");
    check(&street, TerrainParams::default());
    check(&street, TerrainParams::simulation());
    check(&panoramas::simulator_dropouts_panorama().unwrap(), TerrainParams::default());
}

fn any_range() -> impl Strategy<Value = f32> {
    prop_oneof![
        6 => 0.3f32..12.0,
        1 => Just(0.0f32),
        1 => Just(f32::NAN),
        1 => Just(f32::INFINITY),
        1 => -5.0f32..0.0,
        1 => Just(f32::MAX),
        1 => Just(f32::MIN_POSITIVE),
    ]
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 48, ..ProptestConfig::default() })]

    /// Odd sizes (row blocks and SIMD chunks with remainders) and garbage ranges: still the
    /// reference's output bit for bit.
    #[test]
    fn any_panorama_matches_reference(
        rows in 2usize..27,
        cols in 3usize..45,
        fov in 0.3f64..3.1,
        slope in 0.05f64..1.0,
        max_distance in 0.2f64..3.0,
        seed in proptest::collection::vec(any_range(), 1..97),
    ) {
        let g = PanoramaGeometry { rows, cols, v_fov_rad: fov };
        let range_m: Vec<f32> = (0..g.len()).map(|i| seed[(i * 7 + i / cols) % seed.len()]).collect();
        let depth = DepthPanorama { geometry: g, range_m };
        let params = TerrainParams {
            slope_threshold: slope,
            max_obstacle_distance_m: max_distance,
            inflation_m: max_distance / 2.0,
            ..TerrainParams::default()
        };
        let reference = run_reference(&depth, &params);
        let mut analyzer = TerrainAnalyzer::new(g, params).unwrap();
        assert_same(analyzer.analyze(&depth).unwrap(), &reference);
        assert_same(analyzer.analyze_observed(&depth, |_| {}).unwrap(), &reference);
        for set in InstructionSet::ALL {
            if analyzer.select_instruction_set(set) {
                assert_same(analyzer.analyze(&depth).unwrap(), &reference);
            }
        }
    }

    /// Rows of 60–200 columns (whole 64-column words of the hole and run masks and a partial
    /// last one) with holes and obstacle runs of every length, for both run filters.
    #[test]
    fn wide_rows_with_holes_and_runs_match_reference(
        rows in 2usize..7,
        cols in 60usize..200,
        simulation in any::<bool>(),
        seed in proptest::collection::vec(any_range(), 1..61),
        holes in proptest::collection::vec((0usize..1400, 1usize..40), 0..30),
    ) {
        let g = PanoramaGeometry { rows, cols, v_fov_rad: 1.5 };
        let mut range_m: Vec<f32> = (0..g.len()).map(|i| seed[(i * 7 + i / cols) % seed.len()]).collect();
        for (at, len) in holes {
            let at = at % g.len();
            let end = (at + len).min(g.len());
            range_m[at..end].iter_mut().for_each(|r| *r = 0.0);
        }
        let depth = DepthPanorama { geometry: g, range_m };
        let params = if simulation { TerrainParams::simulation() } else { TerrainParams::default() };
        let params = TerrainParams { slope_threshold: 0.1, ..params };
        let reference = run_reference(&depth, &params);
        let mut analyzer = TerrainAnalyzer::new(g, params).unwrap();
        for set in InstructionSet::ALL {
            if analyzer.select_instruction_set(set) {
                assert_same(analyzer.analyze(&depth).unwrap(), &reference);
                assert_same(analyzer.analyze_observed(&depth, |_| {}).unwrap(), &reference);
            }
        }
    }
}
