//! Bad input never panics: garbage panoramas, scans, goals and commands.

// Test helpers outside #[test] functions unwrap too: a failure there is a test failure.
#![allow(clippy::unwrap_used)]

use proptest::prelude::*;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use spomp_core::{DepthPanorama, PanoramaGeometry, Point2, Pose2, Twist2};
use spomp_local_planner::{
    Dwa, DwaParams, LocalGoalParams, SafeRegion, TerrainAnalyzer, TerrainParams, select_local_goal,
};

fn garbage_range() -> impl Strategy<Value = f32> {
    prop_oneof![
        3 => 0.0f32..30.0,
        1 => Just(0.0f32),
        1 => Just(f32::NAN),
        1 => Just(f32::INFINITY),
        1 => Just(f32::NEG_INFINITY),
        1 => -10.0f32..0.0,
        1 => Just(f32::MAX),
        1 => Just(f32::MIN_POSITIVE),
        1 => 1e30f32..1e38,
    ]
}

fn garbage_f64() -> impl Strategy<Value = f64> {
    prop_oneof![
        3 => -20.0f64..20.0,
        1 => Just(f64::NAN),
        1 => Just(f64::INFINITY),
        1 => Just(f64::NEG_INFINITY),
        1 => Just(1e300),
    ]
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 64, ..ProptestConfig::default() })]

    #[test]
    fn garbage_panoramas_never_panic(
        rows in 2usize..12,
        cols in 3usize..40,
        fov in 0.05f64..3.1,
        seed in proptest::collection::vec(garbage_range(), 1..64),
    ) {
        let g = PanoramaGeometry { rows, cols, v_fov_rad: fov };
        let range_m: Vec<f32> = (0..g.len()).map(|i| seed[i % seed.len()]).collect();
        let depth = DepthPanorama { geometry: g, range_m };
        let params = TerrainParams::default();
        let mut a = TerrainAnalyzer::new(g, params.clone()).unwrap();
        let out = a.analyze(&depth).unwrap();
        for &d in out.distance_m() {
            prop_assert!((0.0..=params.max_obstacle_distance_m as f32).contains(&d));
        }
        for &r in out.reach_range_m() {
            prop_assert!(r >= 0.0 && !r.is_nan());
        }
        let region = SafeRegion::from_terrain(out, &params).unwrap();
        let mut rng = ChaCha8Rng::seed_from_u64(0);
        let goal = select_local_goal(
            &region, Point2::new(5.0, 1.0), None, &LocalGoalParams { samples: 20, ..Default::default() }, &mut rng,
        );
        if let Some(goal) = goal {
            let mut dwa = Dwa::new(DwaParams::default()).unwrap();
            let cmd = dwa.step(Twist2::ZERO, goal, &region);
            prop_assert!(cmd.v >= 0.0);
        }
    }

    #[test]
    fn garbage_scans_goals_and_commands_never_panic(
        ranges in proptest::collection::vec(garbage_range(), 1..50),
        gx in garbage_f64(), gy in garbage_f64(),
        v in garbage_f64(), w in garbage_f64(),
        px in garbage_f64(), yaw in garbage_f64(),
    ) {
        let obstacle = vec![true; ranges.len()];
        let region = SafeRegion::from_ranges(&ranges, &obstacle, 2.0).unwrap();
        prop_assert!(region.area_m2().is_finite());
        let _ = region.contains(Point2::new(gx, gy));
        let _ = region.clearance_at(Point2::new(gx, gy));
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        let params = LocalGoalParams { samples: 10, ..Default::default() };
        let _ = select_local_goal(&region, Point2::new(gx, gy), Some(Point2::new(px, yaw)), &params, &mut rng);
        let mut dwa = Dwa::new(DwaParams::default()).unwrap();
        let cmd = dwa.step_in_region(Twist2 { v, omega: w }, Pose2::new(px, gy, yaw), Point2::new(gx, gy), &region);
        prop_assert!(cmd.v.is_finite() && cmd.omega.is_finite() && cmd.v >= 0.0);
    }
}
