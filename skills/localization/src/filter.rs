//! The particle filter over (x, y, yaw) in the aerial map frame.

use std::sync::Arc;

use rand::Rng;
use rand_distr::StandardNormal;
use serde::{Deserialize, Serialize};
use spomp_core::{AerialMap, ClassTable, PanoramaFrame, Pose2, PoseEstimate, Time, normalize_angle};

use crate::error::LocalizationError;
use crate::field::{MatchField, UNKNOWN_COST_LEVEL, check_map, fingerprint, shared_field};
use crate::motion::{MotionNoise, OdometryMotion};
use crate::observation::LocalObservation;
use crate::params::{LocalizationParams, PosePrior};
use crate::scoring::{PoseScore, Scorer};

/// One hypothesis of the robot's map-frame pose.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Particle {
    /// East, metres.
    pub x: f64,
    /// North, metres.
    pub y: f64,
    /// Heading, radians.
    pub yaw: f64,
}

impl Particle {
    /// The particle as a pose.
    pub fn pose(self) -> Pose2 {
        Pose2::new(self.x, self.y, self.yaw)
    }

    fn from_pose(p: Pose2) -> Self {
        Particle { x: p.x, y: p.y, yaw: p.yaw }
    }
}

/// What one measurement update did.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct UpdateReport {
    /// Number of (cell, class) pairs observed in the panorama's local grid.
    pub observed_cells: usize,
    /// Weighted fraction of the observation landing on known aerial cells (0 … 1).
    pub known_fraction: f64,
    /// Weighted fraction of the known-landing observation that agrees with the aerial map
    /// (class found within `agreement_distance_m`), averaged over the particles (0 … 1).
    pub agreement: f64,
    /// Whether the update counted as evidence (enough of it on known cells).
    pub informative: bool,
    /// Effective sample size after reweighting.
    pub effective_sample_size: f64,
    /// Whether the particles were resampled.
    pub resampled: bool,
    /// Particles replaced by global re-localisation.
    pub injected: usize,
    /// Mean match cost of the observation under the predicted particles, as a fraction of the
    /// cost a random pose would get (0 = perfect match, about 1 = no better than a guess).
    pub cost_ratio: f64,
    /// The robot had not moved since the last update (within `still_translation_m` and
    /// `still_rotation_rad`) and the map was the same: the view was not fused again (no
    /// reweighting, resampling or injection; the other fields are left at their defaults).
    pub repeated_view: bool,
    /// Particles held after the update (KLD sampling adapts the count at each resampling).
    pub particles: usize,
}

/// `ln(Σ exp(a_i))` of two terms, safe for −∞.
fn log_add_exp(a: f64, b: f64) -> f64 {
    let m = a.max(b);
    if m == f64::NEG_INFINITY { m } else { m + ((a - m).exp() + (b - m).exp()).ln() }
}

/// The cross-view localizer: a particle filter that weighs each pose hypothesis by how well the
/// robot's semantic panorama, projected top-down, matches the aerial semantic map.
///
/// Typical use, once per panorama: [`Self::process_frame`] (odometry prediction from the last
/// panorama's odometry pose, then the measurement update); between panoramas,
/// [`Self::pose_at`] composes the filtered pose with odometry for the planners.
#[derive(Clone, Debug)]
pub struct CrossViewLocalizer {
    params: LocalizationParams,
    particles: Vec<Particle>,
    weights: Vec<f64>,
    resample_buffer: Vec<Particle>,
    /// KLD histogram bins of the particles being counted (scratch).
    kld_bins: Vec<(i64, i64, i64)>,
    log_likelihoods: Vec<f64>,
    scores: Vec<PoseScore>,
    scorer: Scorer,
    candidates: Vec<Particle>,
    candidate_scores: Vec<PoseScore>,
    candidate_order: Vec<usize>,
    order: Vec<usize>,
    /// Cost planes of the current map, shared with every localizer in the process that holds
    /// the same map with the same parameters.
    field: Option<Arc<MatchField>>,
    /// Frame time at which `field` was built by an update (None: built outside an update).
    field_built_at: Option<Time>,
    /// Incremented whenever `field` is rebuilt.
    field_generation: u64,
    /// Odometry motion (composed) since the last measurement update that fused a view, and the
    /// field generation it was fused against (None: no update since the initialisation).
    motion_since_update: Pose2,
    fused_on_generation: Option<u64>,
    /// The estimate and the odometry pose at the last update that tracked well (short-term
    /// cost ratio under `relocalization_min_cost_ratio`), or the prior: where a robot that got
    /// lost was last known to be.
    last_tracked: Option<(Pose2, Pose2)>,
    observation: LocalObservation,
    anchor_odom: Option<Pose2>,
    stamp: Time,
    log_likelihood_fast: Option<f64>,
    log_likelihood_slow: Option<f64>,
    /// Short-term average of the match cost ratio (see `UpdateReport::cost_ratio`).
    cost_ratio_fast: Option<f64>,
    match_factor: f64,
    estimate: PoseEstimate,
    last_report: UpdateReport,
}

impl CrossViewLocalizer {
    /// A localizer with checked parameters and no particles yet.
    pub fn new(params: LocalizationParams) -> Result<Self, LocalizationError> {
        params.validate()?;
        Ok(CrossViewLocalizer {
            params,
            particles: Vec::new(),
            weights: Vec::new(),
            resample_buffer: Vec::new(),
            kld_bins: Vec::new(),
            log_likelihoods: Vec::new(),
            scores: Vec::new(),
            scorer: Scorer::default(),
            candidates: Vec::new(),
            candidate_scores: Vec::new(),
            candidate_order: Vec::new(),
            order: Vec::new(),
            field: None,
            field_built_at: None,
            field_generation: 0,
            motion_since_update: Pose2::default(),
            fused_on_generation: None,
            last_tracked: None,
            observation: LocalObservation::default(),
            anchor_odom: None,
            stamp: Time::ZERO,
            log_likelihood_fast: None,
            log_likelihood_slow: None,
            cost_ratio_fast: None,
            match_factor: 1.0,
            estimate: PoseEstimate::default(),
            last_report: UpdateReport::default(),
        })
    }

    /// The parameters.
    pub fn params(&self) -> &LocalizationParams {
        &self.params
    }

    /// Whether the filter has particles.
    pub fn is_initialized(&self) -> bool {
        !self.particles.is_empty()
    }

    /// The particles (map frame).
    pub fn particles(&self) -> &[Particle] {
        &self.particles
    }

    /// The normalised particle weights, one per particle.
    pub fn weights(&self) -> &[f64] {
        &self.weights
    }

    /// The latest filtered estimate (after the last prediction or update).
    pub fn estimate(&self) -> PoseEstimate {
        self.estimate
    }

    /// What the latest measurement update did (default before the first one).
    pub fn last_report(&self) -> UpdateReport {
        self.last_report
    }

    /// Spreads the particles around a prior that holds when odometry reads `odom_pose`.
    pub fn initialize<R: Rng + ?Sized>(
        &mut self,
        prior: &PosePrior,
        odom_pose: Pose2,
        stamp: Time,
        rng: &mut R,
    ) -> Result<(), LocalizationError> {
        check_pose(prior.pose, "prior pose")?;
        check_pose(odom_pose, "odom_pose")?;
        if !(prior.std_xy_m.is_finite()
            && prior.std_xy_m >= 0.0
            && prior.std_yaw_rad.is_finite()
            && prior.std_yaw_rad >= 0.0)
        {
            return Err(LocalizationError::NonFinite("prior standard deviations"));
        }
        let n = self.params.num_particles;
        self.particles.clear();
        for _ in 0..n {
            let (a, b, c): (f64, f64, f64) =
                (rng.sample(StandardNormal), rng.sample(StandardNormal), rng.sample(StandardNormal));
            self.particles.push(Particle {
                x: prior.pose.x + prior.std_xy_m * a,
                y: prior.pose.y + prior.std_xy_m * b,
                yaw: normalize_angle(prior.pose.yaw + prior.std_yaw_rad * c),
            });
        }
        self.reset_after_initialization(odom_pose, stamp, 1.0);
        self.last_tracked = Some((prior.pose, odom_pose));
        Ok(())
    }

    /// Global localisation: spreads the particles uniformly over the known ground-class cells
    /// of the map, with uniform headings.
    pub fn initialize_global<R: Rng + ?Sized>(
        &mut self,
        map: &AerialMap,
        classes: &ClassTable,
        odom_pose: Pose2,
        stamp: Time,
        rng: &mut R,
    ) -> Result<(), LocalizationError> {
        check_pose(odom_pose, "odom_pose")?;
        self.prepare_map(map, classes)?;
        let Some(field) = self.field.as_ref() else {
            return Err(LocalizationError::NoGroundCells);
        };
        if field.ground_cells.is_empty() {
            return Err(LocalizationError::NoGroundCells);
        }
        self.particles.clear();
        for _ in 0..self.params.num_particles {
            self.particles.push(random_ground_particle(field, rng));
        }
        self.reset_after_initialization(odom_pose, stamp, 0.0);
        Ok(())
    }

    fn reset_after_initialization(&mut self, odom_pose: Pose2, stamp: Time, match_factor: f64) {
        let n = self.particles.len();
        self.weights.clear();
        self.weights.resize(n, 1.0 / n as f64);
        self.anchor_odom = Some(odom_pose);
        self.stamp = stamp;
        self.motion_since_update = Pose2::default();
        self.fused_on_generation = None;
        self.last_tracked = None;
        self.log_likelihood_fast = None;
        self.log_likelihood_slow = None;
        // A prior is trusted until the evidence says otherwise (a drifted prior is first
        // corrected by its own particles); a global initialisation is lost by definition.
        self.cost_ratio_fast = Some(1.0 - match_factor);
        self.match_factor = match_factor;
        self.refresh_estimate();
    }

    /// Builds (or reuses) the per-class cost planes of a map: rebuilt whenever the map's
    /// placement, version or contents, or the class table, differ from the last build. Planes
    /// another localizer in the process already holds for the same map, table and parameters
    /// are shared (by `Arc`), not built again: robots with the same prior map hold one set.
    /// Call it
    /// ahead of time to keep the cost out of an update, or to force a new map in at once;
    /// [`Self::update`] itself rebuilds for a new version of the same map at most every
    /// `map_rebuild_interval_s`.
    pub fn prepare_map(&mut self, map: &AerialMap, classes: &ClassTable) -> Result<(), LocalizationError> {
        check_map(map)?;
        let fingerprint = fingerprint(&map.class);
        if self.field.as_ref().is_some_and(|f| f.matches_fingerprint(map, classes, fingerprint)) {
            return Ok(());
        }
        self.field = None;
        self.field_built_at = None;
        self.field = Some(shared_field(map, classes, &self.params, fingerprint)?);
        self.field_generation += 1;
        Ok(())
    }

    /// Like [`Self::prepare_map`], but keeps planes of an older version of the same map for up
    /// to `map_rebuild_interval_s` after they were built (see that parameter).
    fn refresh_map(&mut self, map: &AerialMap, classes: &ClassTable, now: Time) -> Result<(), LocalizationError> {
        check_map(map)?;
        if let (Some(field), Some(built_at)) = (self.field.as_ref(), self.field_built_at) {
            let age_s = now.secs_since(built_at);
            if field.same_layout(map, classes) && (0.0..self.params.map_rebuild_interval_s).contains(&age_s) {
                return Ok(());
            }
        }
        // `prepare_map` keeps planes that match the map and rebuilds the others.
        let generation = self.field_generation;
        self.prepare_map(map, classes)?;
        if self.field_generation == generation {
            return Ok(());
        }
        self.field_built_at = Some(now);
        Ok(())
    }

    /// Motion update: moves every particle by one noisy sample of the odometry delta (the new
    /// odometry pose expressed in the previous one's frame).
    pub fn predict<R: Rng + ?Sized>(&mut self, odom_delta: Pose2, rng: &mut R) -> Result<(), LocalizationError> {
        check_pose(odom_delta, "odom_delta")?;
        if self.particles.is_empty() {
            return Err(LocalizationError::NotInitialized);
        }
        let motion = OdometryMotion::new(odom_delta, (&self.params).into());
        if !motion.is_still() {
            for p in &mut self.particles {
                *p = Particle::from_pose(motion.sample(p.pose(), rng));
            }
        }
        if let Some(anchor) = self.anchor_odom.as_mut() {
            *anchor = anchor.compose(odom_delta);
        }
        self.motion_since_update = self.motion_since_update.compose(odom_delta);
        self.refresh_estimate();
        Ok(())
    }

    /// Whether the robot has not moved since the last update that fused a view (within
    /// `still_translation_m` / `still_rotation_rad`) and the map is the one it was fused with.
    ///
    /// The rule (as AMCL's, which updates and resamples only after motion): a second panorama
    /// from the same pose is the same view of the same scene, its errors (labels, the map's own
    /// mistakes) the same as the first's; fusing it again would count one observation twice,
    /// sharpening the weights on whatever that view happened to favour, and each resampling
    /// without motion noise afterwards draws the cloud at random from itself, so a still robot's
    /// estimate random-walks. A changed map is new evidence on the same view and is fused.
    fn is_repeated_view(&self) -> bool {
        let m = self.motion_since_update;
        self.fused_on_generation == Some(self.field_generation)
            && m.x.hypot(m.y) < self.params.still_translation_m
            && normalize_angle(m.yaw).abs() < self.params.still_rotation_rad
    }

    /// One panorama: predicts with the odometry since the previous panorama (from the frame's
    /// odometry pose), then runs the measurement update.
    pub fn process_frame<R: Rng + ?Sized>(
        &mut self,
        frame: &PanoramaFrame,
        map: &AerialMap,
        classes: &ClassTable,
        rng: &mut R,
    ) -> Result<UpdateReport, LocalizationError> {
        check_pose(frame.odom_pose, "odom_pose")?;
        if let Some(anchor) = self.anchor_odom {
            self.predict(anchor.between(frame.odom_pose), rng)?;
        }
        self.update(frame, map, classes, rng)
    }

    /// Measurement update on one semantic panorama: projects it top-down into a sparse local
    /// grid, scores every particle against the aerial map, reweights, re-localises if the
    /// likelihood collapsed, and resamples when the effective sample size is low. The frame's
    /// odometry pose becomes the anchor for [`Self::pose_at`].
    pub fn update<R: Rng + ?Sized>(
        &mut self,
        frame: &PanoramaFrame,
        map: &AerialMap,
        classes: &ClassTable,
        rng: &mut R,
    ) -> Result<UpdateReport, LocalizationError> {
        if self.particles.is_empty() {
            return Err(LocalizationError::NotInitialized);
        }
        crate::observation::check_frame(frame)?;
        self.refresh_map(map, classes, frame.stamp)?;
        self.anchor_odom = Some(frame.odom_pose);
        self.stamp = frame.stamp;
        if self.is_repeated_view() {
            let report = UpdateReport {
                effective_sample_size: effective_sample_size(&self.weights),
                repeated_view: true,
                particles: self.particles.len(),
                ..Default::default()
            };
            self.refresh_estimate();
            self.last_report = report;
            return Ok(report);
        }
        let field_generation = self.field_generation;
        let Some(field) = self.field.as_ref() else {
            return Err(LocalizationError::InvalidMap("no match field".into()));
        };
        self.observation.build(frame, &field.slots, field.spec.resolution_m, &self.params)?;
        self.motion_since_update = Pose2::default();
        self.fused_on_generation = Some(field_generation);
        let mut report = UpdateReport { observed_cells: self.observation.len(), ..Default::default() };
        // Common support: while the particles are concentrated, score everyone on the cells that
        // every plausible pose sees on known ground — the cells known at the estimate and at
        // the estimate moved `common_support_sigmas` standard deviations along each principal
        // axis of its position spread and turned as many in heading. A cell that lands on
        // known ground for some particles and on unknown ground for others would otherwise
        // reward the particles that put more of the view on the map (at the edge of a partly
        // mapped area, those shifted into it along a straight road).
        let mut support_fraction = 1.0;
        let spread = max_xy_std(&self.estimate.covariance);
        if spread <= self.params.common_support_max_spread_m {
            let poses = support_poses(&self.estimate, self.params.common_support_sigmas);
            let spec = field.spec;
            let inv_res = 1.0 / spec.resolution_m;
            let frames = poses.map(|p| {
                let (s, c) = p.yaw.sin_cos();
                ((p.x - spec.origin.x) * inv_res, (p.y - spec.origin.y) * inv_res, s, c)
            });
            support_fraction = self.observation.retain(&field.slots.weight, |cell, slot| {
                let plane = field.plane(slot);
                frames.iter().all(|&(ox, oy, s, c)| {
                    let u = floor_to_i64(ox + c * cell.x as f64 - s * cell.y as f64);
                    let v = floor_to_i64(oy + s * cell.x as f64 + c * cell.y as f64);
                    spec.contains(u, v)
                        && plane.get(v as usize * spec.width as usize + u as usize).copied() != Some(UNKNOWN_COST_LEVEL)
                })
            });
        }
        let total_weight = self.observation.total_weight;
        if self.observation.is_empty() || total_weight <= 0.0 {
            report.effective_sample_size = effective_sample_size(&self.weights);
            report.particles = self.particles.len();
            self.refresh_estimate();
            self.last_report = report;
            return Ok(report);
        }

        // Score every particle.
        let agree_level = agreement_level(field, self.params.agreement_distance_m);
        let inv_temperature = 1.0 / self.params.match_temperature_m;
        self.scorer.score_all(field, &self.observation, &self.particles, agree_level, &mut self.scores);
        self.log_likelihoods.clear();
        self.log_likelihoods.extend(self.scores.iter().map(|s| -s.weighted_cost / total_weight * inv_temperature));

        let random_cost = random_guess_cost(field, &self.observation);
        if random_cost > 0.0 {
            let predicted: f64 = self.weights.iter().zip(&self.scores).map(|(w, s)| w * s.weighted_cost).sum();
            report.cost_ratio = predicted / random_cost;
        }

        // Predictive likelihood of the observation, ln Σ w_i · l_i, for the re-localisation test.
        let max_ll = self.log_likelihoods.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        let mix: f64 = self.weights.iter().zip(&self.log_likelihoods).map(|(w, ll)| w * (ll - max_ll).exp()).sum();
        let log_avg = max_ll + mix.ln();

        // Reweight (still unnormalised, relative to max_ll).
        for (w, ll) in self.weights.iter_mut().zip(&self.log_likelihoods) {
            *w *= (ll - max_ll).exp();
        }
        normalize(&mut self.weights);

        let known_fraction: f64 =
            self.weights.iter().zip(&self.scores).map(|(w, s)| w * s.known_weight).sum::<f64>() / total_weight;
        // Known fraction of the whole view, not only of the supported part.
        let known_fraction = known_fraction * support_fraction;
        report.known_fraction = known_fraction.clamp(0.0, 1.0);
        report.informative = known_fraction >= self.params.min_known_fraction && known_fraction > 0.0;

        let mut inject = 0usize;
        let mut tracking = false;
        if report.informative {
            let agreement: f64 = self
                .weights
                .iter()
                .zip(&self.scores)
                .map(|(w, s)| if s.known_weight > 0.0 { w * s.agree_weight / s.known_weight } else { 0.0 })
                .sum();
            report.agreement = agreement.clamp(0.0, 1.0);
            self.match_factor = report.agreement;

            let (fast_rate, slow_rate) = (self.params.likelihood_fast_rate, self.params.likelihood_slow_rate);
            let ema = |old: Option<f64>, rate: f64| match old {
                Some(old) if rate < 1.0 => log_add_exp(old + (1.0 - rate).ln(), log_avg + rate.ln()),
                _ => log_avg,
            };
            let fast = ema(self.log_likelihood_fast, fast_rate);
            let slow = ema(self.log_likelihood_slow, slow_rate);
            self.log_likelihood_fast = Some(fast);
            self.log_likelihood_slow = Some(slow);
            let ratio_fast = match self.cost_ratio_fast {
                Some(old) => old + fast_rate * (report.cost_ratio - old),
                None => report.cost_ratio,
            };
            self.cost_ratio_fast = Some(ratio_fast);
            tracking = ratio_fast < self.params.relocalization_min_cost_ratio;
            if self.params.relocalization_enabled && !tracking {
                let p_inject = (1.0 - (fast - slow).exp()).clamp(0.0, self.params.max_relocalization_fraction);
                inject = (p_inject * self.params.num_particles as f64).round() as usize;
            }
        }

        if inject > 0 {
            // Lost: many particles. A set that KLD sampling shrank while tracking is first
            // drawn back up to `num_particles` (the same posterior, uniform weights), so the
            // injected poses join a full set rather than replacing most of a small one.
            if self.particles.len() < self.params.num_particles {
                let offset = rng.random::<f64>();
                self.systematic_resample(self.params.num_particles, offset);
                std::mem::swap(&mut self.particles, &mut self.resample_buffer);
                let n = self.particles.len();
                self.weights.clear();
                self.weights.resize(n, 1.0 / n as f64);
                report.resampled = true;
            }
            report.injected = self.inject_candidates(inject, max_ll, mix, rng);
        }

        report.effective_sample_size = effective_sample_size(&self.weights);
        if report.effective_sample_size < self.params.resample_ess_fraction * self.particles.len() as f64 {
            self.resample(rng);
            report.resampled = true;
        }
        report.particles = self.particles.len();
        self.refresh_estimate();
        if tracking {
            self.last_tracked = Some((self.estimate.pose, frame.odom_pose));
        }
        self.last_report = report;
        Ok(report)
    }

    /// Augmented-MCL injection: draws `count × candidates_per_particle` random poses over the
    /// known ground cells, scores them on the current observation, and puts the best `count`
    /// in place of the lowest-weight particles, weighted by the same likelihood as everyone
    /// (so a wrong injection dies out and a right one takes over). Returns how many were put in.
    fn inject_candidates<R: Rng + ?Sized>(&mut self, count: usize, max_ll: f64, mix: f64, rng: &mut R) -> usize {
        let Some(field) = self.field.as_ref() else {
            return 0;
        };
        if field.ground_cells.is_empty() || self.observation.is_empty() {
            return 0;
        }
        let total_weight = self.observation.total_weight;
        let inv_temperature = 1.0 / self.params.match_temperature_m;
        let agree_level = agreement_level(field, self.params.agreement_distance_m);
        let count = count.min(self.particles.len());
        let n_candidates = count * self.params.relocalization_candidates_per_particle;
        // Most candidates stand on the ground class the robot sees under itself.
        let same_class_cells = self
            .observation
            .under_robot_slot
            .and_then(|slot| field.cells_of_slot.get(slot))
            .filter(|cells| !cells.is_empty());
        let under_slot = same_class_cells.and(self.observation.under_robot_slot);
        // Local candidates around the estimate and, as often, around where the robot was last
        // tracked, carried on by odometry (the estimate may have wandered off since); none
        // before the filter ever tracked (after a global initialisation the estimate is the
        // mean of particles all over the map, a meaningless place).
        let last_tracked = match (self.last_tracked, self.anchor_odom) {
            (Some((pose, odom)), Some(now)) => Some(pose.compose(odom.between(now))),
            _ => None,
        };
        let estimate = self.estimate.pose;
        self.candidates.clear();
        for _ in 0..n_candidates {
            let local = match last_tracked {
                Some(tracked) if rng.random::<f64>() < self.params.relocalization_local_fraction => {
                    let here = if rng.random::<bool>() { estimate } else { tracked };
                    random_particle_near(field, here, self.params.relocalization_local_radius_m, under_slot, rng)
                }
                _ => None,
            };
            let p = match (local, same_class_cells) {
                (Some(p), _) => p,
                (None, Some(cells)) if rng.random::<f64>() < self.params.relocalization_same_class_fraction => {
                    random_particle_on(field, cells, rng)
                }
                _ => random_ground_particle(field, rng),
            };
            self.candidates.push(p);
        }
        self.scorer.score_all(field, &self.observation, &self.candidates, agree_level, &mut self.candidate_scores);
        let candidate_ll = |i: usize| -self.candidate_scores[i].weighted_cost / total_weight * inv_temperature;
        // Best candidates first.
        self.candidate_order.clear();
        self.candidate_order.extend(0..self.candidates.len());
        if count < self.candidate_order.len() {
            self.candidate_order.select_nth_unstable_by(count, |&a, &b| candidate_ll(b).total_cmp(&candidate_ll(a)));
        }
        // Lowest-weight particles first.
        self.order.clear();
        self.order.extend(0..self.particles.len());
        self.order
            .select_nth_unstable_by(count.saturating_sub(1), |&a, &b| self.weights[a].total_cmp(&self.weights[b]));
        // The reweighted particles hold w_old · exp(ℓ − max ℓ) / Z; an injected particle gets
        // the uniform prior weight 1/N times its own likelihood on the same scale.
        // Both are rescaled to the best log-likelihood of either set so nothing overflows.
        let best_candidate =
            self.candidate_order.iter().take(count).map(|&i| candidate_ll(i)).fold(f64::NEG_INFINITY, f64::max);
        let top = max_ll.max(best_candidate);
        let shift = (max_ll - top).exp();
        self.weights.iter_mut().for_each(|w| *w *= shift);
        let n = self.particles.len() as f64;
        let mix = mix.max(f64::MIN_POSITIVE);
        for (&slot, &candidate) in self.order.iter().take(count).zip(self.candidate_order.iter().take(count)) {
            self.particles[slot] = self.candidates[candidate];
            self.weights[slot] = (candidate_ll(candidate) - top).exp() / (n * mix);
        }
        normalize(&mut self.weights);
        count
    }

    /// Systematic (low-variance) resampling; weights become uniform. With `kld_sampling`, the
    /// new set's size follows the KLD bound (see [`kld_particle_bound`]) for the number of
    /// histogram bins the posterior occupies, counted on a systematic draw of `num_particles`
    /// (the largest set: it finds every bin of noticeable weight), then the set is drawn again
    /// at that size with the same offset. One random number per resampling either way, so
    /// with `kld_sampling` off the filter is the fixed-size filter it was.
    fn resample<R: Rng + ?Sized>(&mut self, rng: &mut R) {
        if self.particles.is_empty() {
            return;
        }
        let offset = rng.random::<f64>();
        let n_max = self.params.num_particles;
        self.systematic_resample(n_max, offset);
        if self.params.kld_sampling {
            let k = self.occupied_bins();
            let wanted = kld_particle_bound(k, self.params.kld_error, self.params.kld_quantile_z);
            let n = wanted.clamp(self.params.min_particles.min(n_max), n_max);
            if n < n_max {
                self.systematic_resample(n, offset);
            }
        }
        std::mem::swap(&mut self.particles, &mut self.resample_buffer);
        let n = self.particles.len();
        self.weights.clear();
        self.weights.resize(n, 1.0 / n as f64);
    }

    /// Draws `n` particles systematically from the weighted set into the spare buffer, with
    /// the first pointer at `offset · (1 / n)` (`offset` in [0, 1)).
    fn systematic_resample(&mut self, n: usize, offset: f64) {
        self.resample_buffer.clear();
        let m = self.particles.len();
        if m == 0 || n == 0 {
            return;
        }
        let step = 1.0 / n as f64;
        let mut target = offset * step;
        let mut cumulative = self.weights.first().copied().unwrap_or(0.0);
        let mut j = 0usize;
        for _ in 0..n {
            while target > cumulative && j + 1 < m {
                j += 1;
                cumulative += self.weights.get(j).copied().unwrap_or(0.0);
            }
            self.resample_buffer.push(self.particles[j]);
            target += step;
        }
    }

    /// Number of distinct (x, y, yaw) KLD histogram bins among the particles in the spare
    /// buffer.
    fn occupied_bins(&mut self) -> usize {
        let (bxy, byaw) = (self.params.kld_bin_xy_m, self.params.kld_bin_yaw_rad);
        let bin = |v: f64, size: f64| (v / size).floor().clamp(-1e15, 1e15) as i64;
        self.kld_bins.clear();
        self.kld_bins.extend(
            self.resample_buffer
                .iter()
                .map(|p| (bin(p.x, bxy), bin(p.y, bxy), bin(p.yaw.rem_euclid(std::f64::consts::TAU), byaw))),
        );
        self.kld_bins.sort_unstable();
        self.kld_bins.dedup();
        self.kld_bins.len()
    }

    fn refresh_estimate(&mut self) {
        let (mean, cov) = weighted_mean_and_covariance(&self.particles, &self.weights);
        let confidence = self.confidence(&cov);
        self.estimate = PoseEstimate { stamp: self.stamp, pose: mean, covariance: cov, confidence };
    }

    /// Confidence in 0 … 1: exp(−σ / scale) for the spread σ of position along the widest axis,
    /// times the latest agreement of the observation with the aerial map (1 until there was
    /// evidence after a prior, 0 after a global initialisation).
    fn confidence(&self, covariance: &[f64; 9]) -> f64 {
        confidence(covariance, self.params.confidence_spread_scale_m, self.match_factor)
    }

    /// The map-frame pose at odometry pose `odom_now`: the latest filtered pose composed with
    /// the odometry travelled since the last panorama (the paper's scheme: odometry between
    /// panoramas). The covariance grows with that odometry per the motion model.
    pub fn pose_at(&self, odom_now: Pose2) -> PoseEstimate {
        self.composer().pose_at(odom_now)
    }

    /// [`Self::pose_at`] for an odometry message, stamped with its time.
    pub fn pose_at_odometry(&self, odom: &spomp_core::Odometry) -> PoseEstimate {
        self.composer().pose_at_odometry(odom)
    }

    /// What [`Self::pose_at`] needs, copied out: it keeps answering while the filter itself is
    /// away in a measurement update on another thread.
    pub fn composer(&self) -> OdometryComposer {
        OdometryComposer {
            estimate: self.estimate,
            stamp: self.stamp,
            anchor_odom: self.anchor_odom,
            noise: (&self.params).into(),
            confidence_spread_scale_m: self.params.confidence_spread_scale_m,
            match_factor: self.match_factor,
        }
    }
}

/// The latest filtered pose and the odometry pose it holds at, with the motion noise: composes
/// later odometry onto it ([`CrossViewLocalizer::composer`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct OdometryComposer {
    estimate: PoseEstimate,
    stamp: Time,
    anchor_odom: Option<Pose2>,
    noise: MotionNoise,
    confidence_spread_scale_m: f64,
    match_factor: f64,
}

impl OdometryComposer {
    /// See [`CrossViewLocalizer::pose_at`].
    pub fn pose_at(&self, odom_now: Pose2) -> PoseEstimate {
        let Some(anchor) = self.anchor_odom else {
            return self.estimate;
        };
        if !(odom_now.x.is_finite() && odom_now.y.is_finite() && odom_now.yaw.is_finite()) {
            return self.estimate;
        }
        let delta = anchor.between(odom_now);
        let pose = self.estimate.pose.compose(delta);
        let (sigma_trans, sigma_rot) = OdometryMotion::new(delta, self.noise).spread();
        let mut covariance = self.estimate.covariance;
        // Heading uncertainty swings the travelled distance sideways.
        let lever = self.estimate.covariance[8] * (delta.x * delta.x + delta.y * delta.y);
        covariance[0] += sigma_trans * sigma_trans + lever;
        covariance[4] += sigma_trans * sigma_trans + lever;
        covariance[8] += sigma_rot * sigma_rot;
        let confidence = confidence(&covariance, self.confidence_spread_scale_m, self.match_factor);
        PoseEstimate { stamp: self.stamp, pose, covariance, confidence }
    }

    /// [`Self::pose_at`] for an odometry message, stamped with its time.
    pub fn pose_at_odometry(&self, odom: &spomp_core::Odometry) -> PoseEstimate {
        PoseEstimate { stamp: odom.stamp, ..self.pose_at(odom.pose) }
    }
}

/// Confidence in 0 … 1: exp(−σ / scale) for the spread σ of position along the widest axis,
/// times the agreement of the observation with the aerial map.
fn confidence(covariance: &[f64; 9], spread_scale_m: f64, match_factor: f64) -> f64 {
    let spread = max_xy_std(covariance);
    let c = (-spread / spread_scale_m).exp() * match_factor;
    if c.is_finite() { c.clamp(0.0, 1.0) } else { 0.0 }
}

/// Fox's KLD-sampling bound: the number of samples from a posterior occupying `k` histogram
/// bins such that, with probability 1 − δ, the Kullback–Leibler divergence between the
/// sample-based and the true (binned) posterior is at most `epsilon`, z = z₁₋δ — the
/// Wilson–Hilferty approximation of the χ² quantile with k − 1 degrees of freedom:
/// n = (k − 1) / (2ε) · (1 − 2/(9(k − 1)) + √(2/(9(k − 1))) · z)³. One bin needs one sample.
pub(crate) fn kld_particle_bound(k: usize, epsilon: f64, z: f64) -> usize {
    if k <= 1 {
        return 1;
    }
    let dof = (k - 1) as f64;
    let a = 2.0 / (9.0 * dof);
    let x = 1.0 - a + a.sqrt() * z;
    let n = (dof / (2.0 * epsilon) * x * x * x).ceil();
    if n.is_finite() && n < usize::MAX as f64 { n as usize } else { usize::MAX }
}

/// `v.floor() as i64`, bit for bit (NaN → 0, saturating), without the call to libm's `floor`
/// that the x86-64 baseline (no SSE4.1 rounding instruction) makes: truncate, then step down
/// where truncation went up (negative non-integers). The common-support test floors 14 times per
/// observed cell.
#[inline]
pub(crate) fn floor_to_i64(v: f64) -> i64 {
    let t = v as i64;
    if (t as f64) > v { t.saturating_sub(1) } else { t }
}

fn check_pose(p: Pose2, what: &'static str) -> Result<(), LocalizationError> {
    if p.x.is_finite() && p.y.is_finite() && p.yaw.is_finite() {
        Ok(())
    } else {
        Err(LocalizationError::NonFinite(what))
    }
}

/// The highest cost level that still counts as agreement.
fn agreement_level(field: &MatchField, agreement_distance_m: f64) -> u8 {
    let level = (agreement_distance_m / field.metres_per_level as f64).floor();
    level.clamp(0.0, (UNKNOWN_COST_LEVEL - 1) as f64) as u8
}

/// Σ over the observed cells of weight × the class's random-guess cost: what a random pose
/// would score on this observation.
fn random_guess_cost(field: &MatchField, obs: &LocalObservation) -> f64 {
    obs.segments
        .iter()
        .map(|seg| {
            let weight = field.slots.weight.get(seg.slot).copied().unwrap_or(0.0) as f64;
            let cost = field.unknown_cost_m.get(seg.slot).copied().unwrap_or(0.0) as f64;
            weight * cost * (seg.end - seg.start) as f64
        })
        .sum()
}

/// A uniformly drawn pose on a known ground cell (the field must have some).
fn random_ground_particle<R: Rng + ?Sized>(field: &MatchField, rng: &mut R) -> Particle {
    random_particle_on(field, &field.ground_cells, rng)
}

/// Tries to draw a pose on a known ground cell (of `slot`'s class when given) within `radius_m`
/// of `around`: half the time with `around`'s heading give or take 0.2 rad (a robot carried
/// off mostly keeps its heading, which odometry carries on), otherwise uniform. `None` when
/// a few tries found no such cell.
fn random_particle_near<R: Rng + ?Sized>(
    field: &MatchField,
    around: Pose2,
    radius_m: f64,
    slot: Option<usize>,
    rng: &mut R,
) -> Option<Particle> {
    const TRIES: usize = 16;
    let spec = field.spec;
    for _ in 0..TRIES {
        // Uniform over the disc.
        let r = radius_m * rng.random::<f64>().sqrt();
        let a = rng.random::<f64>() * std::f64::consts::TAU;
        let (x, y) = (around.x + r * a.cos(), around.y + r * a.sin());
        let (u, v) = ((x - spec.origin.x) / spec.resolution_m, (y - spec.origin.y) / spec.resolution_m);
        if !(u.is_finite() && v.is_finite() && spec.contains(u.floor() as i64, v.floor() as i64)) {
            continue;
        }
        let index = v.floor() as usize * spec.width as usize + u.floor() as usize;
        let on = |s: usize| field.plane(s).get(index).copied() == Some(0);
        let ground = match slot {
            Some(s) => on(s),
            None => (0..field.slots.len()).any(|s| field.slots.is_ground.get(s).copied().unwrap_or(false) && on(s)),
        };
        if ground {
            let yaw = if rng.random::<bool>() {
                around.yaw + 0.2 * rng.sample::<f64, _>(StandardNormal)
            } else {
                rng.random::<f64>() * std::f64::consts::TAU
            };
            return Some(Particle { x, y, yaw: normalize_angle(yaw) });
        }
    }
    None
}

/// A pose drawn uniformly over a list of cells (should not be empty), with uniform heading.
fn random_particle_on<R: Rng + ?Sized>(field: &MatchField, cells: &[u32], rng: &mut R) -> Particle {
    let n = cells.len().max(1);
    let index = cells.get(rng.random_range(0..n)).copied().unwrap_or(0) as usize;
    let cell = field.spec.cell_of_index(index);
    let res = field.spec.resolution_m;
    Particle {
        x: field.spec.origin.x + (cell.col as f64 + rng.random::<f64>()) * res,
        y: field.spec.origin.y + (cell.row as f64 + rng.random::<f64>()) * res,
        yaw: normalize_angle(rng.random::<f64>() * std::f64::consts::TAU),
    }
}

/// Scales weights to sum to one (uniform if they are all zero or not finite).
fn normalize(weights: &mut [f64]) {
    let sum: f64 = weights.iter().sum();
    if sum.is_finite() && sum > 0.0 {
        weights.iter_mut().for_each(|w| *w /= sum);
    } else {
        let n = weights.len().max(1) as f64;
        weights.iter_mut().for_each(|w| *w = 1.0 / n);
    }
}

/// 1 / Σ w², for normalised weights.
fn effective_sample_size(weights: &[f64]) -> f64 {
    let sq: f64 = weights.iter().map(|w| w * w).sum();
    if sq > 0.0 { 1.0 / sq } else { 0.0 }
}

/// Weighted mean (circular for yaw) and row-major 3 × 3 covariance of (x, y, yaw).
fn weighted_mean_and_covariance(particles: &[Particle], weights: &[f64]) -> (Pose2, [f64; 9]) {
    let (mut mx, mut my, mut ms, mut mc) = (0.0, 0.0, 0.0, 0.0);
    for (p, w) in particles.iter().zip(weights) {
        mx += w * p.x;
        my += w * p.y;
        ms += w * p.yaw.sin();
        mc += w * p.yaw.cos();
    }
    let myaw = if ms == 0.0 && mc == 0.0 { 0.0 } else { ms.atan2(mc) };
    let mut cov = [0.0; 9];
    for (p, w) in particles.iter().zip(weights) {
        let d = [p.x - mx, p.y - my, normalize_angle(p.yaw - myaw)];
        for (i, di) in d.iter().enumerate() {
            for (j, dj) in d.iter().enumerate() {
                cov[i * 3 + j] += w * di * dj;
            }
        }
    }
    (Pose2::new(mx, my, myaw), cov)
}

/// Standard deviation of position along the widest axis of the xy covariance.
/// The poses a cell must be known from to be in the common support: the estimate, and the
/// estimate moved ± `sigmas` standard deviations along each principal axis of its position
/// covariance and turned ± `sigmas` standard deviations of heading.
fn support_poses(estimate: &PoseEstimate, sigmas: f64) -> [Pose2; 7] {
    let p = estimate.pose;
    let cov = &estimate.covariance;
    let (a, b, d) = (cov[0], cov[1], cov[4]);
    let half_trace = 0.5 * (a + d);
    let radius = (0.25 * (a - d) * (a - d) + b * b).sqrt();
    let finite = |v: f64| if v.is_finite() { v.max(0.0) } else { 0.0 };
    let (l1, l2) = (finite(half_trace + radius), finite(half_trace - radius));
    // Direction of the major axis.
    let theta = 0.5 * (2.0 * b).atan2(a - d);
    let theta = if theta.is_finite() { theta } else { 0.0 };
    let (s1, s2) = (sigmas * l1.sqrt(), sigmas * l2.sqrt());
    let (st, ct) = theta.sin_cos();
    let yaw_step = sigmas * finite(cov[8]).sqrt();
    let at = |dx: f64, dy: f64, dyaw: f64| Pose2::new(p.x + dx, p.y + dy, p.yaw + dyaw);
    [
        p,
        at(s1 * ct, s1 * st, 0.0),
        at(-s1 * ct, -s1 * st, 0.0),
        at(-s2 * st, s2 * ct, 0.0),
        at(s2 * st, -s2 * ct, 0.0),
        at(0.0, 0.0, yaw_step),
        at(0.0, 0.0, -yaw_step),
    ]
}

fn max_xy_std(cov: &[f64; 9]) -> f64 {
    let (a, b, d) = (cov[0], cov[1], cov[4]);
    let half_trace = 0.5 * (a + d);
    let radius = (0.25 * (a - d) * (a - d) + b * b).sqrt();
    let variance = half_trace + radius;
    if variance.is_nan() { f64::INFINITY } else { variance.max(0.0).sqrt() }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;
    use std::f64::consts::PI;

    #[test]
    fn floor_to_i64_is_floor_as_i64() {
        let specials = [
            0.0,
            -0.0,
            1e-300,
            -1e-300,
            0.5,
            -0.5,
            -1.0,
            1.0,
            -1.0 + f64::EPSILON,
            2.0f64.powi(52) + 0.5,
            -(2.0f64.powi(52) + 0.5),
            2.0f64.powi(53),
            9.3e18,
            -9.3e18,
            -9.223_372_036_854_775e18,
            1e300,
            -1e300,
            f64::MAX,
            f64::MIN,
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::NAN,
        ];
        for v in specials {
            assert_eq!(floor_to_i64(v), v.floor() as i64, "{v:e}");
        }
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        for _ in 0..100_000 {
            let v: f64 = rng.random_range(-5000.0..5000.0);
            assert_eq!(floor_to_i64(v), v.floor() as i64, "{v:e}");
            let tiny: f64 = rng.random_range(-1e-6..1e-6);
            assert_eq!(floor_to_i64(tiny), tiny.floor() as i64, "{tiny:e}");
        }
    }

    #[test]
    fn circular_mean_handles_the_wrap() {
        let particles = [Particle { x: 0.0, y: 0.0, yaw: PI - 0.1 }, Particle { x: 2.0, y: 0.0, yaw: -PI + 0.1 }];
        let (mean, cov) = weighted_mean_and_covariance(&particles, &[0.5, 0.5]);
        assert!((mean.x - 1.0).abs() < 1e-12);
        assert!(normalize_angle(mean.yaw - PI).abs() < 1e-9);
        assert!((cov[8] - 0.01).abs() < 1e-9, "yaw variance from wrapped differences: {}", cov[8]);
        assert!((cov[0] - 1.0).abs() < 1e-12);
        assert!((max_xy_std(&cov) - 1.0).abs() < 1e-12);
    }

    #[test]
    fn systematic_resampling_keeps_proportions() {
        let mut loc = CrossViewLocalizer::new(LocalizationParams { num_particles: 10, ..Default::default() }).unwrap();
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        loc.initialize(&PosePrior::default(), Pose2::default(), Time::ZERO, &mut rng).unwrap();
        for (i, p) in loc.particles.iter_mut().enumerate() {
            p.x = i as f64;
        }
        loc.weights = vec![0.0; 10];
        loc.weights[2] = 0.7;
        loc.weights[7] = 0.3;
        loc.resample(&mut rng);
        let twos = loc.particles.iter().filter(|p| p.x == 2.0).count();
        let sevens = loc.particles.iter().filter(|p| p.x == 7.0).count();
        assert_eq!((twos, sevens), (7, 3));
        assert!(loc.weights.iter().all(|&w| (w - 0.1).abs() < 1e-12));
    }

    #[test]
    fn kld_bound_follows_fox_formula() {
        assert_eq!(kld_particle_bound(0, 0.05, 2.326), 1);
        assert_eq!(kld_particle_bound(1, 0.05, 2.326), 1);
        // k = 2: 1/(2·0.05) · (1 − 2/9 + √(2/9) · 2.326)³ = 10 · 1.87424³ = 65.84 → 66.
        assert_eq!(kld_particle_bound(2, 0.05, 2.326), 66);
        // k = 11: 10/0.1 · (1 − 0.02222 + 0.14907 · 2.326)³ = 100 · 1.32452³ = 232.4 → 233.
        assert_eq!(kld_particle_bound(11, 0.05, 2.326), 233);
        // AMCL's defaults (ε = 0.01, z = 0.99), k = 11: 500 · 1.12535³ = 712.6 → 713.
        assert_eq!(kld_particle_bound(11, 0.01, 0.99), 713);
        let mut previous = 0;
        for k in 2..2000 {
            let n = kld_particle_bound(k, 0.05, 2.326);
            assert!(n > previous, "grows with the bins: k = {k}");
            assert!(n >= k - 1 && n <= kld_particle_bound(k, 0.02, 2.326));
            previous = n;
        }
    }

    /// Resamples a filter whose particles stand at `spread(i)` with uniform weights.
    fn resampled_count(params: LocalizationParams, spread: impl Fn(usize) -> Particle) -> usize {
        let mut loc = CrossViewLocalizer::new(params).unwrap();
        let mut rng = ChaCha8Rng::seed_from_u64(6);
        loc.initialize(&PosePrior::default(), Pose2::default(), Time::ZERO, &mut rng).unwrap();
        for (i, p) in loc.particles.iter_mut().enumerate() {
            *p = spread(i);
        }
        loc.resample(&mut rng);
        assert!(loc.weights.iter().all(|&w| (w - 1.0 / loc.particles.len() as f64).abs() < 1e-15));
        loc.particles.len()
    }

    #[test]
    fn kld_sampling_keeps_few_particles_on_a_tight_cloud_and_all_on_a_wide_one() {
        let params = LocalizationParams { kld_sampling: true, ..LocalizationParams::default() };
        let (n_max, n_min) = (params.num_particles, params.min_particles);
        // Everything in one bin: the minimum.
        let tight = |i: usize| Particle { x: 10.1 + 0.001 * (i % 7) as f64, y: 3.2, yaw: 0.05 };
        assert_eq!(resampled_count(params.clone(), tight), n_min);
        // Spread over 2 × 2 xy bins and 2 heading bins = 8 bins: the bound for 8 bins.
        let grid = |i: usize| Particle {
            x: 0.25 + 0.5 * (i % 2) as f64,
            y: 0.25 + 0.5 * ((i / 2) % 2) as f64,
            yaw: if (i / 4).is_multiple_of(2) { 0.05 } else { 0.25 },
        };
        let eight = kld_particle_bound(8, params.kld_error, params.kld_quantile_z);
        assert!(eight > n_min && eight < n_max, "{eight}");
        assert_eq!(resampled_count(params.clone(), grid), eight);
        // Spread over the whole city: the maximum.
        let wide = |i: usize| Particle { x: 3.0 * i as f64, y: -(i as f64), yaw: 0.01 * i as f64 };
        assert_eq!(resampled_count(params.clone(), wide), n_max);
        // Off: always the fixed count.
        let fixed = LocalizationParams { kld_sampling: false, ..params.clone() };
        assert_eq!(resampled_count(fixed, tight), n_max);
        // A minimum above the maximum means the maximum.
        let small = LocalizationParams { num_particles: 40, ..params };
        assert_eq!(resampled_count(small, tight), 40);
    }

    #[test]
    fn pose_at_composes_the_odometry_since_the_anchor() {
        let params = LocalizationParams { num_particles: 50, ..Default::default() };
        let mut loc = CrossViewLocalizer::new(params).unwrap();
        let mut rng = ChaCha8Rng::seed_from_u64(4);
        let prior = PosePrior { pose: Pose2::new(10.0, 5.0, PI / 2.0), std_xy_m: 0.0, std_yaw_rad: 0.0 };
        let odom0 = Pose2::new(100.0, -3.0, 0.3);
        loc.initialize(&prior, odom0, Time::ZERO, &mut rng).unwrap();
        // Odometry reports 2 m forward: in the map the robot faces north, so it moves to y = 7.
        let odom1 = odom0.compose(Pose2::new(2.0, 0.0, 0.0));
        let e = loc.pose_at(odom1);
        assert!((e.pose.x - 10.0).abs() < 1e-9 && (e.pose.y - 7.0).abs() < 1e-9, "{:?}", e.pose);
        assert!(e.covariance[0] > loc.estimate().covariance[0], "uncertainty grows with odometry");
        let same = loc.pose_at(odom0).pose;
        assert!((same.x - 10.0).abs() < 1e-9 && (same.y - 5.0).abs() < 1e-9);
        // After predicting the same delta the anchor moves with it: no double counting.
        loc.predict(Pose2::new(2.0, 0.0, 0.0), &mut rng).unwrap();
        let e2 = loc.pose_at(odom1);
        assert!((e2.pose.y - 7.0).abs() < 0.1, "only sampling noise: {:?}", e2.pose);
    }

    #[test]
    fn a_changed_map_is_picked_up_after_the_rebuild_interval() {
        use spomp_core::{AerialMap, GridSpec, Point2};
        let spec = GridSpec::new(Point2::new(0.0, 0.0), 0.5, 30, 20);
        let mut map_a = AerialMap::unknown(spec);
        map_a.class.iter_mut().for_each(|c| *c = 3);
        let mut map_b = map_a.clone();
        map_b.class[5] = 0;
        map_b.version += 1;
        let table = ClassTable::default_table();
        let mut loc = CrossViewLocalizer::new(LocalizationParams::default()).unwrap();
        let at = |s: f64| Time::from_secs_f64(s);
        loc.refresh_map(&map_a, &table, at(0.0)).unwrap();
        assert!(loc.field.as_ref().unwrap().matches(&map_a, &table));
        loc.refresh_map(&map_b, &table, at(4.0)).unwrap();
        assert!(loc.field.as_ref().unwrap().matches(&map_a, &table), "within 5 s the old planes serve");
        loc.refresh_map(&map_b, &table, at(5.5)).unwrap();
        assert!(loc.field.as_ref().unwrap().matches(&map_b, &table), "then the new map is used");
        let mut moved = map_b.clone();
        moved.spec.origin.x += 1.0;
        loc.refresh_map(&moved, &table, at(6.0)).unwrap();
        assert!(loc.field.as_ref().unwrap().matches(&moved, &table), "a new placement is used at once");
        loc.prepare_map(&map_a, &table).unwrap();
        assert!(loc.field.as_ref().unwrap().matches(&map_a, &table), "prepare_map always rebuilds");
    }

    #[test]
    fn localizers_with_the_same_map_and_parameters_share_one_field() {
        use spomp_core::{AerialMap, GridSpec, Point2};
        // A map no other test uses (a different origin), so no field of another test is shared.
        let spec = GridSpec::new(Point2::new(-7123.0, 411.0), 0.5, 40, 30);
        let mut map = AerialMap::unknown(spec);
        map.class.iter_mut().enumerate().for_each(|(i, c)| *c = [0, 3, 2][i % 7 % 3]);
        let table = ClassTable::default_table();
        let new = |params: LocalizationParams| {
            let mut loc = CrossViewLocalizer::new(params).unwrap();
            loc.prepare_map(&map, &table).unwrap();
            loc
        };
        let field = |loc: &CrossViewLocalizer| loc.field.clone().unwrap();
        let a = new(LocalizationParams::default());
        let b = new(LocalizationParams { num_particles: 50, ..Default::default() });
        assert!(Arc::ptr_eq(&field(&a), &field(&b)), "same map and planes parameters: one field");
        let c = new(LocalizationParams { max_match_distance_m: 3.0, ..Default::default() });
        assert!(!Arc::ptr_eq(&field(&a), &field(&c)), "other cost parameters: its own field");
        let mut other = map.clone();
        other.class[17] = 6;
        let mut d = CrossViewLocalizer::new(LocalizationParams::default()).unwrap();
        d.prepare_map(&other, &table).unwrap();
        assert!(!Arc::ptr_eq(&field(&a), &field(&d)), "same version, other contents: its own field");
        assert!(field(&d).matches(&other, &table));
        // A shared field equals one built alone.
        let alone = MatchField::build(&map, &table, &LocalizationParams::default()).unwrap();
        assert_eq!(field(&a).planes, alone.planes);
        assert_eq!(field(&a).unknown_cost_m, alone.unknown_cost_m);
        // Once nobody holds it, it is gone: a new localizer builds it anew.
        let weak = Arc::downgrade(&field(&a));
        drop((a, b));
        assert!(weak.upgrade().is_none());
    }

    #[test]
    fn uninitialised_and_non_finite_inputs_are_errors() {
        let mut loc = CrossViewLocalizer::new(LocalizationParams::default()).unwrap();
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        assert_eq!(loc.predict(Pose2::new(1.0, 0.0, 0.0), &mut rng), Err(LocalizationError::NotInitialized));
        let bad = PosePrior { pose: Pose2::new(f64::NAN, 0.0, 0.0), ..Default::default() };
        assert!(loc.initialize(&bad, Pose2::default(), Time::ZERO, &mut rng).is_err());
        loc.initialize(&PosePrior::default(), Pose2::default(), Time::ZERO, &mut rng).unwrap();
        assert!(loc.predict(Pose2::new(f64::INFINITY, 0.0, 0.0), &mut rng).is_err());
        assert!(CrossViewLocalizer::new(LocalizationParams { num_particles: 0, ..Default::default() }).is_err());
    }
}
