//! Safe region, local goal and DWA behaviour.

// Test helpers outside #[test] functions unwrap too: a failure there is a test failure.
#![allow(clippy::unwrap_used)]

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use spomp_core::{PanoramaGeometry, Point2, Pose2, Twist2};
use spomp_local_planner::synthetic::{Primitive, Scene};
use spomp_local_planner::{
    Dwa, DwaParams, LocalGoalParams, LocalPlannerParams, SafeRegion, TerrainAnalyzer, TerrainParams, local_goal_cost,
    select_local_goal,
};

const H: f64 = 0.4;

fn region_of(scene: &Scene) -> SafeRegion {
    let g = PanoramaGeometry::default_lidar();
    let params = TerrainParams::default();
    let mut a = TerrainAnalyzer::new(g, params.clone()).unwrap();
    let out = a.analyze(&scene.render(g)).unwrap();
    SafeRegion::from_terrain(out, &params).unwrap()
}

/// A 1.2 m wide, 1 m tall box 2.5 m ahead of the robot.
fn box_ahead() -> Scene {
    Scene::flat(H).with(Primitive::Box { min: [2.5, -0.6, -H], max: [3.1, 0.6, 0.6] })
}

#[test]
fn region_polygon_matches_the_scan() {
    // 8 bins: ranges 1, 2, 1, 2, ... Bin 0 along +x, bin 2 along −y (clockwise).
    let ranges = [1.0, 2.0, 1.0, 2.0, 1.0, 2.0, 1.0, 2.0];
    let r = SafeRegion::from_ranges(&ranges, &[false; 8], 2.0).unwrap();
    assert!(r.contains(Point2::new(0.95, 0.0)));
    assert!(!r.contains(Point2::new(1.05, 0.0)));
    assert!(r.contains(Point2::new(0.0, -0.95)));
    assert!(!r.contains(Point2::new(0.0, -1.05)));
    let diag = std::f64::consts::FRAC_1_SQRT_2;
    assert!(r.contains(Point2::new(1.9 * diag, -1.9 * diag)));
    assert!(!r.contains(Point2::new(2.1 * diag, -2.1 * diag)));
    // 8 triangles of area ½·1·2·sin 45°.
    assert!((r.area_m2() - 8.0 * 0.5 * 2.0 * diag).abs() < 1e-9);
}

#[test]
fn uniform_samples_lie_inside_and_cover_the_region() {
    let region = region_of(&box_ahead());
    let mut rng = ChaCha8Rng::seed_from_u64(1);
    let mut left = 0;
    let n = 4000;
    for _ in 0..n {
        let p = region.sample_uniform(&mut rng).unwrap();
        // Samples are inside (up to the fan-edge rounding of the sector lookup).
        let shrunk = p * 0.999;
        assert!(region.contains(shrunk), "{p:?}");
        left += (p.y > 0.0) as usize;
    }
    // The scene is symmetric about the x axis: about half the area is on the left.
    let frac = left as f64 / n as f64;
    assert!((frac - 0.5).abs() < 0.05, "{frac}");
}

#[test]
fn local_goal_is_safe_and_prefers_the_goal_direction() {
    let region = region_of(&box_ahead());
    let params = LocalGoalParams::default();
    let mut rng = ChaCha8Rng::seed_from_u64(3);
    // A goal to the front-left, beyond the known region.
    let goal = Point2::new(10.0, 6.0);
    let g = select_local_goal(&region, goal, None, &params, &mut rng).unwrap();
    assert!(region.contains(g * 0.999));
    assert!(g.x > 0.0 && g.y > 0.0, "{g:?}");
    // It beats every one of many other samples in the region.
    let best = local_goal_cost(g, goal, None, params.consistency_weight);
    for _ in 0..200 {
        let x = region.sample_uniform(&mut rng).unwrap();
        assert!(local_goal_cost(x, goal, None, params.consistency_weight) >= best - 0.2);
    }
    // A goal in plain sight is taken as is.
    let near = Point2::new(-1.0, 1.0);
    assert_eq!(select_local_goal(&region, near, None, &params, &mut rng), Some(near));
    // No area, no goal.
    let empty = SafeRegion::from_ranges(&[0.0; 16], &[true; 16], 2.0).unwrap();
    assert_eq!(select_local_goal(&empty, goal, None, &params, &mut rng), None);
}

#[test]
fn consistency_term_keeps_the_previous_side() {
    // Goal straight behind the box: both sides are equally good, the previous goal decides.
    let region = region_of(&box_ahead());
    let params = LocalGoalParams { include_goal: false, ..LocalGoalParams::default() };
    let goal = Point2::new(8.0, 0.0);
    for side in [1.0, -1.0] {
        let previous = Some(Point2::new(3.0, 1.5 * side));
        for seed in 0..5 {
            let mut rng = ChaCha8Rng::seed_from_u64(seed);
            let g = select_local_goal(&region, goal, previous, &params, &mut rng).unwrap();
            assert!(g.y * side > 0.0, "side {side}, seed {seed}: {g:?}");
        }
    }
    // Same seed, same answer.
    let a = select_local_goal(&region, goal, None, &params, &mut ChaCha8Rng::seed_from_u64(9));
    let b = select_local_goal(&region, goal, None, &params, &mut ChaCha8Rng::seed_from_u64(9));
    assert_eq!(a, b);
}

#[test]
fn dwa_respects_the_dynamic_window_and_never_reverses() {
    let region = region_of(&Scene::flat(H));
    let params = DwaParams::default();
    let mut dwa = Dwa::new(params.clone()).unwrap();
    let dt = 1.0 / params.rate_hz;
    let mut current = Twist2::ZERO;
    // Goal behind the robot: it must turn, not back up.
    let goal = Point2::new(-3.0, 0.5);
    let mut most_left = 0.0f64;
    for _ in 0..50 {
        let next = dwa.step(current, goal, &region);
        assert!(next.v >= 0.0 && next.v <= params.max_speed_mps + 1e-12);
        assert!(next.omega.abs() <= params.max_turn_rate_radps + 1e-12);
        assert!((next.v - current.v).abs() <= params.max_accel_mps2 * dt + 1e-9);
        assert!((next.omega - current.omega).abs() <= params.max_angular_accel_radps2 * dt + 1e-9);
        current = next;
        most_left = most_left.max(current.omega);
    }
    // It turned towards the goal side (left, ω > 0), at the full rate.
    assert!(most_left > 0.9, "{most_left}");
}

#[test]
fn dwa_drives_towards_a_clear_goal() {
    let region = region_of(&Scene::flat(H));
    let mut dwa = Dwa::new(DwaParams::default()).unwrap();
    let mut current = Twist2::ZERO;
    for _ in 0..20 {
        current = dwa.step(current, Point2::new(3.0, 0.0), &region);
    }
    assert!(current.v > 1.0, "{current:?}");
    assert!(current.omega.abs() < 0.2, "{current:?}");
}

/// Closed loop: unicycle in the region's frame, the region fixed (one panorama).
fn drive(region: &SafeRegion, goal: Point2, steps: usize) -> Vec<Pose2> {
    let params = DwaParams::default();
    let dt = 1.0 / params.rate_hz;
    let mut dwa = Dwa::new(params).unwrap();
    let (mut pose, mut cmd) = (Pose2::default(), Twist2::ZERO);
    let mut path = vec![pose];
    for _ in 0..steps {
        cmd = dwa.step_in_region(cmd, pose, goal, region);
        let yaw = pose.yaw + 0.5 * cmd.omega * dt;
        pose = Pose2::new(pose.x + cmd.v * dt * yaw.cos(), pose.y + cmd.v * dt * yaw.sin(), pose.yaw + cmd.omega * dt);
        path.push(pose);
    }
    path
}

#[test]
fn dwa_steers_around_an_obstacle_ahead() {
    let region = region_of(&box_ahead());
    // The global goal is straight behind the box; the local goal comes out beside it.
    let mut rng = ChaCha8Rng::seed_from_u64(5);
    let params = LocalGoalParams::default();
    let previous = Some(Point2::new(3.0, 1.5));
    let goal = select_local_goal(&region, Point2::new(8.0, 0.0), previous, &params, &mut rng).unwrap();
    assert!(goal.y > 0.8, "{goal:?}");
    // With the 2 m reachability gap the known ground reaches past the box: the local goal lies
    // beyond it, about 7 m away.
    let path = drive(&region, goal, 100);
    for p in &path {
        // Never inside the box or within 0.2 m of it.
        let inside = p.x > 2.3 && p.x < 3.3 && p.y.abs() < 0.8;
        assert!(!inside, "hit the box at {p:?}");
        assert!(region.contains(p.position()), "left the safe region at {p:?}");
    }
    let end = path.last().unwrap().position();
    assert!(end.distance(goal) < 0.6, "ended at {end:?}, goal {goal:?}");
}

#[test]
fn params_round_trip_and_reject_unknown_keys() {
    let p = LocalPlannerParams::simulation();
    let json = serde_json::to_string(&p).unwrap();
    let back: LocalPlannerParams = serde_json::from_str(&json).unwrap();
    assert_eq!(p, back);
    let partial: LocalPlannerParams = serde_json::from_str(r#"{"terrain": {"slope_threshold": 0.25}}"#).unwrap();
    assert_eq!(partial.terrain.slope_threshold, 0.25);
    assert_eq!(partial.dwa, DwaParams::default());
    assert!(serde_json::from_str::<LocalPlannerParams>(r#"{"terrain": {"slope": 1}}"#).is_err());
    assert!(p.validate().is_ok());
    let bad = DwaParams { speed_samples: 0, ..DwaParams::default() };
    assert!(Dwa::new(bad).is_err());
}
