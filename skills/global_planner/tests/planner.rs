//! Behaviour of the global planner on small synthetic maps.

#![allow(clippy::unwrap_used)] // tests may unwrap (working rules); helpers outside #[test] fns too

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use spomp_core::{
    AerialMap, Cell, ClassTable, GridSpec, MapTile, Point2, Pose2, ReachabilityScan, Time, UNKNOWN_CLASS,
};
use spomp_global_planner::synthetic::{self, CityLayout, Probe, class, color};
use spomp_global_planner::{
    EdgeState, GlobalPath, GlobalPlanner, GlobalPlannerParams, PathStatus, PlanError, TrainOutcome,
    bins_ending_at_teammates,
};

const RES: f64 = 0.5;

fn blank(width: u32, height: u32, class: u8, rgb: [u8; 3]) -> AerialMap {
    let mut m = AerialMap::unknown(GridSpec::new(Point2::new(0.0, 0.0), RES, width, height));
    m.class.fill(class);
    m.rgb.fill(rgb);
    m.elevation.fill(0.0);
    m
}

fn paint(m: &mut AerialMap, cols: std::ops::Range<u32>, rows: std::ops::Range<u32>, class: u8, rgb: [u8; 3]) {
    for r in rows {
        for c in cols.clone() {
            let i = m.spec.index(Cell::new(c, r));
            m.class[i] = class;
            m.rgb[i] = rgb;
        }
    }
}

/// 80 m × 50 m of buildings with an 8 m ring road along the border.
fn ring_map() -> AerialMap {
    let mut m = blank(160, 100, class::BUILDING, color::BUILDING);
    paint(&mut m, 0..160, 0..16, class::ROAD, color::ROAD);
    paint(&mut m, 0..160, 84..100, class::ROAD, color::ROAD);
    paint(&mut m, 0..16, 0..100, class::ROAD, color::ROAD);
    paint(&mut m, 144..160, 0..100, class::ROAD, color::ROAD);
    m
}

fn planner(params: GlobalPlannerParams, map: &AerialMap) -> GlobalPlanner {
    let mut p = GlobalPlanner::new(params, ClassTable::default_table()).unwrap();
    p.update_map(map).unwrap();
    p
}

const RING_START: Point2 = Point2::new(4.0, 10.0);
const RING_GOAL: Point2 = Point2::new(76.0, 10.0);
const BLOCK_X: f64 = 40.0;

/// Ground truth of the ring map with a roadblock across the southern road at x = 40 m.
fn ring_truth(map: &AerialMap) -> impl Fn(Point2) -> Probe + '_ {
    let base = synthetic::city_probe(map);
    move |p: Point2| {
        if (p.x - BLOCK_X).abs() <= 0.5 && p.y < 8.0 { Probe::Obstacle } else { base(p) }
    }
}

fn goes_north(path: &GlobalPath) -> bool {
    path.waypoints.iter().any(|w| w.y > 40.0)
}

/// The path edge that crosses the roadblock, and a robot pose on it 4 m before the block.
fn pose_before_block(p: &GlobalPlanner, path: &GlobalPath) -> (spomp_global_planner::EdgeId, Pose2) {
    for (k, &e) in path.edges.iter().enumerate() {
        let (a, b) = (path.waypoints[k + 1], path.waypoints[k + 2]);
        if (a.x - BLOCK_X) * (b.x - BLOCK_X) < 0.0 {
            let (a, b) = if a.x < b.x { (a, b) } else { (b, a) };
            let x = BLOCK_X - 4.0;
            let t = (x - a.x) / (b.x - a.x);
            let y = a.y + t * (b.y - a.y);
            assert!(p.edge_state(e).is_some());
            return (e, Pose2::new(x, y, (b - a).angle()));
        }
    }
    panic!("no path edge crosses the block: {:?}", path.waypoints);
}

fn scan_at(map: &AerialMap, robot: &str, pose: Pose2) -> ReachabilityScan {
    synthetic::raycast_scan(robot, Time::ZERO, pose, 720, 30.0, 0.25, ring_truth(map))
}

#[test]
fn every_easy_cell_is_covered_and_touching_regions_are_connected() {
    let map = synthetic::city_map(200, 160, CityLayout::default(), 3);
    let p = planner(GlobalPlannerParams::default(), &map);
    let table = ClassTable::default_table();
    let stats = p.graph_stats();
    assert!(stats.nodes > 5 && stats.edges >= stats.nodes - 1, "{stats:?}");
    let w = map.spec.width;
    for row in 0..map.spec.height {
        for col in 0..w {
            let cell = Cell::new(col, row);
            let c = map.class_at(cell);
            let here = p.covering_node(map.spec.center(cell));
            assert_eq!(here.is_some(), table.rank(c) <= 4, "cell {cell:?} of class {c}");
            for next in [Cell::new(col + 1, row), Cell::new(col, row + 1)] {
                if next.col >= w || next.row >= map.spec.height {
                    continue;
                }
                if let (Some(a), Some(b)) = (here, p.covering_node(map.spec.center(next)))
                    && a != b
                {
                    assert!(p.edge_between(a, b).is_some(), "regions of {a:?} and {b:?} touch at {cell:?}");
                }
            }
        }
    }
}

#[test]
fn road_network_is_connected_and_a_building_block_is_not_crossed() {
    // Two ring roads side by side, separated by a wall of buildings.
    let mut map = blank(320, 100, class::BUILDING, color::BUILDING);
    for x0 in [0u32, 170] {
        paint(&mut map, x0..x0 + 150, 0..16, class::ROAD, color::ROAD);
        paint(&mut map, x0..x0 + 150, 84..100, class::ROAD, color::ROAD);
        paint(&mut map, x0..x0 + 16, 0..100, class::ROAD, color::ROAD);
        paint(&mut map, x0 + 134..x0 + 150, 0..100, class::ROAD, color::ROAD);
    }
    let mut p = planner(GlobalPlannerParams::default(), &map);
    let path = p.plan(Point2::new(4.0, 4.0), Point2::new(70.0, 46.0)).unwrap();
    assert!(path.length_m >= 66.0 + 42.0 - 16.0, "around the block, {}", path.length_m);
    for w in &path.waypoints {
        let c = map.spec.cell_at(*w).unwrap();
        assert_eq!(map.class_at(c), class::ROAD, "waypoint {w:?} on the road");
    }
    assert!((path.waypoints[0].x - 4.0).abs() < 1e-9 && path.waypoints.last() == Some(&Point2::new(70.0, 46.0)));
    assert_eq!(p.plan(Point2::new(4.0, 4.0), Point2::new(150.0, 4.0)), Err(PlanError::NoPath));
    assert!(matches!(p.plan(Point2::new(40.0, 25.0), Point2::new(4.0, 4.0)), Err(PlanError::NotOnGraph { .. })));
    assert!(matches!(p.plan(Point2::new(-5.0, 4.0), Point2::new(4.0, 4.0)), Err(PlanError::OffMap { .. })));
    assert!(matches!(p.plan(Point2::new(f64::NAN, 4.0), Point2::new(4.0, 4.0)), Err(PlanError::NonFinite { .. })));
}

#[test]
fn a_goal_in_unmapped_territory_is_reported_as_such() {
    // A road along the south edge; the rest of the map not yet seen, but for one mapped
    // building far from the road.
    let mut map = blank(200, 100, class::BUILDING, color::BUILDING);
    map.class.fill(UNKNOWN_CLASS);
    paint(&mut map, 0..200, 0..16, class::ROAD, color::ROAD);
    paint(&mut map, 150..170, 70..90, class::BUILDING, color::BUILDING);
    let mut p = planner(GlobalPlannerParams::default(), &map);
    let start = Point2::new(4.0, 4.0);
    assert!(p.plan(start, Point2::new(90.0, 4.0)).is_ok());
    // Unknown ground next to the road attaches to the road's nodes within the attach radius.
    assert!(p.plan(start, Point2::new(90.0, 9.0)).is_ok());
    let far = p.plan(start, Point2::new(50.0, 40.0)).unwrap_err();
    assert!(matches!(far, PlanError::Unmapped { which: "goal", .. }), "{far:?}");
    assert!(far.to_string().contains("does not cover yet"), "{far}");
    let wall = p.plan(start, Point2::new(80.0, 40.0)).unwrap_err();
    assert!(matches!(wall, PlanError::NotOnGraph { which: "goal", .. }), "{wall:?}");
}

#[test]
fn own_observations_of_a_roadblock_remove_the_edge_and_the_path_reroutes() {
    let map = ring_map();
    let mut p = planner(GlobalPlannerParams::default(), &map);
    let path = p.plan(RING_START, RING_GOAL).unwrap();
    assert!(!goes_north(&path), "the southern road is shorter");
    let (edge, pose) = pose_before_block(&p, &path);
    let scan = scan_at(&map, "ugv1", pose);
    let first = p.add_scan(&scan, true).unwrap();
    assert!(first.observed[1] >= 1, "the blocked edge is judged not_trav: {first:?}");
    assert_eq!(first.edges_removed, 0, "one observation is not enough");
    assert_eq!(p.edge_state(edge), Some(EdgeState::Unknown));
    assert!(p.path_still_valid(&path));
    let second = p.add_scan(&scan, true).unwrap();
    assert!(second.edges_removed >= 1);
    assert_eq!(p.edge_state(edge), None, "removed");
    assert_eq!(p.path_status(&path), PathStatus::Blocked);
    let rerouted = p.plan(RING_START, RING_GOAL).unwrap();
    assert!(goes_north(&rerouted), "{:?}", rerouted.waypoints);
    assert!(p.graph_stats().removed_edges >= 1);
    // A map update does not bring the edge back.
    let mut newer = map.clone();
    newer.version += 1;
    newer.rgb[0] = [1, 2, 3];
    p.update_map(&newer).unwrap();
    assert!(goes_north(&p.plan(RING_START, RING_GOAL).unwrap()));
}

#[test]
fn an_edge_the_robot_failed_to_drive_is_never_planned_again() {
    let map = ring_map();
    let mut p = planner(GlobalPlannerParams::default(), &map);
    let path = p.plan(RING_START, RING_GOAL).unwrap();
    assert!(!goes_north(&path));
    let (edge, pose) = pose_before_block(&p, &path);
    let k = path.edges.iter().position(|&e| e == edge).unwrap();
    let (a, b) = (path.nodes[k], path.nodes[k + 1]);
    // The scans saw the way open (trav): experience of the drive overrules them.
    let open_scan = synthetic::raycast_scan("ugv1", Time::ZERO, pose, 720, 30.0, 0.25, synthetic::city_probe(&map));
    p.add_scan(&open_scan, true).unwrap();
    p.add_scan(&open_scan, true).unwrap();
    assert_eq!(p.edge_state(edge), Some(EdgeState::Trav));
    assert!(p.mark_failed_edge(b, a), "either order names the edge");
    assert_eq!(p.edge_state(edge), None, "removed");
    assert!(p.edge_between(a, b).is_none());
    assert!(!p.mark_failed_edge(a, b), "already gone");
    assert!(goes_north(&p.plan(RING_START, RING_GOAL).unwrap()), "not sent back the same way");
    // Neither the robot's own scans nor a map update bring it back.
    p.add_scan(&open_scan, true).unwrap();
    let mut newer = map.clone();
    newer.version += 1;
    newer.rgb[0] = [1, 2, 3];
    p.update_map(&newer).unwrap();
    assert!(p.edge_between(a, b).is_none());
    assert!(goes_north(&p.plan(RING_START, RING_GOAL).unwrap()));

    // With graph updates off (the paper's ablation) experience changes nothing.
    let mut params = GlobalPlannerParams::default();
    params.experience.graph_updates = false;
    let mut frozen = planner(params, &map);
    assert!(!frozen.mark_failed_edge(a, b));
    assert_eq!(frozen.plan(RING_START, RING_GOAL).unwrap(), path);
}

#[test]
fn other_robots_evidence_never_removes_an_edge() {
    let map = ring_map();
    let mut p = planner(GlobalPlannerParams::default(), &map);
    let path = p.plan(RING_START, RING_GOAL).unwrap();
    let (edge, pose) = pose_before_block(&p, &path);
    let scan = scan_at(&map, "ugv2", pose);
    for _ in 0..6 {
        let u = p.add_scan(&scan, false).unwrap();
        assert_eq!(u.edges_removed, 0);
    }
    assert_eq!(p.votes_at(pose.position()), 6, "other robots' scans still vote for the model");
    assert_eq!(p.edge_state(edge), Some(EdgeState::NotTrav), "marked, but kept");
    assert_eq!(p.graph_stats().removed_edges, 0);
    assert!(matches!(p.path_status(&path), PathStatus::CostRose { .. }), "{:?}", p.path_status(&path));
}

/// Ground teammates' bodies (radius `TEAMMATE_RADIUS_M`) at `mates`, on the ring map's ground
/// truth (with or without the roadblock).
fn with_teammates<'a>(base: impl Fn(Point2) -> Probe + 'a, mates: &'a [Point2]) -> impl Fn(Point2) -> Probe + 'a {
    move |p: Point2| {
        if mates.iter().any(|m| m.distance(p) <= TEAMMATE_RADIUS_M) { Probe::Obstacle } else { base(p) }
    }
}

const TEAMMATE_RADIUS_M: f64 = 1.4;

#[test]
fn teammates_across_the_road_mark_its_edge_but_a_roadblock_beside_teammates_still_cuts_it() {
    let map = ring_map();
    let fresh = || planner(GlobalPlannerParams::default(), &map);
    let mut p0 = fresh();
    let path = p0.plan(RING_START, RING_GOAL).unwrap();
    let (edge, pose) = pose_before_block(&p0, &path);
    // Three teammates side by side across the southern road where the roadblock would be (and
    // no roadblock): the robot's own scans find the road's edge not_trav at their bodies.
    let across = [Point2::new(BLOCK_X, 1.5), Point2::new(BLOCK_X, 4.0), Point2::new(BLOCK_X, 6.5)];
    let held = synthetic::raycast_scan(
        "ugv1",
        Time::ZERO,
        pose,
        720,
        30.0,
        0.25,
        with_teammates(synthetic::city_probe(&map), &across),
    );
    let mut p = fresh();
    for _ in 0..4 {
        let u = p.add_own_scan_among(&held, &across).unwrap();
        assert!(u.at_teammates >= 1 && u.observed[1] >= 1, "{u:?}");
        assert_eq!(u.edges_removed, 0, "{u:?}");
    }
    assert_eq!(p.edge_state(edge), Some(EdgeState::NotTrav), "marked, but kept");
    // Without their positions the same scans cut the road for good (the rule's reason).
    let mut blind = fresh();
    for _ in 0..2 {
        blind.add_scan(&held, true).unwrap();
    }
    assert_eq!(blind.edge_state(edge), None, "removed");

    // The pile-up this rule once caused: a robot at a roadblock with teammates in its scan
    // (queued behind it) still cuts the road at the block, since the block is not a teammate.
    let behind = [Point2::new(pose.x - 4.0, pose.y - 1.5), Point2::new(pose.x - 4.0, pose.y + 1.5)];
    let blocked =
        synthetic::raycast_scan("ugv1", Time::ZERO, pose, 720, 30.0, 0.25, with_teammates(ring_truth(&map), &behind));
    assert!(bins_ending_at_teammates(&blocked, &behind, 2.0) > 0, "the teammates show in the scan");
    let mut q = fresh();
    let first = q.add_own_scan_among(&blocked, &behind).unwrap();
    assert_eq!(first.edges_removed, 0, "one observation is not enough");
    let second = q.add_own_scan_among(&blocked, &behind).unwrap();
    assert!(second.edges_removed >= 1, "{second:?}");
    assert_eq!(q.edge_state(edge), None, "removed");
    assert!(goes_north(&q.plan(RING_START, RING_GOAL).unwrap()));
}

#[test]
fn graph_updates_off_freezes_edges() {
    let map = ring_map();
    let mut params = GlobalPlannerParams::default();
    params.experience.graph_updates = false;
    let mut p = planner(params, &map);
    let path = p.plan(RING_START, RING_GOAL).unwrap();
    let (edge, pose) = pose_before_block(&p, &path);
    let costs_before: Vec<f64> = p.edges().map(|e| e.cost).collect();
    for _ in 0..5 {
        let u = p.add_scan(&scan_at(&map, "ugv1", pose), true).unwrap();
        assert_eq!((u.edges_changed, u.observed), (0, [0, 0, 0]));
    }
    assert_eq!(p.edge_state(edge), Some(EdgeState::Unknown));
    assert!(p.edges().all(|e| e.state == EdgeState::Unknown));
    assert_eq!(p.edges().map(|e| e.cost).collect::<Vec<_>>(), costs_before);
    assert_eq!(p.plan(RING_START, RING_GOAL).unwrap(), path);
}

/// A U-shaped road (west, south, east arms) whose two northern ends are also joined by a short
/// gravel lane.
fn u_road_with_gravel_shortcut() -> AerialMap {
    let mut m = blank(120, 140, class::BUILDING, color::BUILDING);
    paint(&mut m, 0..16, 0..140, class::ROAD, color::ROAD);
    paint(&mut m, 104..120, 0..140, class::ROAD, color::ROAD);
    paint(&mut m, 0..120, 0..16, class::ROAD, color::ROAD);
    paint(&mut m, 16..104, 124..136, class::GRAVEL, color::GRAVEL);
    m
}

#[test]
fn learning_off_uses_the_class_rank_cost() {
    let map = u_road_with_gravel_shortcut();
    let (start, goal) = (Point2::new(4.0, 66.0), Point2::new(56.0, 66.0));
    // Untrained learning: every sample costs −log 0.5, so the short gravel lane wins.
    let mut learned = planner(GlobalPlannerParams::default(), &map);
    let short = learned.plan(start, goal).unwrap();
    assert!(short.length_m < 90.0, "{}", short.length_m);
    let ln2 = std::f64::consts::LN_2;
    for e in learned.edges() {
        let samples = (e.from.distance(e.to) / 1.0).ceil().max(1.0) + 1.0;
        assert!((e.cost - samples * ln2).abs() < 1e-9, "edge cost {} vs {} samples", e.cost, samples);
    }
    // Class rank: gravel (rank 1) costs 100¹ − 1 per edge, the road (rank 0) only D: the detour.
    let mut params = GlobalPlannerParams::default();
    params.learning.enabled = false;
    let mut ranked = planner(params, &map);
    let detour = ranked.plan(start, goal).unwrap();
    assert!(detour.length_m > 150.0, "{}", detour.length_m);
    for w in &detour.waypoints[1..detour.waypoints.len() - 1] {
        assert_eq!(map.class_at(map.spec.cell_at(*w).unwrap()), class::ROAD);
    }
    for e in ranked.edges() {
        let hardest = [e.from, e.to].iter().map(|p| map.class_at(map.spec.cell_at(*p).unwrap())).max().unwrap();
        if hardest == class::ROAD && e.cost < 99.0 {
            // W = 100⁰ − 1 + D with D ≥ 0 the distance to the nearest gravel (capped at 25 m).
            assert!((0.0..=25.01).contains(&e.cost), "{}", e.cost);
        }
        if hardest == class::GRAVEL {
            assert!(e.cost >= 99.0, "{}", e.cost);
        }
    }
    // The road edge nearest the gravel lane has D = 0 where it touches it.
    let road_only_far: Vec<f64> = ranked.edges().filter(|e| e.from.y < 20.0 && e.to.y < 20.0).map(|e| e.cost).collect();
    assert!(!road_only_far.is_empty());
    for c in road_only_far {
        assert!((c - 25.0).abs() < 0.1, "southern road edges are > 25 m from gravel: {c}");
    }
    assert_eq!(ranked.train(Time::from_secs_f64(100.0), &mut ChaCha8Rng::seed_from_u64(1)), TrainOutcome::Disabled);
}

#[test]
fn ramps_seen_in_one_area_rate_unseen_ramps_above_plain_curbs() {
    // Ramps 4 m wide every 10 m along the curbs.
    let layout = CityLayout { ramp_every_cells: 20, ramp_cells: 8, ..CityLayout::default() };
    let map = synthetic::city_map(300, 300, layout, 11);
    let mut p = planner(GlobalPlannerParams::default(), &map);
    let truth = synthetic::city_probe(&map);
    // Drive along the first horizontal road for x < 50 m, and up two ramps onto the sidewalk.
    let mut poses: Vec<Pose2> = (0..25).map(|k| Pose2::new(2.0 + k as f64 * 2.0, 5.0, 0.0)).collect();
    for x in [22.0, 42.0] {
        poses.extend([7.0, 9.0, 10.25, 11.5, 12.5].map(|y| Pose2::new(x, y, std::f64::consts::FRAC_PI_2)));
    }
    let mut t = 0.0;
    for pose in poses {
        let scan = synthetic::raycast_scan("ugv1", Time::from_secs_f64(t), pose, 360, 20.0, 0.25, &truth);
        p.add_scan(&scan, true).unwrap();
        t += 1.0;
    }
    assert!(p.votes_at(Point2::new(10.0, 5.0)) >= 3, "road under the robot is voted traversable");
    let mut rng = ChaCha8Rng::seed_from_u64(5);
    let outcome = p.train(Time::from_secs_f64(t), &mut rng);
    assert!(matches!(outcome, TrainOutcome::Trained { .. }), "{outcome:?}");
    assert_eq!(p.train(Time::from_secs_f64(t + 5.0), &mut rng), TrainOutcome::TooSoon);
    // The robot keeps training every 10 s on what it has seen.
    for k in 1..=4 {
        assert!(matches!(p.train(Time::from_secs_f64(t + 10.0 * k as f64), &mut rng), TrainOutcome::Trained { .. }));
    }
    // Far from where the robot was (x, y > 75 m), compare ramps and curbs.
    let (mut ramp, mut curb) = (Vec::new(), Vec::new());
    for row in 150..300u32 {
        for col in 150..300u32 {
            let cell = Cell::new(col, row);
            let i = map.spec.index(cell);
            let pt = map.spec.center(cell);
            match map.rgb[i] {
                color::RAMP => ramp.push(p.traversability_at(pt).unwrap()),
                color::CURB => curb.push(p.traversability_at(pt).unwrap()),
                _ => {}
            }
        }
    }
    let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len() as f64;
    assert!(!ramp.is_empty() && !curb.is_empty());
    let (r, c) = (mean(&ramp), mean(&curb));
    assert!(r > c + 0.2, "unseen ramps {r:.3} vs curbs {c:.3}");
    let road = p.traversability_at(Point2::new(120.0, 5.0)).unwrap();
    assert!(road > 0.8 && road > c, "unseen road {road:.3}");
}

#[test]
fn the_graph_grows_with_the_map_without_losing_edge_states() {
    let full = ring_map();
    // First only the western half is mapped.
    let mut partial = AerialMap::unknown(full.spec);
    let west = MapTile {
        col0: 0,
        row0: 0,
        width: 80,
        height: 100,
        class: (0..100u32)
            .flat_map(|r| (0..80u32).map(move |c| (c, r)))
            .map(|(c, r)| full.class_at(Cell::new(c, r)))
            .collect(),
        rgb: vec![color::ROAD; 8000],
        elevation: vec![0.0; 8000],
    };
    assert!(partial.apply_tile(&west) > 0);
    let mut p = planner(GlobalPlannerParams::default(), &partial);
    let before = p.graph_stats();
    // Drive the western road, marking edges trav.
    for k in 0..8 {
        let pose = Pose2::new(4.0, 8.0 + 4.0 * k as f64, std::f64::consts::FRAC_PI_2);
        let scan = synthetic::raycast_scan("ugv1", Time::ZERO, pose, 360, 20.0, 0.25, synthetic::city_probe(&partial));
        p.add_scan(&scan, true).unwrap();
        p.add_scan(&scan, true).unwrap();
    }
    let marked: Vec<_> = p.edges().filter(|e| e.state == EdgeState::Trav).collect();
    assert!(!marked.is_empty());
    assert!(p.plan(RING_START, RING_GOAL).is_err(), "east not mapped yet");
    let east = MapTile {
        col0: 80,
        row0: 0,
        width: 80,
        height: 100,
        class: (0..100u32)
            .flat_map(|r| (80..160u32).map(move |c| (c, r)))
            .map(|(c, r)| full.class_at(Cell::new(c, r)))
            .collect(),
        rgb: vec![color::ROAD; 8000],
        elevation: vec![0.0; 8000],
    };
    partial.apply_tile(&east);
    let grown = p.update_map(&partial).unwrap();
    assert!(grown.nodes_added > 0 && grown.edges_added > 0, "{grown:?}");
    let after = p.graph_stats();
    assert!(after.nodes > before.nodes);
    for e in &marked {
        assert_eq!(p.edge_state(e.id), Some(EdgeState::Trav), "edge {:?} kept its state", e.id);
    }
    assert_eq!(p.edges().filter(|e| e.state == EdgeState::Trav).count(), marked.len());
    assert!(p.plan(RING_START, RING_GOAL).is_ok());
    for (i, &c) in partial.class.iter().enumerate() {
        if c == class::ROAD {
            assert!(p.covering_node(partial.spec.center(partial.spec.cell_of_index(i))).is_some());
        }
    }
    // A map on another grid is refused.
    let other = blank(10, 10, class::ROAD, color::ROAD);
    assert!(p.update_map(&other).is_err());
}

#[test]
fn unknown_cells_are_not_covered_and_edge_costs_skip_them() {
    let mut map = ring_map();
    paint(&mut map, 60..70, 0..16, UNKNOWN_CLASS, [0, 0, 0]);
    let mut p = planner(GlobalPlannerParams::default(), &map);
    assert!(p.covering_node(Point2::new(32.0, 4.0)).is_none());
    assert!(p.traversability_at(Point2::new(32.0, 4.0)).is_none());
    assert!(p.traversability_at(Point2::new(-1.0, 4.0)).is_none());
    assert_eq!(p.traversability_at(Point2::new(4.0, 4.0)), Some(0.5), "untrained prior");
    assert!(p.plan(RING_START, RING_GOAL).is_ok());
}

#[test]
fn params_deserialize_with_defaults_and_reject_unknown_keys() {
    let p: GlobalPlannerParams =
        serde_json::from_str(r#"{"learning": {"enabled": false}, "sharing": {"mode": "all"}}"#).unwrap();
    assert!(!p.learning.enabled);
    assert_eq!(p.learning.hidden_units, 10);
    assert_eq!(p.experience.observations_to_mark, 2);
    assert!((p.experience.crossing_window_rad - 0.3).abs() < 1e-12);
    assert!(serde_json::from_str::<GlobalPlannerParams>(r#"{"graph": {"visibility": 3}}"#).is_err());
    let mut bad = GlobalPlannerParams::default();
    bad.graph.class_order = vec!["lava".into()];
    assert!(GlobalPlanner::new(bad, ClassTable::default_table()).is_err());
}

#[test]
fn learned_edge_cost_is_the_mean_over_mapped_samples_times_the_sample_count() {
    // A uniform 100 m road: every mapped cell has the same features, hence the same T.
    let mut map = blank(200, 20, class::ROAD, color::ROAD);
    let mut p = planner(GlobalPlannerParams::default(), &map);
    let free = |_: Point2| Probe::Free;
    for k in 0..3 {
        let scan = synthetic::raycast_scan("ugv1", Time::ZERO, Pose2::new(50.0, 5.0, 0.0), 360, 8.0, 0.25, free);
        assert!(p.add_scan(&scan, true).unwrap().cells_voted > 100, "scan {k}");
    }
    assert!(matches!(p.train(Time::ZERO, &mut ChaCha8Rng::seed_from_u64(2)), TrainOutcome::Trained { .. }));
    let t = p.traversability_at(Point2::new(20.0, 5.0)).unwrap();
    assert!(t > 0.5, "trained on traversable labels only: {t}");
    let edge = p.edges().max_by(|a, b| a.from.distance(a.to).total_cmp(&b.from.distance(b.to))).unwrap();
    let samples = edge.from.distance(edge.to).ceil() + 1.0;
    let per_sample = -t.ln();
    assert!((edge.cost - samples * per_sample).abs() < 0.05 * per_sample, "{} vs {}", edge.cost, samples * per_sample);
    // Unmap the middle of the edge: the known samples' mean is scaled back up to all samples.
    let mid = edge.from + (edge.to - edge.from) * 0.5;
    let cell = map.spec.cell_at(mid).unwrap();
    paint(&mut map, cell.col - 3..cell.col + 4, 0..20, UNKNOWN_CLASS, [0, 0, 0]);
    map.version += 1;
    p.update_map(&map).unwrap();
    assert!(p.traversability_at(mid).is_none(), "samples in the middle are unmapped now");
    let after = p.edges().find(|e| e.id == edge.id).unwrap();
    let per_sample = -p.traversability_at(Point2::new(20.0, 5.0)).unwrap().ln();
    // Three or more samples are unmapped; summing only the mapped ones would miss them.
    assert!(
        (after.cost - samples * per_sample).abs() < 0.05 * per_sample,
        "{} vs {}",
        after.cost,
        samples * per_sample
    );
}

#[test]
fn same_inputs_and_seed_give_the_same_planner() {
    let map = synthetic::city_map(200, 200, CityLayout::default(), 4);
    let run = || {
        let mut p = planner(GlobalPlannerParams::default(), &map);
        let truth = synthetic::city_probe(&map);
        for k in 0..10 {
            let pose = Pose2::new(2.0 + 3.0 * k as f64, 5.0, 0.0);
            p.add_scan(&synthetic::raycast_scan("ugv1", Time::ZERO, pose, 256, 20.0, 0.25, &truth), true).unwrap();
        }
        let outcome = p.train(Time::ZERO, &mut ChaCha8Rng::seed_from_u64(9));
        assert!(matches!(outcome, TrainOutcome::Trained { .. }), "{outcome:?}");
        (p.edges().collect::<Vec<_>>(), p.plan(Point2::new(3.0, 3.0), Point2::new(53.0, 53.0)).unwrap())
    };
    assert_eq!(run(), run());
}

mod prop {
    use super::*;
    use proptest::prelude::*;

    fn any_f32() -> impl Strategy<Value = f32> {
        prop_oneof![Just(f32::NAN), Just(f32::INFINITY), Just(-1.0f32), 0.0f32..60.0]
    }

    proptest! {
        #![proptest_config(ProptestConfig { cases: 48, ..ProptestConfig::default() })]
        #[test]
        fn arbitrary_scans_and_queries_never_panic(
            ranges in proptest::collection::vec(any_f32(), 0..64),
            flags in proptest::collection::vec(any::<bool>(), 0..64),
            x in prop_oneof![Just(f64::NAN), -20.0..100.0f64],
            y in -20.0..60.0f64,
            yaw in prop_oneof![Just(f64::INFINITY), -10.0..10.0f64],
            own in any::<bool>(),
        ) {
            thread_local! {
                static PLANNER: std::cell::RefCell<GlobalPlanner> = std::cell::RefCell::new(planner(GlobalPlannerParams::default(), &ring_map()));
            }
            let scan = ReachabilityScan { robot: "r".into(), stamp: Time::ZERO, pose: Pose2::new(x, y, yaw), range_m: ranges.clone(), obstacle: flags.clone() };
            PLANNER.with(|p| {
                let mut p = p.borrow_mut();
                let consistent = !ranges.is_empty() && ranges.len() == flags.len() && x.is_finite() && yaw.is_finite();
                prop_assert_eq!(p.add_scan(&scan, own).is_ok(), consistent);
                let _ = p.plan(Point2::new(x, y), RING_GOAL);
                let _ = p.traversability_at(Point2::new(x, y));
                Ok(())
            })?;
        }

        #[test]
        fn arbitrary_small_maps_are_covered_and_queries_never_panic(
            w in 1u32..24,
            h in 1u32..24,
            cells in proptest::collection::vec(prop_oneof![Just(0u8), Just(2), Just(3), Just(6), Just(5), Just(255)], 576),
            a in (-2.0..14.0f64, -2.0..14.0f64),
            b in (-2.0..14.0f64, -2.0..14.0f64),
        ) {
            let mut map = blank(w, h, 0, color::ROAD);
            let n = (w * h) as usize;
            map.class.copy_from_slice(&cells[..n]);
            let table = ClassTable::default_table();
            let mut p = planner(GlobalPlannerParams::default(), &map);
            for i in 0..n {
                let c = map.class[i];
                let covered = p.covering_node(map.spec.center(map.spec.cell_of_index(i))).is_some();
                let coverable = c != UNKNOWN_CLASS && table.rank(c) <= 4 && !table.is_ignored(c);
                prop_assert_eq!(covered, coverable, "cell {} class {}", i, c);
            }
            if let Ok(path) = p.plan(Point2::new(a.0, a.1), Point2::new(b.0, b.1)) {
                prop_assert!(path.cost.is_finite() && path.cost >= 0.0);
                prop_assert_eq!(p.path_status(&path), PathStatus::Valid);
            }
            let mut broken = map.clone();
            broken.rgb.pop();
            prop_assert!(p.update_map(&broken).is_err());
        }
    }
}

#[test]
fn plan_avoiding_skips_the_given_edges_and_keeps_them() {
    let map = ring_map();
    let mut p = planner(GlobalPlannerParams::default(), &map);
    let direct = p.plan(RING_START, RING_GOAL).unwrap();
    assert!(!goes_north(&direct), "the direct route takes the southern road");
    let avoid: Vec<_> = direct.nodes.windows(2).map(|w| (w[1], w[0])).collect(); // either order
    let around = p.plan_avoiding(RING_START, RING_GOAL, &avoid).unwrap();
    assert!(goes_north(&around), "without the southern edges it goes round: {:?}", around.waypoints);
    assert!(around.nodes.windows(2).all(|w| !avoid.contains(&(w[1], w[0])) && !avoid.contains(&(w[0], w[1]))));
    // The edges are still in the graph: the plain search takes them again.
    assert_eq!(p.plan(RING_START, RING_GOAL).unwrap().nodes, direct.nodes);
    // Pairs that are not edges change nothing.
    let none = [(direct.nodes[0], direct.nodes[0])];
    assert_eq!(p.plan_avoiding(RING_START, RING_GOAL, &none).unwrap().nodes, direct.nodes);
}

/// 40 m × 25 m: road below y = 10 m, a sidewalk 0.15 m up behind a curb above it, one ramp up
/// the curb at x ∈ [20, 23) m rising over y ∈ [10, 13) m, buildings above y = 20 m.
fn curb_and_ramp_map() -> AerialMap {
    curb_map_with_ramp(80, 40)
}

/// `width` cells (0.5 m each) by 25 m: road below y = 10 m, a sidewalk 0.15 m up behind a
/// curb, one ramp 3 m wide from column `ramp_col` rising over y ∈ [10, 13) m, buildings above
/// y = 20 m.
fn curb_map_with_ramp(width: u32, ramp_col: u32) -> AerialMap {
    let mut m = blank(width, 50, class::ROAD, color::ROAD);
    paint(&mut m, 0..width, 20..40, class::SIDEWALK, color::SIDEWALK);
    paint(&mut m, 0..width, 40..50, class::BUILDING, color::BUILDING);
    for row in 20..50u32 {
        for col in 0..width {
            let i = m.spec.index(Cell::new(col, row));
            m.elevation[i] = if row >= 40 {
                10.0
            } else if (ramp_col..ramp_col + 6).contains(&col) && row < 26 {
                // Cell centres 0.25 m into the ramp rise 0.15 m over its 3 m.
                0.15 * ((row - 20) as f32 * 0.5 + 0.25) / 3.0
            } else {
                0.15
            };
        }
    }
    m
}

/// Where a path's pieces cross the curb line y = 10 m.
fn curb_crossings(path: &GlobalPath) -> Vec<f64> {
    path.waypoints
        .windows(2)
        .filter(|w| (w[0].y < 10.0) != (w[1].y < 10.0))
        .map(|w| w[0].x + (w[1].x - w[0].x) * (10.0 - w[0].y) / (w[1].y - w[0].y))
        .collect()
}

#[test]
fn a_path_to_the_sidewalk_goes_up_the_ramp_the_aerial_elevation_shows() {
    let map = curb_and_ramp_map();
    let mut p = planner(GlobalPlannerParams::default(), &map);
    assert!(p.graph_stats().routed_edges >= 1, "{:?}", p.graph_stats());
    let path = p.plan(Point2::new(10.0, 5.0), Point2::new(10.0, 16.0)).unwrap();
    let crossings = curb_crossings(&path);
    assert_eq!(crossings.len(), 1, "{:?}", path.waypoints);
    // Up the middle of the ramp (x ∈ [20, 23)), clear of the curb on either side.
    assert!((20.75..22.25).contains(&crossings[0]), "up the ramp, not the curb: {:?}", path.waypoints);
    // Every node of the path is at its recorded waypoint.
    let positions: Vec<Point2> = p.nodes().map(|(_, q, _)| q).collect();
    for (k, &w) in path.node_waypoints.iter().enumerate() {
        assert!(positions.contains(&path.waypoints[w]), "node {k} at waypoint {w}");
    }

    // With the routing off the graph only has straight edges, which cross the curb.
    let mut straight = GlobalPlannerParams::default();
    straight.graph.max_step_m = None;
    let mut q = planner(straight, &map);
    assert_eq!(q.graph_stats().routed_edges, 0);
    let path = q.plan(Point2::new(10.0, 5.0), Point2::new(10.0, 16.0)).unwrap();
    assert!(curb_crossings(&path).iter().all(|x| !(20.0..23.0).contains(x)), "{:?}", path.waypoints);
}

/// 120 m × 25 m: the curb map's road and sidewalk, with the one ramp far along the curb, at
/// x ∈ [110, 113) m: beyond the visibility range of the nodes near the west end.
fn curb_with_a_far_ramp_map() -> AerialMap {
    curb_map_with_ramp(240, 220)
}

#[test]
fn an_edge_straight_up_a_curb_is_a_last_resort_while_a_ramp_joins_the_two_sides() {
    let map = curb_with_a_far_ramp_map();
    let (start, goal) = (Point2::new(10.0, 5.0), Point2::new(10.0, 16.0));
    let mut params = GlobalPlannerParams::default();
    params.graph.curbs_last_resort = true;
    let mut p = planner(params.clone(), &map);
    let stats = p.graph_stats();
    assert!(stats.edges_up_curbs >= 1 && stats.routed_edges >= 1, "{stats:?}");
    let path = p.plan(start, goal).unwrap();
    let crossings = curb_crossings(&path);
    assert_eq!(crossings.len(), 1, "{:?}", path.waypoints);
    assert!((110.0..113.0).contains(&crossings[0]), "round by the ramp, 100 m away: {:?}", path.waypoints);
    assert!(path.length_m > 200.0, "{}", path.length_m);

    // By default, and in the paper's ablation without graph updates, the straight edges keep
    // their plain costs: the path goes straight up the curb near the goal.
    let mut frozen = params.clone();
    frozen.experience.graph_updates = false;
    for plain in [GlobalPlannerParams::default(), frozen] {
        let mut q = planner(plain, &map);
        let straight = q.plan(start, goal).unwrap();
        let crossings = curb_crossings(&straight);
        assert!(crossings.iter().all(|&x| x < 40.0), "{:?}", straight.waypoints);
        assert!(straight.length_m < 60.0, "{}", straight.length_m);
    }

    // Without a ramp at all, the curb edges are all there is: a path still exists.
    let mut no_ramp = map.clone();
    for row in 20..26u32 {
        for col in 220..226u32 {
            let i = no_ramp.spec.index(Cell::new(col, row));
            no_ramp.elevation[i] = 0.15;
        }
    }
    let mut r = planner(params, &no_ramp);
    let last_resort = r.plan(start, goal).unwrap();
    assert!(
        last_resort.cost >= 1e9 && last_resort.length_m < 60.0,
        "{} m, cost {}",
        last_resort.length_m,
        last_resort.cost
    );
}

/// Whether the polyline `points` crosses x = `x` somewhere on the southern road (y < 8 m).
fn crosses_south_road_at(points: &[Point2], x: f64) -> bool {
    points.windows(2).any(|w| {
        let (a, b) = (w[0], w[1]);
        if (a.x - x) * (b.x - x) > 0.0 || a.x == b.x {
            return false;
        }
        let y = a.y + (x - a.x) / (b.x - a.x) * (b.y - a.y);
        y < 8.0
    })
}

#[test]
fn a_robot_at_a_roadblock_in_the_region_of_the_node_beyond_it_plans_from_a_node_on_its_side() {
    // Regression (the shipped mission with full sharing, seed 5): regions grow on the aerial
    // map, which does not show a roadblock labelled road, so a robot that drove up to one stood
    // in the region of the node beyond it. Every plan started with the straight leg to that node,
    // through the block: no graph edge, so neither the scans nor the failed drives could remove
    // it, and the robot tried it for 25 minutes.
    let map = ring_map();
    let fresh = planner(GlobalPlannerParams::default(), &map);
    // A place on the southern road whose covering node lies at least 3 m further east, and a
    // block across the road between the two.
    let here = (100..600)
        .map(|k| Point2::new(f64::from(k) * 0.1, 4.0))
        .find_map(|p| {
            let id = fresh.covering_node(p)?;
            let (_, at, _) = fresh.nodes().find(|(n, _, _)| *n == id)?;
            (at.x > p.x + 3.0 && at.y < 8.0).then_some(p)
        })
        .expect("a node covers road to its west");
    let block = here.x + 0.8;
    let truth = {
        let base = synthetic::city_probe(&map);
        move |p: Point2| if p.x >= block && p.x < block + 1.0 && p.y < 8.0 { Probe::Obstacle } else { base(p) }
    };
    let mut p = planner(GlobalPlannerParams::default(), &map);
    let before = p.plan(here, RING_GOAL).unwrap();
    assert!(before.waypoints[1].x > block, "the premise: it attaches beyond the block: {:?}", before.waypoints);
    // The robot drove up to the block: its scans on the way vote the ground at the block.
    for k in 0..6 {
        let pose = Pose2::new(here.x - 0.5 * f64::from(k), here.y, 0.0);
        p.add_scan(&synthetic::raycast_scan("ugv1", Time::ZERO, pose, 720, 30.0, 0.25, &truth), true).unwrap();
    }
    let after = p.plan(here, RING_GOAL).unwrap();
    assert!(after.waypoints[1].x < block, "it starts from a node on its side: {:?}", after.waypoints);
    assert!(!crosses_south_road_at(&after.waypoints[..2], block + 0.5), "{:?}", after.waypoints);
    // (Whether the graph edges beyond are judged is the edge rules' business: on this map the
    // road's south side is the map's edge, unknown ground, so they stay unk_trav here.)
}
