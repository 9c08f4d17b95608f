//! The ground robot: curbs stop it except at ramps (it may roll off one), obstacles stop it, runs are deterministic.

use proptest::prelude::*;
use spomp_core::{Cell, ClassTable, GridSpec, Point2, Pose2, Time, Twist2};
use spomp_sim::{OdometryModel, OdometryNoiseParams, Ugv, UgvParams};
use spomp_world::{CityParams, UgvLimits, World, footprint_heights, generate_city, ground_truth_traversability};

/// 40 m × 30 m: road below y = 10 m, a 0.15 m sidewalk above it, with a ramp across the
/// sidewalk's first 3 m at x ∈ [20, 23) rising 0.025 m per cell, and a building at
/// x ∈ [30, 35), y ∈ [2, 8).
fn curb_world() -> World {
    let spec = GridSpec::new(Point2::new(0.0, 0.0), 0.5, 80, 60);
    let mut w = World::flat(spec, ClassTable::default_table(), 0, 0.0).expect("flat world");
    for row in 0..spec.height {
        for col in 0..spec.width {
            let c = spec.center(Cell::new(col, row));
            let cell = Cell::new(col, row);
            if c.y > 10.0 {
                let ramp = (20.0..23.0).contains(&c.x) && c.y < 13.0;
                let e = if ramp { ((c.y - 10.0) / 3.0 * 0.15 * 1000.0).round() as f32 / 1000.0 } else { 0.15 };
                w.set_cell(cell, 3, if ramp { [214, 180, 70] } else { [168, 168, 162] }, e);
            } else if (30.0..35.0).contains(&c.x) && (2.0..8.0).contains(&c.y) {
                w.set_cell(cell, 2, [70, 70, 70], 15.0);
            }
        }
    }
    w
}

fn drive(w: &World, robot: &mut Ugv, cmd: Twist2, seconds: f64) {
    for _ in 0..(seconds / 0.1).round() as usize {
        robot.step(w, cmd, 0.1);
    }
}

#[test]
fn curb_stops_the_robot_but_a_ramp_lets_it_up() {
    let w = curb_world();
    let north = std::f64::consts::FRAC_PI_2;
    let mut blocked = Ugv::new(&w, UgvParams::default(), Pose2::new(5.0, 5.0, north)).unwrap();
    drive(&w, &mut blocked, Twist2 { v: 1.0, omega: 0.0 }, 15.0);
    assert!(blocked.pose().y < 10.0 - 0.45 && blocked.pose().y > 9.0, "stopped at the curb: {:?}", blocked.pose());
    assert_eq!(blocked.base_elevation_m(), 0.0);
    assert_eq!(blocked.collisions(), 1, "one contact, however long it pushes");
    assert_eq!(blocked.twist().v, 0.0);

    let mut climber = Ugv::new(&w, UgvParams::default(), Pose2::new(21.5, 5.0, north)).unwrap();
    drive(&w, &mut climber, Twist2 { v: 1.0, omega: 0.0 }, 15.0);
    assert!(climber.pose().y > 15.0, "up the ramp: {:?}", climber.pose());
    assert!((climber.base_elevation_m() - 0.15).abs() < 1e-6);
    assert_eq!(climber.collisions(), 0);
    assert!((climber.distance_m() - (climber.pose().y - 5.0)).abs() < 1e-6);

    // It rolls off the curb away from the ramp (a 0.15 m drop is within `max_drop_m`), and
    // cannot climb back up where it came down.
    let mut down = Ugv::new(&w, UgvParams::default(), Pose2::new(5.0, 15.0, -north)).unwrap();
    drive(&w, &mut down, Twist2 { v: 1.0, omega: 0.0 }, 8.0);
    assert!(down.pose().y < 9.0 && down.base_elevation_m() == 0.0, "down on the road: {:?}", down.pose());
    assert_eq!(down.collisions(), 0);
    drive(&w, &mut down, Twist2 { v: 0.0, omega: 1.0 }, std::f64::consts::PI);
    drive(&w, &mut down, Twist2 { v: 1.0, omega: 0.0 }, 8.0);
    assert!(down.pose().y < 10.0 - 0.45 && down.base_elevation_m() == 0.0, "not back up: {:?}", down.pose());
    assert_eq!(down.collisions(), 1);
}

#[test]
fn a_drop_deeper_than_the_limit_stops_the_robot() {
    let mut w = curb_world();
    let spec = *w.spec();
    // A 0.3 m ledge: the sidewalk north of y = 10 m raised to 0.3 m west of x = 10 m.
    for row in 0..spec.height {
        for col in 0..spec.width {
            let c = spec.center(Cell::new(col, row));
            if c.y > 10.0 && c.x < 10.0 {
                w.set_cell(Cell::new(col, row), 3, [168, 168, 162], 0.3);
            }
        }
    }
    let north = std::f64::consts::FRAC_PI_2;
    let mut robot = Ugv::new(&w, UgvParams::default(), Pose2::new(5.0, 15.0, -north)).unwrap();
    drive(&w, &mut robot, Twist2 { v: 1.0, omega: 0.0 }, 8.0);
    assert!(robot.pose().y > 10.45 && robot.base_elevation_m() == 0.3, "stopped at the ledge: {:?}", robot.pose());
    assert_eq!(robot.collisions(), 1);
}

#[test]
fn buildings_stop_the_robot_outside_and_it_can_back_away() {
    let w = curb_world();
    let mut robot = Ugv::new(&w, UgvParams::default(), Pose2::new(25.0, 5.0, 0.0)).unwrap();
    drive(&w, &mut robot, Twist2 { v: 1.5, omega: 0.0 }, 10.0);
    let x = robot.pose().x;
    assert!(x <= 30.0 - 0.5 + 1e-9 && x > 29.0, "against the wall: {x}");
    assert_eq!(robot.collisions(), 1);
    // Turning on the spot is always possible; then it drives away.
    drive(&w, &mut robot, Twist2 { v: 0.0, omega: 1.0 }, std::f64::consts::PI + 0.2);
    drive(&w, &mut robot, Twist2 { v: 1.0, omega: 0.0 }, 2.0);
    assert!(robot.pose().x < x - 1.0, "{:?}", robot.pose());
}

#[test]
fn acceleration_and_speed_limits_hold() {
    let w = curb_world();
    let p = UgvParams::default();
    let mut robot = Ugv::new(&w, p.clone(), Pose2::new(5.0, 5.0, 0.0)).unwrap();
    robot.step(&w, Twist2 { v: 10.0, omega: 10.0 }, 0.1);
    assert!((robot.twist().v - p.max_accel_mps2 * 0.1).abs() < 1e-12);
    assert!((robot.twist().omega - p.max_yaw_accel_radps2 * 0.1).abs() < 1e-12);
    drive(&w, &mut robot, Twist2 { v: 10.0, omega: 0.0 }, 2.0);
    assert_eq!(robot.twist().v, p.max_speed_mps);
    // Garbage commands and steps do nothing harmful.
    let before = robot.pose();
    robot.step(&w, Twist2 { v: f64::NAN, omega: f64::INFINITY }, f64::NAN);
    assert_eq!(robot.pose(), before);
}

#[test]
fn cannot_start_inside_a_building_or_across_a_curb() {
    let w = curb_world();
    assert!(Ugv::new(&w, UgvParams::default(), Pose2::new(32.0, 5.0, 0.0)).is_err());
    assert!(Ugv::new(&w, UgvParams::default(), Pose2::new(5.0, 10.1, 0.0)).is_err());
    assert!(Ugv::new(&w, UgvParams::default(), Pose2::new(-3.0, 5.0, 0.0)).is_err());
    let trav = ground_truth_traversability(&w, &UgvLimits::default());
    assert!(!*trav.get(Point2::new(30.2, 5.0)).unwrap(), "straddling the wall");
    assert!(!*trav.get(Point2::new(5.0, 10.1)).unwrap());
    assert!(*trav.get(Point2::new(5.0, 5.0)).unwrap());
    assert!(*trav.get(Point2::new(21.5, 11.0)).unwrap(), "the middle of the ramp");
}

fn commands() -> Vec<Twist2> {
    (0..300).map(|k| Twist2 { v: 1.5 * ((k as f64) * 0.07).sin().abs(), omega: ((k as f64) * 0.05).cos() }).collect()
}

#[test]
fn same_commands_same_trajectory_and_odometry() {
    let w = generate_city(&CityParams { width_m: 150.0, height_m: 150.0, ..CityParams::default() }, 2).unwrap();
    let run = || {
        let start = w.meta.start_poses[0];
        let mut robot = Ugv::new(&w, UgvParams::default(), start).unwrap();
        let mut odom = OdometryModel::new(OdometryNoiseParams::default(), 1.0, start, 99);
        let mut trace = Vec::new();
        for (k, cmd) in commands().into_iter().enumerate() {
            robot.step(&w, cmd, 0.1);
            let o = odom.update(Time::from_millis(100 * k as i64), robot.pose(), robot.twist());
            trace.push((robot.pose(), o.pose));
        }
        (trace, robot.collisions())
    };
    assert_eq!(run(), run());
}

#[test]
fn odometry_drifts_with_noise_and_is_exact_without() {
    let w = curb_world();
    let start = Pose2::new(5.0, 5.0, 0.0);
    let mut robot = Ugv::new(&w, UgvParams::default(), start).unwrap();
    let mut exact = OdometryModel::new(OdometryNoiseParams::default(), 0.0, start, 1);
    let mut noisy = OdometryModel::new(OdometryNoiseParams::default(), 5.0, start, 1);
    for k in 0..150 {
        robot.step(&w, Twist2 { v: 1.0, omega: 0.2 }, 0.1);
        exact.update(Time::from_millis(100 * k), robot.pose(), robot.twist());
        noisy.update(Time::from_millis(100 * k), robot.pose(), robot.twist());
    }
    // Exact odometry is the true motion expressed in the start frame.
    let truth = start.between(robot.pose());
    assert!((exact.pose().x - truth.x).abs() < 1e-9 && (exact.pose().y - truth.y).abs() < 1e-9);
    let drift = noisy.pose().position().distance(truth.position());
    assert!(drift > 1e-3 && drift < 3.0, "drift {drift} m over {} m", robot.distance_m());
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 24, ..ProptestConfig::default() })]
    /// Whatever it is told, the robot never enters a building, never straddles more than a curb,
    /// and never climbs more than a step at once (it reaches the sidewalk by the ramp only).
    #[test]
    fn robot_never_enters_an_obstacle(cmds in prop::collection::vec((-2.0..3.0f64, -3.0..3.0f64), 1..120)) {
        let w = curb_world();
        let limits = UgvLimits::default();
        let mut robot = Ugv::new(&w, UgvParams::default(), Pose2::new(27.0, 5.0, 0.0)).unwrap();
        for (v, omega) in cmds {
            let base_before = robot.base_elevation_m();
            robot.step(&w, Twist2 { v, omega }, 0.25);
            let f = footprint_heights(&w, robot.pose().position(), limits.radius_m).unwrap();
            prop_assert!(f.max_m - f.min_m <= limits.max_drop_m as f32 + 1e-4, "{f:?}");
            prop_assert!(robot.base_elevation_m() - base_before <= limits.max_step_m as f32 + 1e-4);
            prop_assert_eq!(w.class_at(robot.pose().position()).map(|c| c != 2), Some(true));
        }
    }
}

#[test]
fn noisy_pose_source_has_the_requested_spread() {
    use spomp_sim::{NoisyPoseSource, PoseNoiseParams};
    let truth = Pose2::new(10.0, -4.0, 3.1);
    let params = PoseNoiseParams { position_std_m: 0.2, yaw_std_rad: 0.05 };
    let mut exact = NoisyPoseSource::new(params.clone(), 0.0, 1);
    let e = exact.estimate(Time::ZERO, truth).pose;
    assert!(e.x == truth.x && e.y == truth.y && (e.yaw - truth.yaw).abs() < 1e-12);
    let mut src = NoisyPoseSource::new(params, 1.0, 1);
    let n = 4000;
    let (mut sx, mut sxx, mut syaw) = (0.0, 0.0, 0.0);
    for k in 0..n {
        let e = src.estimate(Time::from_millis(k), truth);
        let dx = e.pose.x - truth.x;
        sx += dx;
        sxx += dx * dx;
        syaw += spomp_core::normalize_angle(e.pose.yaw - truth.yaw).powi(2);
        assert!((e.covariance[0] - 0.04).abs() < 1e-12 && e.covariance[1] == 0.0);
    }
    let mean = sx / n as f64;
    let std = (sxx / n as f64 - mean * mean).sqrt();
    assert!(mean.abs() < 0.02, "{mean}");
    assert!((std - 0.2).abs() < 0.02, "{std}");
    assert!(((syaw / n as f64).sqrt() - 0.05).abs() < 0.005);
}

#[test]
fn robots_stop_short_of_each_other() {
    use spomp_world::Obstacle;
    let w = curb_world();
    let mut a = Ugv::new(&w, UgvParams::default(), Pose2::new(5.0, 5.0, 0.0)).unwrap();
    let b = Obstacle { center: Point2::new(10.0, 5.0), radius_m: 0.5, bottom_m: 0.0, top_m: 0.6, class: 4 };
    for _ in 0..100 {
        a.step_among(&w, Twist2 { v: 1.0, omega: 0.0 }, 0.1, &[b]);
    }
    let gap = a.pose().position().distance(b.center);
    assert!((0.99..1.1).contains(&gap), "stopped {gap} m from the other robot's centre");
    assert_eq!(a.collisions(), 1);
    // Backing away is allowed.
    for _ in 0..10 {
        a.step_among(&w, Twist2 { v: -0.5, omega: 0.0 }, 0.1, &[b]);
    }
    assert!(a.pose().position().distance(b.center) > gap + 0.2);
}
