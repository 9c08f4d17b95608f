//! Closed-loop checks in a synthetic town: the localizer is fed panoramas rendered from the true
//! pose and odometry that drifts, and its estimate is compared with the truth.

#![allow(clippy::unwrap_used)] // tests may unwrap (house rule)

mod common;

use common::*;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use spomp_core::{AerialMap, ClassTable, PanoramaGeometry, Point2, Pose2};
use spomp_localization::{CrossViewLocalizer, LocalizationParams, PosePrior};

const SENSOR_HEIGHT_M: f64 = 0.4;

fn test_geometry() -> PanoramaGeometry {
    PanoramaGeometry { rows: 64, cols: 256, v_fov_rad: std::f64::consts::FRAC_PI_2 }
}

/// The block bounded by the two western vertical roads and the two lower horizontal roads:
/// a 110 m loop.
fn block_loop() -> Vec<Point2> {
    vec![Point2::new(23.0, 31.0), Point2::new(53.0, 31.0), Point2::new(53.0, 56.0), Point2::new(23.0, 56.0)]
}

struct Run {
    filter_errors: Vec<f64>,
    odometry_errors: Vec<f64>,
    estimates: Vec<Pose2>,
    dead_reckoning: Vec<Pose2>,
    weights_untouched: bool,
    reports: Vec<spomp_localization::UpdateReport>,
}

/// Drives `truth` (a panorama every step), with the prior offset from the first true pose.
/// `kidnap_at`: the robot is carried off between that step and the previous one, unknown to
/// odometry.
fn drive(
    params: &LocalizationParams,
    map: &AerialMap,
    world: &World,
    truth: &[Pose2],
    prior_offset: Pose2,
    seed: u64,
    kidnap_at: Option<usize>,
) -> Run {
    let classes = ClassTable::default_table();
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut motions = steps(truth);
    if let Some(k) = kidnap_at {
        // Odometry does not notice being carried off: it reports an ordinary step.
        motions[k - 1] = Pose2::new(1.5, 0.0, 0.0);
    }
    let odom = noisy_odometry(&motions, &mut rng, 0.004);
    let mut loc = CrossViewLocalizer::new(params.clone()).unwrap();
    let prior_pose = truth[0].compose(prior_offset);
    let prior = PosePrior { pose: prior_pose, std_xy_m: 2.0, std_yaw_rad: 5f64.to_radians() };
    loc.initialize(&prior, odom[0], spomp_core::Time::ZERO, &mut rng).unwrap();
    let mut run = Run {
        filter_errors: vec![],
        odometry_errors: vec![],
        estimates: vec![],
        dead_reckoning: vec![],
        weights_untouched: true,
        reports: vec![],
    };
    for (k, (&true_pose, &odom_pose)) in truth.iter().zip(&odom).enumerate() {
        let pano = render(world, true_pose, test_geometry(), SENSOR_HEIGHT_M, 0.03, &mut rng);
        let f = frame(k as u64, k as f64, odom_pose, SENSOR_HEIGHT_M, pano);
        let report = loc.process_frame(&f, map, &classes, &mut rng).unwrap();
        run.reports.push(report);
        if report.resampled || report.injected > 0 {
            run.weights_untouched = false;
        }
        let estimate = loc.estimate().pose;
        let dead_reckoning = prior_pose.compose(odom[0].between(odom_pose));
        run.filter_errors.push(position_error(estimate, true_pose));
        run.odometry_errors.push(position_error(dead_reckoning, true_pose));
        run.estimates.push(estimate);
        run.dead_reckoning.push(dead_reckoning);
    }
    run
}

#[test]
fn tracks_a_100_m_loop_from_a_2_m_5_degree_prior_error() {
    let world = World::town();
    let truth = loop_route(&block_loop(), 1.5, 1.0);
    assert!(truth.len() >= 70, "a loop of about 110 m at 1.5 m per panorama");
    let run = drive(
        &LocalizationParams { kld_sampling: true, ..Default::default() },
        &world.map,
        &world,
        &truth,
        Pose2::new(1.5, -1.3, 5f64.to_radians()),
        11,
        None,
    );
    let med = median(run.filter_errors.clone());
    let max = run.filter_errors.iter().copied().fold(0.0, f64::max);
    let odo_med = median(run.odometry_errors.clone());
    let odo_final = *run.odometry_errors.last().unwrap();
    let mut counts: Vec<usize> = run.reports.iter().map(|r| r.particles).collect();
    counts.sort_unstable();
    let median_count = counts[counts.len() / 2];
    eprintln!("filter median {med:.2} m, max {max:.2} m; odometry median {odo_med:.2} m, final {odo_final:.2} m");
    eprintln!("particles: median {median_count}, range {:?}", (counts[0], counts[counts.len() - 1]));
    assert!(median_count < 200, "KLD sampling keeps fewer than 300 particles while tracking");
    assert!(med < 2.0, "median error {med} m");
    assert!(max < 5.0, "max error {max} m");
    assert!(med < 0.5 * odo_med, "filter median {med} m vs odometry alone {odo_med} m");
    assert!(*run.filter_errors.last().unwrap() < 2.0);
}

#[test]
fn with_an_all_unknown_map_the_estimate_follows_odometry() {
    let world = World::town();
    let unknown = AerialMap::unknown(world.map.spec);
    let truth = loop_route(&block_loop(), 1.5, 0.5);
    let run = drive(
        &LocalizationParams::default(),
        &unknown,
        &world,
        &truth,
        Pose2::new(1.5, -1.3, 5f64.to_radians()),
        12,
        None,
    );
    assert!(run.weights_untouched, "no evidence: never resampled, nothing injected");
    for (k, (e, d)) in run.estimates.iter().zip(&run.dead_reckoning).enumerate() {
        // The particle mean drifts from the dead-reckoned pose only by sampling noise and the
        // slight pull of heading spread on the mean.
        let gap = position_error(*e, *d);
        assert!(gap < 1.0, "step {k}: estimate {e:?} vs dead reckoning {d:?}");
        assert!(spomp_core::normalize_angle(e.yaw - d.yaw).abs() < 0.1);
    }
}

#[test]
fn recovers_from_a_30_m_kidnapping_within_60_s() {
    let world = World::town();
    let step_m = 1.5;
    let route = loop_route(&block_loop(), step_m, 3.0);
    let kidnap_at = 15;
    let shift = (30.0 / step_m) as usize; // 30 m further along the loop
    let mut truth: Vec<Pose2> = route[..kidnap_at].to_vec();
    truth.extend_from_slice(&route[kidnap_at + shift..kidnap_at + shift + 70]);
    let jump = position_error(truth[kidnap_at - 1], truth[kidnap_at]);
    assert!(jump > 20.0, "the robot is carried off by {jump} m");
    let run = drive(
        &LocalizationParams { kld_sampling: true, ..Default::default() },
        &world.map,
        &world,
        &truth,
        Pose2::new(1.0, 1.0, 3f64.to_radians()),
        13,
        Some(kidnap_at),
    );
    assert!(run.filter_errors[kidnap_at - 1] < 2.0, "tracking before the kidnapping");
    assert!(run.filter_errors[kidnap_at] > 15.0, "the kidnapping is a surprise");
    // At 1.5 m/s and one panorama per second, 60 s is 60 updates.
    let recovered = (kidnap_at..truth.len()).find(|&k| run.filter_errors[k..].iter().all(|&e| e < 3.0));
    let Some(k) = recovered else {
        panic!("never recovered: errors {:?}", run.filter_errors);
    };
    eprintln!("recovered {} updates after the kidnapping", k - kidnap_at);
    assert!(k - kidnap_at <= 60, "took {} updates", k - kidnap_at);
    // KLD sampling: few particles while tracking, all of them while lost, few again after.
    let counts: Vec<usize> = run.reports.iter().map(|r| r.particles).collect();
    eprintln!("particles per update: {counts:?}");
    let max = LocalizationParams::default().num_particles;
    assert!(counts[kidnap_at - 3..kidnap_at].iter().all(|&n| n < max / 2), "tracking: {counts:?}");
    assert!(counts[kidnap_at..k].contains(&max), "lost: back to {max} particles: {counts:?}");
    assert!(counts.last().is_some_and(|&n| n < max / 2), "tracking again: {counts:?}");
}

/// Not part of the quick suite: the same scenarios over many seeds, to see the spread of
/// outcomes (`cargo test -p spomp-localization --test tracking -- --ignored --nocapture`).
#[test]
#[ignore]
fn seed_sweep() {
    let world = World::town();
    let truth = loop_route(&block_loop(), 1.5, 1.0);
    for seed in 100..110 {
        let run = drive(
            &LocalizationParams::default(),
            &world.map,
            &world,
            &truth,
            Pose2::new(1.5, -1.3, 5f64.to_radians()),
            seed,
            None,
        );
        let max = run.filter_errors.iter().copied().fold(0.0, f64::max);
        eprintln!(
            "seed {seed}: loop median {:.2} m max {max:.2} m (odometry median {:.2} m)",
            median(run.filter_errors.clone()),
            median(run.odometry_errors.clone())
        );
    }
    let partial = south_only(&world);
    for seed in 100..110 {
        let run =
            drive(&LocalizationParams::default(), &partial, &world, &truth, Pose2::new(1.5, -1.3, 0.09), seed, None);
        let max = run.filter_errors.iter().copied().fold(0.0, f64::max);
        eprintln!("seed {seed}: partly mapped loop median {:.2} m max {max:.2} m", median(run.filter_errors.clone()));
    }
    let route = loop_route(&block_loop(), 1.5, 3.0);
    let (kidnap_at, shift) = (15, 20);
    let mut kidnapped: Vec<Pose2> = route[..kidnap_at].to_vec();
    kidnapped.extend_from_slice(&route[kidnap_at + shift..kidnap_at + shift + 70]);
    for seed in 100..110 {
        let run = drive(
            &LocalizationParams::default(),
            &world.map,
            &world,
            &kidnapped,
            Pose2::new(1.0, 1.0, 0.05),
            seed,
            Some(kidnap_at),
        );
        let recovered = (kidnap_at..kidnapped.len()).find(|&k| run.filter_errors[k..].iter().all(|&e| e < 3.0));
        eprintln!("seed {seed}: kidnap recovered after {:?} updates", recovered.map(|k| k - kidnap_at));
        let (errors, _, confidence) = drive_from_global(&world, 1000, seed);
        eprintln!(
            "seed {seed}: global (1000 particles) settled after {:?} updates, confidence {confidence:.2}",
            settled(&errors, 2.0)
        );
        if std::env::var("SWEEP_VERBOSE").is_ok() && recovered.is_none_or(|k| k - kidnap_at > 30) {
            for (k, (e, r)) in run.filter_errors.iter().zip(&run.reports).enumerate().skip(kidnap_at - 2) {
                eprintln!(
                    "  {k}: err {e:.1} agree {:.2} known {:.2} injected {} ess {:.0}",
                    r.agreement, r.known_fraction, r.injected, r.effective_sample_size
                );
            }
        }
    }
}

/// Global initialisation with `particles`, then the loop; returns the per-update errors and the
/// final confidence.
fn drive_from_global(world: &World, particles: usize, seed: u64) -> (Vec<f64>, f64, f64) {
    let classes = ClassTable::default_table();
    let truth = loop_route(&block_loop(), 1.5, 1.0);
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let odom = noisy_odometry(&steps(&truth), &mut rng, 0.004);
    let params = LocalizationParams { num_particles: particles, ..Default::default() };
    let mut loc = CrossViewLocalizer::new(params).unwrap();
    loc.initialize_global(&world.map, &classes, odom[0], spomp_core::Time::ZERO, &mut rng).unwrap();
    let initial_confidence = loc.estimate().confidence;
    let mut errors = vec![];
    for (k, (&true_pose, &odom_pose)) in truth.iter().zip(&odom).enumerate() {
        let pano = render(world, true_pose, test_geometry(), SENSOR_HEIGHT_M, 0.03, &mut rng);
        let f = frame(k as u64, k as f64, odom_pose, SENSOR_HEIGHT_M, pano);
        loc.process_frame(&f, &world.map, &classes, &mut rng).unwrap();
        errors.push(position_error(loc.estimate().pose, true_pose));
    }
    (errors, initial_confidence, loc.estimate().confidence)
}

/// First update from which the error stays below `limit` for good.
fn settled(errors: &[f64], limit: f64) -> Option<usize> {
    (0..errors.len()).find(|&k| errors[k..].iter().all(|&e| e < limit))
}

#[test]
fn global_initialisation_converges_while_driving() {
    let world = World::town();
    let (errors, initial_confidence, final_confidence) = drive_from_global(&world, 1000, 21);
    assert!(initial_confidence < 0.05, "no idea yet: {initial_confidence}");
    let converged = settled(&errors, 2.0);
    eprintln!("global: converged after {converged:?} updates");
    assert!(converged.is_some_and(|k| k <= 40), "errors {errors:?}");
    assert!(final_confidence > 0.4, "confident once converged: {final_confidence}");
}

#[test]
fn a_partly_mapped_area_neither_attracts_nor_repels() {
    // The UAV has mapped only the south of the town (y < 45 m); the loop runs 11 m into the
    // unmapped part, where the filter must carry on with odometry and not be dragged back.
    let world = World::town();
    let partial = south_only(&world);
    let truth = loop_route(&block_loop(), 1.5, 1.0);
    let params =
        LocalizationParams { relocalization_enabled: std::env::var("NO_RELOC").is_err(), ..Default::default() };
    let run = drive(&params, &partial, &world, &truth, Pose2::new(1.5, -1.3, 5f64.to_radians()), 14, None);
    let med = median(run.filter_errors.clone());
    let max = run.filter_errors.iter().copied().fold(0.0, f64::max);
    eprintln!("partly mapped: median {med:.2} m, max {max:.2} m");
    assert!(med < 2.0 && max < 5.0, "errors {:?}", run.filter_errors);
}

/// The town as mapped only south of y = 45 m.
fn south_only(world: &World) -> AerialMap {
    let mut partial = world.map.clone();
    let spec = partial.spec;
    for (i, class) in partial.class.iter_mut().enumerate() {
        if spec.center(spec.cell_of_index(i)).y >= 45.0 {
            *class = spomp_core::UNKNOWN_CLASS;
        }
    }
    partial
}

/// A robot that has not moved sees the same view again: it is not fused again (no reweighting,
/// no resampling, no drift), until the robot moves or the map changes.
#[test]
fn the_same_view_is_not_fused_twice() {
    let world = World::town();
    let classes = ClassTable::default_table();
    let mut rng = ChaCha8Rng::seed_from_u64(3);
    let truth = Pose2::new(30.0, 31.0, 0.2);
    let mut loc = CrossViewLocalizer::new(LocalizationParams::default()).unwrap();
    let prior = PosePrior { pose: Pose2::new(31.0, 30.0, 0.25), std_xy_m: 2.0, std_yaw_rad: 0.087 };
    let odom = Pose2::new(5.0, -2.0, 1.0);
    loc.initialize(&prior, odom, spomp_core::Time::ZERO, &mut rng).unwrap();
    let view = |k: u64, odom: Pose2, truth: Pose2, rng: &mut ChaCha8Rng| {
        frame(k, k as f64, odom, SENSOR_HEIGHT_M, render(&world, truth, test_geometry(), SENSOR_HEIGHT_M, 0.03, rng))
    };
    let first = loc.process_frame(&view(0, odom, truth, &mut rng), &world.map, &classes, &mut rng).unwrap();
    assert!(!first.repeated_view && first.observed_cells > 0);
    let (particles, weights) = (loc.particles().to_vec(), loc.weights().to_vec());
    for k in 1..20 {
        // A new rendering (new label noise) of the same scene from the same place.
        let r = loc.process_frame(&view(k, odom, truth, &mut rng), &world.map, &classes, &mut rng).unwrap();
        assert!(r.repeated_view && !r.resampled && r.injected == 0, "update {k}: {r:?}");
    }
    assert_eq!(loc.particles(), &particles[..], "the particles did not move");
    assert_eq!(loc.weights(), &weights[..], "nor were they reweighted");
    // A new version of the map is new evidence on the same view.
    let mut map = world.map.clone();
    map.version += 1;
    map.class[0] = map.class[1];
    loc.prepare_map(&map, &classes).unwrap();
    let r = loc.process_frame(&view(20, odom, truth, &mut rng), &map, &classes, &mut rng).unwrap();
    assert!(!r.repeated_view && r.observed_cells > 0, "{r:?}");
    // So is a view after the robot moved half a metre.
    let step = Pose2::new(0.5, 0.0, 0.0);
    let r = loc
        .process_frame(&view(21, odom.compose(step), truth.compose(step), &mut rng), &map, &classes, &mut rng)
        .unwrap();
    assert!(!r.repeated_view && r.observed_cells > 0, "{r:?}");
}
