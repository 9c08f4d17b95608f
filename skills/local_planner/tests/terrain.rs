//! Terrain analysis against analytic scenes rendered by the crate's ray caster.

// Test helpers outside #[test] functions unwrap too: a failure there is a test failure.
#![allow(clippy::unwrap_used)]

use spomp_core::{DepthPanorama, PanoramaGeometry};
use spomp_local_planner::synthetic::{Primitive, Scene};
use spomp_local_planner::{TerrainAnalyzer, TerrainError, TerrainParams};

const H: f64 = 0.4;

fn geometry() -> PanoramaGeometry {
    PanoramaGeometry::default_lidar()
}

fn analyze(scene: &Scene, params: TerrainParams) -> TerrainAnalyzer {
    let depth = scene.render(geometry());
    let mut analyzer = TerrainAnalyzer::new(geometry(), params).unwrap();
    analyzer.analyze(&depth).unwrap();
    analyzer
}

/// Flat-ground horizontal range where successive rows are more than `gap` apart: the first row
/// (walking up from the bottom) whose next row up lies more than `gap` farther.
fn flat_reach_limit(g: PanoramaGeometry, gap: f64) -> f64 {
    let mut last = None;
    for row in (0..g.rows).rev() {
        let e = g.elevation_of_row(row);
        if e >= 0.0 {
            break;
        }
        let r = H / (-e).tan();
        if let Some(prev) = last
            && r - prev > gap
        {
            return prev;
        }
        last = Some(r);
    }
    last.unwrap()
}

#[test]
fn flat_plane_has_no_obstacles_and_reaches_the_gap_limit() {
    let params = TerrainParams::default();
    let a = analyze(&Scene::flat(H), params.clone());
    let out = a.output();
    assert!(out.obstacle().iter().all(|&o| !o));
    // With the 2 m gap of the defaults (decision 8) the flat ground is known out to ≈ 11 m.
    let limit = flat_reach_limit(geometry(), params.reach_gap_m) as f32;
    assert!(limit > 10.0, "{limit}");
    for (c, (&r, &o)) in out.reach_range_m().iter().zip(out.reach_obstacle()).enumerate() {
        assert!(!o, "column {c} claims an obstacle");
        assert!((r - limit).abs() < 1e-3 * limit, "column {c}: {r} vs {limit}");
    }
    // Every return on the plane is far from obstacles.
    let trav = out.traversable().iter().filter(|&&t| t).count();
    let returns = out.ranges_m().iter().filter(|&&r| r > 0.0).count();
    assert_eq!(trav, returns);
}

#[test]
fn wall_ends_reachability_in_its_columns_only() {
    // Wall across x = 4 m for y in [−1, 1] (azimuth within ±14°), 2 m tall.
    let d = 4.0;
    let scene = Scene::flat(H).with(Primitive::Box { min: [d, -1.0, -H], max: [d + 0.2, 1.0, 1.6] });
    let params = TerrainParams::default();
    let a = analyze(&scene, params.clone());
    let out = a.output();
    let g = geometry();
    let limit = flat_reach_limit(g, params.reach_gap_m) as f32;
    for c in 0..g.cols {
        let az = -g.azimuth_of_col(c).rem_euclid(std::f64::consts::TAU);
        let az = spomp_core::normalize_angle(-az);
        let (r, o) = (out.reach_range_m()[c], out.reach_obstacle()[c]);
        if az.abs() < 0.2 {
            // Straight at the wall: the obstacle region begins within W of the foot of the wall
            // (the elevation window reaches up onto it), then the inflation applies.
            let foot = d / az.cos();
            assert!(o, "column {c} (az {az:.3}) should end at the wall");
            let lo = foot - params.inflation_m - params.gradient_window_m - 0.15;
            let hi = foot - params.inflation_m + 0.05;
            assert!((lo as f32..=hi as f32).contains(&r), "column {c}: {r} not in [{lo}, {hi}]");
        } else if az.abs() > 0.6 {
            assert!(!o, "column {c} (az {az:.3}) sees no wall");
            assert!((r - limit).abs() < 1e-3 * limit, "column {c}: {r} vs {limit}");
        }
    }
}

#[test]
fn curb_is_an_obstacle_and_a_small_step_is_not() {
    let curb = |height: f64| {
        Scene::flat(H).with(Primitive::Box { min: [3.0, -50.0, -H - 1.0], max: [50.0, 50.0, -H + height] })
    };
    for params in [TerrainParams::default(), TerrainParams::simulation()] {
        let a = analyze(&curb(0.15), params.clone());
        let out = a.output();
        // Straight ahead, the curb face at 3 m is an obstacle.
        assert!(out.reach_obstacle()[0]);
        let r = out.reach_range_m()[0] as f64;
        assert!(r < 3.0 - params.inflation_m + 0.05 && r > 3.0 - params.inflation_m - 0.7, "{r}");
        // In column 0, the curb face (x = 3 m, above the ground) is mostly obstacle — its top
        // lip compares with the curb top inside the elevation window and looks flat — and
        // nothing else is.
        let g = geometry();
        let column: Vec<usize> = (0..g.rows).map(|row| row * g.cols).collect();
        let face: Vec<usize> = column
            .iter()
            .copied()
            .filter(|&i| out.point_m(i).is_some_and(|p| (p[0] - 3.0).abs() < 0.02 && p[2] > (-H + 0.005) as f32))
            .collect();
        let face_obstacles = face.iter().filter(|&&i| out.obstacle()[i]).count();
        assert!(face.len() >= 6 && face_obstacles * 3 >= face.len() * 2, "{face_obstacles}/{}", face.len());
        for &i in &column {
            if out.obstacle()[i] {
                let x = out.point_m(i).unwrap()[0];
                assert!((2.5..3.01).contains(&x), "obstacle at x = {x}");
            }
        }
    }
    // A 3 cm step is within what the slope threshold tolerates.
    let a = analyze(&curb(0.03), TerrainParams::default());
    assert!(!a.output().reach_obstacle()[0]);
    assert!(a.output().obstacle().iter().all(|&o| !o));
}

#[test]
fn ramps_below_the_threshold_pass_and_steep_ones_do_not() {
    let ramp = |grade: f64| Scene::flat(H).with(Primitive::Ramp { start_x_m: 1.5, z_m: -H, grade });
    let gentle = analyze(&ramp(0.15), TerrainParams::default());
    assert!(!gentle.output().reach_obstacle()[0]);
    let steep = analyze(&ramp(0.6), TerrainParams::default());
    assert!(steep.output().reach_obstacle()[0]);
}

#[test]
fn single_missing_pixel_is_filled_and_a_wide_gap_is_not() {
    let g = geometry();
    let mut depth = Scene::flat(H).render(g);
    let row = 200;
    let base = row * g.cols;
    let original = depth.range_m[base + 10];
    depth.range_m[base + 10] = 0.0;
    // Wrap-around hole of one pixel at column 0.
    let original_0 = depth.range_m[base];
    depth.range_m[base] = f32::NAN;
    // A 60-pixel gap: 60 · 2π/1024 · ρ ≫ 0.1 m.
    for c in 100..160 {
        depth.range_m[base + c] = 0.0;
    }
    let mut a = TerrainAnalyzer::new(g, TerrainParams::default()).unwrap();
    let out = a.analyze(&depth).unwrap();
    assert!((out.ranges_m()[base + 10] - original).abs() < 1e-4);
    assert!((out.ranges_m()[base] - original_0).abs() < 1e-4);
    assert!(out.ranges_m()[base + 100..base + 160].iter().all(|&r| r == 0.0));
}

#[test]
fn hole_size_limit_scales_with_range() {
    // One row with a 3-pixel hole: filled at 2 m (3·0.0123 m ≈ 0.037 m ≤ 0.1 m), not at 10 m
    // (3 · 0.061 m ≈ 0.18 m).
    let g = PanoramaGeometry { rows: 2, cols: 1024, v_fov_rad: 0.1 };
    for (range, filled) in [(2.0f32, true), (10.0, false)] {
        let mut depth = DepthPanorama { geometry: g, range_m: vec![range; g.len()] };
        for c in 500..503 {
            depth.range_m[c] = 0.0;
        }
        let mut a = TerrainAnalyzer::new(g, TerrainParams::default()).unwrap();
        let out = a.analyze(&depth).unwrap();
        assert_eq!(out.ranges_m()[501] > 0.0, filled, "range {range}");
    }
}

#[test]
fn wrong_geometry_is_an_error() {
    let mut a = TerrainAnalyzer::new(geometry(), TerrainParams::default()).unwrap();
    let other = PanoramaGeometry { rows: 64, cols: 1024, v_fov_rad: 1.0 };
    assert!(matches!(a.analyze(&DepthPanorama::empty(other)), Err(TerrainError::GeometryMismatch { .. })));
    let mut short = DepthPanorama::empty(geometry());
    short.range_m.pop();
    assert!(matches!(a.analyze(&short), Err(TerrainError::BufferLength { .. })));
    let bad = PanoramaGeometry { rows: 1, cols: 1024, v_fov_rad: 1.0 };
    assert!(TerrainAnalyzer::new(bad, TerrainParams::default()).is_err());
    let params = TerrainParams { slope_threshold: f64::NAN, ..TerrainParams::default() };
    assert!(TerrainAnalyzer::new(geometry(), params).is_err());
}

#[test]
fn gradient_of_a_ramp_matches_the_noise_corrected_slope() {
    // On a ramp of grade m along x, straight ahead: z differences are m times the r differences
    // and the azimuth window is symmetric (no height difference across it, so ∇_a = 0), so
    // |∇| = ∇_e = (m·Δr − η·|sin θ|)/(Δr + η_xy).
    let grade = 0.4;
    let params = TerrainParams::default();
    let scene = Scene::flat(H).with(Primitive::Ramp { start_x_m: 0.0, z_m: -H, grade });
    let a = analyze(&scene, params.clone());
    let (out, t) = (a.output(), a.tables());
    let g = geometry();
    let eta = params.range_noise_m as f32;
    let mut checked = 0;
    for row in g.rows / 2 + 2..g.rows {
        let we = t.elevation_window[row] as usize;
        let (i, j) = (row * g.cols, (row - we) * g.cols);
        if out.r_m()[j].is_nan() || out.r_m()[i].is_nan() {
            continue;
        }
        let dr = (out.r_m()[i] - out.r_m()[j]).abs();
        let (se, ce) = (t.row_sin[row].abs(), t.row_cos[row]);
        let expected = ((grade as f32 * dr - eta * se).max(0.0)) / (dr + eta * ce);
        let got = out.gradient()[i];
        assert!((got - expected).abs() < 2e-3 + 1e-2 * expected, "row {row}: {got} vs {expected}");
        checked += 1;
    }
    assert!(checked > 50);
}

#[test]
fn fused_and_staged_analysis_agree_exactly() {
    use rand::SeedableRng;
    let g = geometry();
    let mut depth = Scene::street(H).render(g);
    spomp_local_planner::synthetic::add_noise(&mut depth, 0.02, 0.05, &mut rand_chacha::ChaCha8Rng::seed_from_u64(3));
    let mut fused = TerrainAnalyzer::new(g, TerrainParams::default()).unwrap();
    let mut staged = fused.clone();
    let a = fused.analyze(&depth).unwrap();
    let mut seen = Vec::new();
    let b = staged.analyze_observed(&depth, |s| seen.push(s)).unwrap();
    assert_eq!(seen, spomp_local_planner::TerrainStage::ALL);
    let same = |x: &[f32], y: &[f32]| x.iter().zip(y).all(|(p, q)| p.to_bits() == q.to_bits());
    assert!(same(a.ranges_m(), b.ranges_m()));
    assert!(same(a.z_m(), b.z_m()) && same(a.r_m(), b.r_m()));
    assert!(same(a.gradient(), b.gradient()));
    assert_eq!(a.obstacle(), b.obstacle());
    assert!(same(a.column_distance_m(), b.column_distance_m()));
    assert!(same(a.distance_m(), b.distance_m()));
    assert_eq!(a.traversable(), b.traversable());
    assert!(same(a.reach_range_m(), b.reach_range_m()));
    assert_eq!(a.reach_obstacle(), b.reach_obstacle());
    // The street has obstacles on both sides and open road ahead and behind.
    assert!(a.obstacle().iter().any(|&o| o));
    assert!(a.reach_obstacle()[256] && a.reach_obstacle()[768]);
}
