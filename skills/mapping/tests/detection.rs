//! Goal detection on synthetic maps with hand-checkable answers.
#![allow(clippy::unwrap_used)]

mod common;

use common::*;
use spomp_core::{ClassTable, Point2};
use spomp_mapping::{GoalDetectionParams, GoalDetector, MappingError};

fn detector() -> GoalDetector {
    GoalDetector::new(GoalDetectionParams::default(), &ClassTable::default_table()).unwrap()
}

#[test]
fn four_vehicles_three_metres_apart_are_one_goal() {
    let mut m = flat(200, 200, ROAD);
    vehicle_row(&mut m, 20.0, 40.0, 4, 3.0);
    let d = detector().detect(&m, &[]).unwrap();
    assert_eq!(d.goals.len(), 1, "{d:?}");
    let g = &d.goals[0];
    assert_eq!(g.class, ROAD);
    // Cluster spans x 20..47, y 40..42: its centroid is near (33.5, 41).
    assert!(g.cluster_centroid.distance(Point2::new(33.5, 41.0)) < 1.0, "{:?}", g.cluster_centroid);
    assert!((g.cluster_size_m - 27.0).abs() <= 1.0, "{}", g.cluster_size_m);
    // Within 7 m of the cluster, on the clearest road cell, i.e. as far as possible from the
    // vehicles: 7 m away from them.
    assert!(g.clearance_m >= 6.5, "{}", g.clearance_m);
    // 9 × 4 cells per vehicle, less the four corner cells the speck-removing open trims.
    assert_eq!(g.class_cells, 4 * (9 * 4 - 4));
}

#[test]
fn two_clusters_forty_metres_apart_are_two_goals() {
    let mut m = flat(300, 200, ROAD);
    vehicle_row(&mut m, 10.0, 40.0, 3, 3.0); // ends at x = 29.5
    vehicle_row(&mut m, 69.5, 40.0, 3, 3.0); // 40 m further
    let d = detector().detect(&m, &[]).unwrap();
    assert_eq!(d.goals.len(), 2, "{d:?}");
    assert!(d.goals[0].position.distance(d.goals[1].position) > 20.0);
}

#[test]
fn clusters_closer_than_the_merge_distance_merge() {
    let mut m = flat(300, 200, ROAD);
    vehicle_row(&mut m, 10.0, 40.0, 2, 3.0); // ends at x = 22
    vehicle_row(&mut m, 34.0, 40.0, 2, 3.0); // 12 m gap < 15 m
    let d = detector().detect(&m, &[]).unwrap();
    assert_eq!(d.goals.len(), 1, "{d:?}");
}

#[test]
fn clusters_farther_than_the_merge_distance_stay_apart() {
    let mut m = flat(300, 200, ROAD);
    vehicle_row(&mut m, 10.0, 40.0, 2, 3.0); // ends at x = 22
    vehicle_row(&mut m, 39.0, 40.0, 2, 3.0); // 17 m gap > 15 m
    let d = detector().detect(&m, &[]).unwrap();
    assert_eq!(d.goals.len(), 2, "{d:?}");
}

#[test]
fn a_single_vehicle_is_below_the_minimum_size() {
    let mut m = flat(200, 200, ROAD);
    vehicle(&mut m, 50.0, 50.0);
    // A one-cell speck of the class elsewhere, removed by the open.
    fill(&mut m, 80.0, 80.0, 80.5, 80.5, VEHICLE);
    let d = detector().detect(&m, &[]).unwrap();
    assert!(d.goals.is_empty(), "{d:?}");
    assert_eq!(d.too_small, 1, "the speck is gone, the single vehicle is too small");
}

#[test]
fn goal_goes_on_the_easiest_class_nearby_never_in_a_building() {
    // Grass everywhere; vehicles parked on grass; a road strip 3 m south of them; a building
    // right north of them.
    let mut m = flat(200, 200, GRASS);
    fill(&mut m, 0.0, 30.0, 100.0, 36.0, ROAD);
    vehicle_row(&mut m, 20.0, 39.0, 4, 3.0); // y 39..41
    fill(&mut m, 0.0, 41.0, 100.0, 100.0, BUILDING);
    let d = detector().detect(&m, &[]).unwrap();
    assert_eq!(d.goals.len(), 1);
    let g = &d.goals[0];
    assert_eq!(g.class, ROAD, "road beats the grass next to the vehicles");
    assert!(g.position.y >= 30.0 && g.position.y < 36.0, "{:?}", g.position);
    // The clearest road cell: mid-strip (3 m to the strip's grass edge does not count: grass
    // is not an obstacle; the vehicles are ≥ 3 m away).
    assert!(g.clearance_m >= 3.0, "{}", g.clearance_m);

    // Without the road: gravel (rank 1) beats grass (rank 2).
    let mut m2 = flat(200, 200, GRASS);
    fill(&mut m2, 0.0, 30.0, 100.0, 36.0, GRAVEL);
    vehicle_row(&mut m2, 20.0, 39.0, 4, 3.0);
    fill(&mut m2, 0.0, 41.0, 100.0, 100.0, BUILDING);
    assert_eq!(detector().detect(&m2, &[]).unwrap().goals[0].class, GRAVEL);

    // Surrounded by buildings and unknown except a thin grass ring: the goal is on grass.
    let mut m3 = flat(200, 200, BUILDING);
    fill(&mut m3, 18.0, 37.0, 50.0, 43.0, GRASS);
    vehicle_row(&mut m3, 20.0, 39.0, 4, 3.0);
    fill(&mut m3, 0.0, 0.0, 100.0, 20.0, spomp_core::UNKNOWN_CLASS);
    let g3 = &detector().detect(&m3, &[]).unwrap().goals[0];
    assert_eq!(g3.class, GRASS);
    assert!(m3.is_known(g3.cell));
}

#[test]
fn a_cluster_with_nowhere_to_stand_gives_no_goal() {
    let mut m = flat(200, 200, BUILDING);
    vehicle_row(&mut m, 20.0, 40.0, 4, 0.0);
    let d = detector().detect(&m, &[]).unwrap();
    assert!(d.goals.is_empty());
    assert_eq!(d.unplaceable, 1);
}

#[test]
fn known_goals_suppress_detections_within_the_radius() {
    let mut m = flat(300, 200, ROAD);
    vehicle_row(&mut m, 10.0, 40.0, 3, 3.0);
    vehicle_row(&mut m, 69.5, 40.0, 3, 3.0);
    let all = detector().detect(&m, &[]).unwrap();
    let known = [all.goals[0].position + Point2::new(5.0, 5.0)];
    let d = detector().detect(&m, &known).unwrap();
    assert_eq!(d.goals.len(), 1);
    assert_eq!(d.duplicates, 1);
    assert_eq!(d.goals[0], all.goals[1]);
}

#[test]
fn bad_class_and_params_are_errors() {
    let t = ClassTable::default_table();
    let p = GoalDetectionParams { class: "tank".into(), ..GoalDetectionParams::default() };
    assert!(matches!(GoalDetector::new(p, &t), Err(MappingError::UnknownClass { .. })));
    let p = GoalDetectionParams { min_size_m: -1.0, ..GoalDetectionParams::default() };
    assert!(matches!(GoalDetector::new(p, &t), Err(MappingError::InvalidParams { .. })));
    let mut m = flat(10, 10, ROAD);
    m.class.pop();
    assert!(detector().detect(&m, &[]).is_err());
    let p: GoalDetectionParams = serde_json::from_str(r#"{"merge_distance_m": 20}"#).unwrap();
    assert_eq!((p.merge_distance_m, p.min_size_m), (20.0, 8.0));
    assert!(serde_json::from_str::<GoalDetectionParams>(r#"{"merge": 20}"#).is_err());
}

mod never_panics {
    use super::*;
    use proptest::prelude::*;

    proptest! {
        #![proptest_config(ProptestConfig { cases: 48, ..ProptestConfig::default() })]

        /// Random class rasters (any class value, unknown included) never panic, and every goal
        /// is on a known, passable cell.
        #[test]
        fn random_maps(w in 1u32..40, h in 1u32..40, seed in any::<u64>(), known in prop::collection::vec((0.0..20.0f64, 0.0..20.0f64), 0..3)) {
            let mut m = flat(w, h, ROAD);
            let mut s = seed | 1;
            for c in m.class.iter_mut() {
                s ^= s << 13; s ^= s >> 7; s ^= s << 17;
                *c = match s % 6 { 0..=2 => VEHICLE, 3 => BUILDING, 4 => 255, _ => (s % 9) as u8 };
            }
            let known: Vec<Point2> = known.into_iter().map(|(x, y)| Point2::new(x, y)).collect();
            let p = GoalDetectionParams { min_size_m: 1.0, ..GoalDetectionParams::default() };
            let d = GoalDetector::new(p, &ClassTable::default_table()).unwrap().detect(&m, &known).unwrap();
            let table = ClassTable::default_table();
            for g in &d.goals {
                prop_assert!(m.is_known(g.cell));
                prop_assert!(table.rank(g.class) < 5 && g.class != VEHICLE);
                prop_assert!(known.iter().all(|k| k.distance(g.position) > 10.0));
            }
        }
    }
}
