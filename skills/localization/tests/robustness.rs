//! Bad input never panics: malformed panoramas, maps, poses and parameters give an error or a
//! no-op. Also the parameter block's serde contract.

#![allow(clippy::unwrap_used)] // tests may unwrap (house rule)

use std::sync::Arc;

use proptest::prelude::*;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use spomp_core::{
    AerialMap, ClassTable, DepthPanorama, GridSpec, PanoramaFrame, PanoramaGeometry, Point2, Pose2, SemanticPanorama,
    Time,
};
use spomp_localization::{CrossViewLocalizer, LocalizationError, LocalizationParams, PosePrior};

fn any_f64() -> impl Strategy<Value = f64> {
    prop_oneof![
        -1e3..1e3f64,
        Just(f64::NAN),
        Just(f64::INFINITY),
        Just(f64::NEG_INFINITY),
        Just(0.0),
        Just(1e300),
        Just(-1e-300),
    ]
}

fn any_f32() -> impl Strategy<Value = f32> {
    prop_oneof![0.0..60.0f32, Just(f32::NAN), Just(f32::INFINITY), Just(-1.0f32), Just(0.0f32), Just(f32::MAX)]
}

fn initialised() -> (CrossViewLocalizer, ChaCha8Rng) {
    let mut rng = ChaCha8Rng::seed_from_u64(7);
    let params = LocalizationParams { num_particles: 20, ..Default::default() };
    let mut loc = CrossViewLocalizer::new(params).unwrap();
    let prior = PosePrior { pose: Pose2::new(5.0, 5.0, 0.0), ..Default::default() };
    loc.initialize(&prior, Pose2::default(), Time::ZERO, &mut rng).unwrap();
    (loc, rng)
}

fn small_map() -> AerialMap {
    let spec = GridSpec::new(Point2::new(0.0, 0.0), 0.5, 20, 20);
    let mut map = AerialMap::unknown(spec);
    for (i, c) in map.class.iter_mut().enumerate() {
        *c = [0, 3, 2, 6][i % 4];
    }
    map
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 64, ..ProptestConfig::default() })]

    #[test]
    fn malformed_panoramas_never_panic(
        rows in 0usize..12,
        cols in 0usize..12,
        semantic_rows in 0usize..12,
        v_fov in any_f64(),
        ranges in proptest::collection::vec(any_f32(), 0..150),
        labels in proptest::collection::vec(any::<u8>(), 0..150),
        height in any_f64(),
        x in any_f64(),
        yaw in any_f64(),
    ) {
        let (mut loc, mut rng) = initialised();
        let g = PanoramaGeometry { rows, cols, v_fov_rad: v_fov };
        let frame = PanoramaFrame {
            seq: 1,
            stamp: Time::from_millis(1000),
            odom_pose: Pose2::new(x, 0.0, yaw),
            sensor_height_m: height,
            depth: Arc::new(DepthPanorama { geometry: g, range_m: ranges }),
            semantic: Arc::new(SemanticPanorama { geometry: PanoramaGeometry { rows: semantic_rows, ..g }, class: labels }),
        };
        let before = loc.estimate();
        match loc.process_frame(&frame, &small_map(), &ClassTable::default_table(), &mut rng) {
            Ok(report) => prop_assert!(report.effective_sample_size.is_finite()),
            Err(_) => prop_assert_eq!(loc.particles().len(), 20),
        }
        let after = loc.estimate();
        prop_assert!(after.pose.x.is_finite() && after.pose.y.is_finite() && after.pose.yaw.is_finite(),
            "estimate stays finite: {:?} → {:?}", before, after);
        prop_assert!((0.0..=1.0).contains(&after.confidence));
        let _ = loc.pose_at(Pose2::new(x, yaw, height));
    }

    #[test]
    fn well_formed_panoramas_with_garbage_values_are_fine(
        ranges in proptest::collection::vec(any_f32(), 48),
        labels in proptest::collection::vec(any::<u8>(), 48),
        height in -2.0..2.0f64,
    ) {
        let (mut loc, mut rng) = initialised();
        let g = PanoramaGeometry { rows: 4, cols: 12, v_fov_rad: 1.5 };
        let frame = PanoramaFrame {
            seq: 1,
            stamp: Time::from_millis(1000),
            odom_pose: Pose2::new(0.5, 0.0, 0.1),
            sensor_height_m: height,
            depth: Arc::new(DepthPanorama { geometry: g, range_m: ranges }),
            semantic: Arc::new(SemanticPanorama { geometry: g, class: labels }),
        };
        let report = loc.process_frame(&frame, &small_map(), &ClassTable::default_table(), &mut rng);
        prop_assert!(report.is_ok(), "{:?}", report);
        let w: f64 = loc.weights().iter().sum();
        prop_assert!((w - 1.0).abs() < 1e-9);
    }

    #[test]
    fn malformed_maps_never_panic(
        width in 0u32..30,
        height in 0u32..30,
        resolution in any_f64(),
        origin_x in any_f64(),
        extra in 0usize..3,
        missing in 0usize..3,
    ) {
        let (mut loc, mut rng) = initialised();
        let spec = GridSpec::new(Point2::new(origin_x, 0.0), resolution, width, height);
        let n = (width as usize * height as usize + extra).saturating_sub(missing);
        let map = AerialMap { spec, class: vec![0; n], rgb: vec![], elevation: vec![], version: 3 };
        let g = PanoramaGeometry { rows: 4, cols: 8, v_fov_rad: 1.5 };
        let frame = PanoramaFrame {
            seq: 1,
            stamp: Time::ZERO,
            odom_pose: Pose2::default(),
            sensor_height_m: 0.4,
            depth: Arc::new(DepthPanorama { geometry: g, range_m: vec![2.0; 32] }),
            semantic: Arc::new(SemanticPanorama { geometry: g, class: vec![0; 32] }),
        };
        let _ = loc.process_frame(&frame, &map, &ClassTable::default_table(), &mut rng);
        let _ = loc.initialize_global(&map, &ClassTable::default_table(), Pose2::default(), Time::ZERO, &mut rng);
        prop_assert!(loc.estimate().pose.x.is_finite() || loc.particles().is_empty());
    }
}

#[test]
fn update_before_initialisation_is_an_error() {
    let mut loc = CrossViewLocalizer::new(LocalizationParams::default()).unwrap();
    let mut rng = ChaCha8Rng::seed_from_u64(1);
    let g = PanoramaGeometry { rows: 2, cols: 2, v_fov_rad: 1.0 };
    let frame = PanoramaFrame {
        seq: 0,
        stamp: Time::ZERO,
        odom_pose: Pose2::default(),
        sensor_height_m: 0.4,
        depth: Arc::new(DepthPanorama::empty(g)),
        semantic: Arc::new(SemanticPanorama { geometry: g, class: vec![0; 4] }),
    };
    let err = loc.update(&frame, &small_map(), &ClassTable::default_table(), &mut rng).unwrap_err();
    assert_eq!(err, LocalizationError::NotInitialized);
}

#[test]
fn params_round_trip_reject_unknown_keys_and_fill_defaults() {
    let params = LocalizationParams::default();
    assert_eq!(params.num_particles, 300);
    let json = serde_json::to_string(&params).unwrap();
    let back: LocalizationParams = serde_json::from_str(&json).unwrap();
    assert_eq!(back, params);
    let partial: LocalizationParams = serde_json::from_str(r#"{"num_particles": 500}"#).unwrap();
    assert_eq!(partial.num_particles, 500);
    assert_eq!(partial.max_match_distance_m, params.max_match_distance_m);
    assert!(serde_json::from_str::<LocalizationParams>(r#"{"num_particle": 500}"#).is_err());
    let schema = schemars::schema_for!(LocalizationParams);
    let text = serde_json::to_string(&schema).unwrap();
    assert!(text.contains("match_temperature_m"));
    let bad = LocalizationParams { match_temperature_m: 0.0, ..Default::default() };
    assert!(matches!(CrossViewLocalizer::new(bad), Err(LocalizationError::InvalidParams(_))));
}

/// A weighted class the table lacks counts 0 (a site's table that lacks one class degrades the
/// match instead of failing every update); a table with none of the ground classes is an error
/// that names them.
#[test]
fn unknown_class_names_in_params_degrade_or_are_reported() {
    let mut weights = LocalizationParams::default().class_weights;
    weights.insert("lava".into(), 1.0);
    let params = LocalizationParams { class_weights: weights, ..Default::default() };
    let mut loc = CrossViewLocalizer::new(params).unwrap();
    loc.prepare_map(&small_map(), &ClassTable::default_table()).unwrap();
    let params = LocalizationParams { ground_classes: vec!["lava".into(), "magma".into()], ..Default::default() };
    let mut loc = CrossViewLocalizer::new(params).unwrap();
    let err = loc.prepare_map(&small_map(), &ClassTable::default_table()).unwrap_err();
    assert!(err.to_string().contains("lava, magma"), "{err}");
}
