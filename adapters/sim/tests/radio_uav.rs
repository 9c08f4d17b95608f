//! The radio (ranges, kills, blackouts, budgets) and the UAV (flight, orthomap reveal).

use spomp_core::{AerialMap, ClassTable, GridSpec, Point2, Pose2, RobotId, Time, UNKNOWN_CLASS};
use spomp_sim::{
    Blackout, Faults, KillFault, LinkTier, OrthoCamera, Radio, RadioNode, RadioParams, Region, Uav, UavParams,
};
use spomp_world::{World, generate_city};

fn node(x: f64, y: f64) -> RadioNode {
    RadioNode { position: Point2::new(x, y), alive: true }
}

#[test]
fn ranges_give_the_papers_tiers() {
    let radio = Radio::new(RadioParams::default(), &Faults::default()).unwrap();
    let t = Time::from_millis(1000);
    let a = node(0.0, 0.0);
    let all = radio.link(t, &a, &node(29.9, 0.0), 0.1).unwrap();
    assert_eq!(all.tier, LinkTier::All);
    assert_eq!(all.budget_bytes, 100_000, "1 MB/s for 0.1 s");
    assert_eq!(radio.link(t, &a, &node(30.0, 0.0), 0.1).map(|l| l.tier), Some(LinkTier::All));
    let small = radio.link(t, &a, &node(30.0, 40.0), 0.5).unwrap();
    assert_eq!(small.tier, LinkTier::Small, "exactly 50 m");
    assert_eq!(small.budget_bytes, 2_000);
    assert!(radio.link(t, &a, &node(50.01, 0.0), 0.1).is_none());
    // Symmetric.
    assert_eq!(radio.link(t, &node(29.0, 0.0), &a, 0.1), radio.link(t, &a, &node(29.0, 0.0), 0.1));
}

#[test]
fn killed_robots_have_no_links() {
    let faults = Faults { kill: vec![KillFault { robot: RobotId::new("ugv2"), at_s: 60.0 }], ..Faults::default() };
    let radio = Radio::new(RadioParams::default(), &faults).unwrap();
    let id = RobotId::new("ugv2");
    assert!(faults.is_alive(&id, Time::from_secs_f64(59.9)));
    assert!(!faults.is_alive(&id, Time::from_secs_f64(60.0)));
    assert!(faults.is_alive(&RobotId::new("ugv1"), Time::from_secs_f64(1e4)));
    let t = Time::from_secs_f64(61.0);
    let nodes =
        [node(0.0, 0.0), RadioNode { position: Point2::new(1.0, 0.0), alive: faults.is_alive(&id, t) }, node(2.0, 0.0)];
    let mut links = Vec::new();
    radio.links_into(t, &nodes, 0.1, &mut links);
    assert_eq!(links.iter().map(|(i, j, _)| (*i, *j)).collect::<Vec<_>>(), vec![(0, 2)]);
}

#[test]
fn blackouts_cut_links_in_their_window_and_region() {
    let faults = Faults {
        blackouts: vec![
            Blackout { start_s: 10.0, end_s: 20.0, region: None },
            Blackout {
                start_s: 100.0,
                end_s: 200.0,
                region: Some(Region::Polygon {
                    points: vec![
                        Point2::new(50.0, -10.0),
                        Point2::new(60.0, -10.0),
                        Point2::new(60.0, 10.0),
                        Point2::new(50.0, 10.0),
                    ],
                }),
            },
            Blackout {
                start_s: 300.0,
                end_s: 400.0,
                region: Some(Region::Circle { center: Point2::new(0.0, 0.0), radius_m: 5.0 }),
            },
        ],
        ..Faults::default()
    };
    let radio = Radio::new(RadioParams::default(), &faults).unwrap();
    let at = Time::from_secs_f64;
    let (a, b) = (node(0.0, 0.0), node(10.0, 0.0));
    assert!(radio.link(at(9.99), &a, &b, 0.1).is_some());
    assert!(radio.link(at(10.0), &a, &b, 0.1).is_none());
    assert!(radio.link(at(19.99), &a, &b, 0.1).is_none());
    assert!(radio.link(at(20.0), &a, &b, 0.1).is_some());
    // Regional: only links with an end inside the polygon.
    let (c, d) = (node(55.0, 0.0), node(45.0, 0.0));
    assert!(radio.link(at(150.0), &c, &d, 0.1).is_none());
    assert!(radio.link(at(150.0), &a, &b, 0.1).is_some());
    assert!(radio.link(at(250.0), &c, &d, 0.1).is_some());
    // Circle around a.
    assert!(radio.link(at(350.0), &a, &b, 0.1).is_none());
    assert!(radio.link(at(350.0), &b, &node(20.0, 0.0), 0.1).is_some());
}

#[test]
fn faults_parse_from_yaml_and_reject_unknown_keys() {
    let yaml = "kill: [{robot: ugv3, at_s: 600}]\nblackouts:\n  - {start_s: 10, end_s: 20, region: {circle: {center: {x: 1, y: 2}, radius_m: 30}}}\nodometry_noise_scale: 2\n";
    let f: Faults = serde_saphyr::from_str(yaml).unwrap();
    assert_eq!(f.kill_time(&RobotId::new("ugv3")), Some(Time::from_secs_f64(600.0)));
    assert_eq!(f.odometry_noise_scale, 2.0);
    assert!(f.validate().is_ok());
    assert!(serde_saphyr::from_str::<Faults>("kil: []\n").is_err());
    let bad = Faults { blackouts: vec![Blackout { start_s: 5.0, end_s: 1.0, region: None }], ..Faults::default() };
    assert!(Radio::new(RadioParams::default(), &bad).is_err());
    assert!(Radio::new(RadioParams { small_range_m: f64::NAN, ..RadioParams::default() }, &Faults::default()).is_err());
}

#[test]
fn uav_flies_waypoints_at_speed() {
    let mut uav = Uav::new(UavParams { speed_mps: 5.0, ..UavParams::default() }, Pose2::new(0.0, 0.0, 0.0)).unwrap();
    uav.set_route(vec![Point2::new(10.0, 0.0), Point2::new(10.0, 10.0)]);
    assert_eq!(uav.step(1.0), 5.0);
    assert_eq!(uav.pose().position(), Point2::new(5.0, 0.0));
    // 3 s = 15 m: 5 m to the first waypoint, then 10 m north: exactly the second.
    uav.step(3.0);
    assert!(uav.pose().position().distance(Point2::new(10.0, 10.0)) < 1e-9);
    assert!(uav.route_done());
    assert!((uav.pose().yaw - std::f64::consts::FRAC_PI_2).abs() < 1e-12);
    assert_eq!(uav.step(1.0), 0.0, "hovers when done");
    assert!((uav.distance_m() - 20.0).abs() < 1e-9);
    uav.go_to(Point2::new(10.0, 0.0));
    assert_eq!(uav.target(), Some(Point2::new(10.0, 0.0)));
}

#[test]
fn camera_reveals_each_cell_once_and_tiles_rebuild_the_world() {
    let world = generate_city(
        &spomp_world::CityParams {
            width_m: 120.0,
            height_m: 120.0,
            vehicle_clusters: 2,
            roadblocks: 1,
            ..Default::default()
        },
        4,
    )
    .unwrap();
    let params = UavParams { footprint_size_m: 40.0, tile_cells: 32, ..UavParams::default() };
    let mut cam = OrthoCamera::new(&params, &world, 0).unwrap();
    let mut map = world.unknown_map();
    let tiles = cam.reveal(&world, Pose2::new(30.0, 30.0, 0.0));
    assert!(tiles.iter().all(|t| t.width <= 32 && t.height <= 32 && t.is_consistent()));
    let n: usize = tiles.iter().map(|t| t.class.iter().filter(|&&c| c != UNKNOWN_CLASS).count()).sum();
    assert_eq!(n, 80 * 80, "a 40 m square at 0.5 m");
    assert_eq!(cam.revealed_cells(), 80 * 80);
    for t in &tiles {
        map.apply_tile(t);
    }
    // Nothing new from the same spot; half new from 20 m further east.
    assert!(cam.reveal(&world, Pose2::new(30.0, 30.0, 1.0)).is_empty());
    let more = cam.reveal(&world, Pose2::new(50.0, 30.0, 0.0));
    let n2: usize = more.iter().map(|t| t.class.iter().filter(|&&c| c != UNKNOWN_CLASS).count()).sum();
    assert_eq!(n2, 40 * 80);
    // A lawnmower over the whole world rebuilds it exactly.
    for y in (0..=120).step_by(20) {
        for x in (0..=120).step_by(20) {
            for t in cam.reveal(&world, Pose2::new(x as f64, y as f64, 0.0)) {
                map.apply_tile(&t);
            }
        }
    }
    for t in &more {
        map.apply_tile(t);
    }
    assert_eq!(map.class, world.map().class);
    assert_eq!(map.rgb, world.map().rgb);
    assert_eq!(map.elevation, world.map().elevation);
    assert!(cam.reveal(&world, Pose2::new(f64::NAN, 0.0, 0.0)).is_empty());
}

#[test]
fn label_noise_flips_about_the_requested_fraction() {
    let spec = GridSpec::new(Point2::new(0.0, 0.0), 0.5, 200, 200);
    let world = World::flat(spec, ClassTable::default_table(), 0, 0.0).unwrap();
    let params = UavParams { footprint_size_m: 100.0, label_noise_probability: 0.2, ..UavParams::default() };
    let mut cam = OrthoCamera::new(&params, &world, 7).unwrap();
    let mut map = AerialMap::unknown(spec);
    for t in cam.reveal(&world, Pose2::new(50.0, 50.0, 0.0)) {
        map.apply_tile(&t);
    }
    let wrong = map.class.iter().filter(|&&c| c != 0).count() as f64 / map.class.len() as f64;
    // 20 % are relabelled with a random class, one in eight of which is the true one.
    assert!((wrong - 0.2 * 7.0 / 8.0).abs() < 0.02, "{wrong}");
    assert!(OrthoCamera::new(&UavParams { label_noise_probability: 2.0, ..params }, &world, 0).is_err());
}
