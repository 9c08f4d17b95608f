//! The ground robot: skid-steer (unicycle) kinematics with speed and acceleration limits,
//! collisions against the world's geometry, and odometry that drifts.

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};
use spomp_core::{Odometry, OdometryCovariance, Point2, Pose2, Time, Twist2, normalize_angle};

use crate::error::SimError;
use spomp_world::World;
use spomp_world::{Obstacle, UgvLimits};

/// Parameters of the ground robot model.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct UgvParams {
    /// What the robot can drive over.
    pub limits: UgvLimits,
    /// Top forward speed, m/s.
    pub max_speed_mps: f64,
    /// Top reverse speed, m/s.
    pub max_reverse_speed_mps: f64,
    /// Top turn rate, rad/s.
    pub max_yaw_rate_radps: f64,
    /// Linear acceleration limit, m/s².
    pub max_accel_mps2: f64,
    /// Angular acceleration limit, rad/s².
    pub max_yaw_accel_radps2: f64,
    /// Longest move between two collision checks, metres (a fifth of a cell keeps thin walls
    /// from being jumped).
    pub max_substep_m: f64,
}

impl Default for UgvParams {
    fn default() -> Self {
        UgvParams {
            limits: UgvLimits::default(),
            max_speed_mps: 1.5,
            max_reverse_speed_mps: 0.5,
            max_yaw_rate_radps: 1.0,
            max_accel_mps2: 2.0,
            max_yaw_accel_radps2: 2.0,
            max_substep_m: 0.1,
        }
    }
}

/// What one step did.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct UgvStep {
    /// Distance driven, metres.
    pub moved_m: f64,
    /// Whether the world stopped the robot during the step.
    pub blocked: bool,
}

/// A ground robot in the world.
#[derive(Clone, Debug, PartialEq)]
pub struct Ugv {
    params: UgvParams,
    pose: Pose2,
    twist: Twist2,
    base_m: f32,
    distance_m: f64,
    collisions: u64,
    /// Where the robot last hit something, until it gets clear of that spot.
    contact: Option<Point2>,
}

/// How far a robot must get from where it hit something before a new hit counts again, metres.
const CONTACT_CLEARANCE_M: f64 = 0.25;

/// Moves `v`, `omega` for `dt` seconds along the exact arc.
fn integrate(p: Pose2, v: f64, omega: f64, dt: f64) -> Pose2 {
    let dyaw = omega * dt;
    let (dx, dy) = if dyaw.abs() < 1e-9 {
        (v * dt * p.yaw.cos(), v * dt * p.yaw.sin())
    } else {
        let r = v / omega;
        (r * ((p.yaw + dyaw).sin() - p.yaw.sin()), -r * ((p.yaw + dyaw).cos() - p.yaw.cos()))
    };
    Pose2::new(p.x + dx, p.y + dy, normalize_angle(p.yaw + dyaw))
}

fn approach(current: f64, target: f64, max_delta: f64) -> f64 {
    current + (target - current).clamp(-max_delta, max_delta)
}

impl Ugv {
    /// A robot standing still at `pose`; an error if it cannot stand there (on an impassable
    /// class such as a building, straddling a curb, off the world).
    pub fn new(world: &World, params: UgvParams, pose: Pose2) -> Result<Self, SimError> {
        let finite = [
            params.max_speed_mps,
            params.max_reverse_speed_mps,
            params.max_yaw_rate_radps,
            params.max_accel_mps2,
            params.max_yaw_accel_radps2,
        ];
        if finite.iter().any(|v| !(v.is_finite() && *v >= 0.0))
            || !(params.max_substep_m.is_finite() && params.max_substep_m > 0.0)
        {
            return Err(SimError::invalid(
                "UGV parameters",
                "speeds and accelerations must be finite and non-negative, max_substep_m positive",
            ));
        }
        let base_m = params
            .limits
            .stand_at(world, pose.position())
            .map_err(|e| SimError::invalid("UGV start pose", e.to_string()))?;
        Ok(Ugv { params, pose, twist: Twist2::ZERO, base_m, distance_m: 0.0, collisions: 0, contact: None })
    }

    /// Ground-truth pose.
    pub fn pose(&self) -> Pose2 {
        self.pose
    }

    /// Moves the robot to `pose` at once, stopped (the "kidnapped robot" test); an error, and
    /// no change, if it cannot stand there.
    pub fn teleport(&mut self, world: &World, pose: Pose2) -> Result<(), SimError> {
        let base = world.elevation_at(pose.position()).unwrap_or(f32::NAN);
        let base_m = self.params.limits.admits(world, pose.position(), base).ok_or_else(|| {
            SimError::invalid("teleport", format!("the robot cannot stand at ({:.2}, {:.2})", pose.x, pose.y))
        })?;
        self.pose = pose;
        self.base_m = base_m;
        self.twist = Twist2::ZERO;
        self.contact = None;
        Ok(())
    }

    /// Actual velocity.
    pub fn twist(&self) -> Twist2 {
        self.twist
    }

    /// Height of the ground under the robot's centre, metres.
    pub fn base_elevation_m(&self) -> f32 {
        self.base_m
    }

    /// Distance driven so far, metres.
    pub fn distance_m(&self) -> f64 {
        self.distance_m
    }

    /// Number of times the robot ran into something: pushing on against the same obstacle
    /// counts once, until the robot has got clear of the spot.
    pub fn collisions(&self) -> u64 {
        self.collisions
    }

    /// The parameters.
    pub fn params(&self) -> &UgvParams {
        &self.params
    }

    /// Drives for `dt_s` seconds towards the commanded velocity. The actual velocity follows the
    /// command within the acceleration limits; a move the world does not admit (a step above
    /// the limit, a wall, the world's edge) stops the robot where it is, though it may still
    /// turn on the spot (its footprint is a disc). Non-finite commands count as zero.
    pub fn step(&mut self, world: &World, cmd: Twist2, dt_s: f64) -> UgvStep {
        self.step_among(world, cmd, dt_s, &[])
    }

    /// [`Ugv::step`] among other robots: a move that brings the footprint closer to an
    /// obstacle it overlaps is refused like a wall (moving apart is always allowed).
    pub fn step_among(&mut self, world: &World, cmd: Twist2, dt_s: f64, others: &[Obstacle]) -> UgvStep {
        if !(dt_s.is_finite() && dt_s > 0.0) {
            return UgvStep { moved_m: 0.0, blocked: false };
        }
        let p = &self.params;
        let v_cmd = if cmd.v.is_finite() { cmd.v.clamp(-p.max_reverse_speed_mps, p.max_speed_mps) } else { 0.0 };
        let w_cmd =
            if cmd.omega.is_finite() { cmd.omega.clamp(-p.max_yaw_rate_radps, p.max_yaw_rate_radps) } else { 0.0 };
        let v = approach(self.twist.v, v_cmd, p.max_accel_mps2 * dt_s);
        let omega = approach(self.twist.omega, w_cmd, p.max_yaw_accel_radps2 * dt_s);
        let n = ((v.abs() * dt_s) / p.max_substep_m).ceil().clamp(1.0, 10_000.0) as usize;
        let h = dt_s / n as f64;
        let mut moved_m = 0.0;
        let mut blocked = false;
        for _ in 0..n {
            if blocked {
                self.pose = integrate(self.pose, 0.0, omega, h);
                continue;
            }
            let next = integrate(self.pose, v, omega, h);
            let radius = self.params.limits.radius_m;
            let here = self.pose.position();
            let bumps = others.iter().any(|o| {
                let reach = radius + o.radius_m;
                let after = next.position().distance(o.center);
                after < reach && after < here.distance(o.center)
            });
            let admitted =
                if bumps { None } else { self.params.limits.admits_move(world, here, next.position(), self.base_m) };
            match admitted {
                Some(base) => {
                    moved_m += next.position().distance(self.pose.position());
                    self.pose = next;
                    self.base_m = base;
                }
                None => {
                    blocked = true;
                    self.pose = integrate(self.pose, 0.0, omega, h);
                }
            }
        }
        let here = self.pose.position();
        if self.contact.is_some_and(|c| c.distance(here) > CONTACT_CLEARANCE_M) {
            self.contact = None;
        }
        if blocked && self.contact.is_none() {
            self.collisions += 1;
            self.contact = Some(here);
        }
        self.twist = Twist2 { v: if blocked { 0.0 } else { v }, omega };
        self.distance_m += moved_m;
        UgvStep { moved_m, blocked }
    }
}

/// Odometry noise: Gaussian, its standard deviation proportional to the motion of each step.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct OdometryNoiseParams {
    /// Position noise per metre driven (standard deviation, metres per metre), along and across.
    pub translation_std_per_m: f64,
    /// Heading noise per radian turned (standard deviation, radians per radian).
    pub rotation_std_per_rad: f64,
    /// Heading noise per metre driven (standard deviation, radians per metre).
    pub rotation_std_per_m: f64,
}

impl Default for OdometryNoiseParams {
    fn default() -> Self {
        // "Ground truth odometry with a small amount of Gaussian noise" (paper, simulation).
        OdometryNoiseParams { translation_std_per_m: 0.01, rotation_std_per_rad: 0.01, rotation_std_per_m: 0.002 }
    }
}

/// Odometry in the robot's own frame: starts at the identity where the robot starts, then
/// integrates the true motion of every step with noise added, so it drifts away from the truth.
#[derive(Clone, Debug)]
pub struct OdometryModel {
    params: OdometryNoiseParams,
    scale: f64,
    last_true: Pose2,
    odom: Pose2,
    /// Covariance of `odom` (x, y, yaw), propagated step by step from the noise model.
    pose_cov: [f64; 9],
    /// Variances of the last step's velocity under the noise model (forward, turn rate).
    twist_var: [f64; 2],
    rng: ChaCha8Rng,
}

/// The least variance the odometry's covariance reports (1 mm², (1 mrad)², (1 mm/s)²): the
/// model's is exactly zero before the robot moves, and a zero claims a certainty that
/// robot_localization and Nav2 read as a configuration mistake.
pub const MIN_ODOMETRY_VARIANCE: f64 = 1e-6;

impl OdometryModel {
    /// Odometry of a robot whose true pose is `true_start`; `noise_scale` multiplies every
    /// standard deviation (0 = perfect odometry; see `Faults::odometry_noise_scale`).
    pub fn new(params: OdometryNoiseParams, noise_scale: f64, true_start: Pose2, seed: u64) -> Self {
        let scale = if noise_scale.is_finite() { noise_scale.max(0.0) } else { 0.0 };
        OdometryModel {
            params,
            scale,
            last_true: true_start,
            odom: Pose2::default(),
            pose_cov: [0.0; 9],
            twist_var: [0.0; 2],
            rng: ChaCha8Rng::seed_from_u64(seed),
        }
    }

    /// Updates with the robot's new true pose and returns the odometry reading.
    pub fn update(&mut self, stamp: Time, true_pose: Pose2, twist: Twist2) -> Odometry {
        let delta = self.last_true.between(true_pose);
        self.last_true = true_pose;
        let dist = delta.x.hypot(delta.y);
        let turn = delta.yaw.abs();
        let p = self.params.clone();
        let mut gauss = |std: f64| -> f64 {
            let z: f64 = self.rng.sample(StandardNormal);
            z * std * self.scale
        };
        let std_t = p.translation_std_per_m * dist;
        let std_r = p.rotation_std_per_rad * turn + p.rotation_std_per_m * dist;
        let noisy = Pose2::new(delta.x + gauss(std_t), delta.y + gauss(std_t), delta.yaw + gauss(std_r));
        self.propagate(noisy, [std_t * self.scale, std_t * self.scale, std_r * self.scale]);
        self.odom = self.odom.compose(noisy);
        // The velocity the noisy increments imply: the same rates per metre and radian, per
        // second of motion.
        let (v, w) = (twist.v.abs(), twist.omega.abs());
        let std_v = p.translation_std_per_m * v * self.scale;
        let std_w = (p.rotation_std_per_rad * w + p.rotation_std_per_m * v) * self.scale;
        self.twist_var = [std_v * std_v, std_w * std_w];
        Odometry { stamp, pose: self.odom, twist }
    }

    /// First-order propagation of the pose covariance through `odom ⊕ step`:
    /// Σ' = Jₓ Σ Jₓᵀ + Jᵤ Q Jᵤᵀ, with Q = diag(`step_std`²) the step's noise in the body frame.
    fn propagate(&mut self, step: Pose2, step_std: [f64; 3]) {
        let (s, c) = self.odom.yaw.sin_cos();
        let jx = [1.0, 0.0, -s * step.x - c * step.y, 0.0, 1.0, c * step.x - s * step.y, 0.0, 0.0, 1.0];
        let ju = [c, -s, 0.0, s, c, 0.0, 0.0, 0.0, 1.0];
        let q = [step_std[0].powi(2), 0.0, 0.0, 0.0, step_std[1].powi(2), 0.0, 0.0, 0.0, step_std[2].powi(2)];
        let a = mul3(&mul3(&jx, &self.pose_cov), &transpose3(&jx));
        let b = mul3(&mul3(&ju, &q), &transpose3(&ju));
        for k in 0..9 {
            self.pose_cov[k] = a[k] + b[k];
        }
    }

    /// The uncertainty of the latest reading under the noise model: the pose covariance grown
    /// over everything driven since the start, the velocity's from the last step's motion;
    /// each variance at least [`MIN_ODOMETRY_VARIANCE`].
    pub fn covariance(&self) -> OdometryCovariance {
        let mut pose = self.pose_cov;
        for k in 0..3 {
            pose[k * 3 + k] = pose[k * 3 + k].max(MIN_ODOMETRY_VARIANCE);
        }
        OdometryCovariance { pose, twist: self.twist_var.map(|v| v.max(MIN_ODOMETRY_VARIANCE)) }
    }

    /// The latest odometry-frame pose.
    pub fn pose(&self) -> Pose2 {
        self.odom
    }

    /// The robot was moved without driving (teleported): odometry does not see the jump.
    pub fn carried_to(&mut self, true_pose: Pose2) {
        self.last_true = true_pose;
    }
}

/// Product of two row-major 3 × 3 matrices.
fn mul3(a: &[f64; 9], b: &[f64; 9]) -> [f64; 9] {
    let mut m = [0.0; 9];
    for r in 0..3 {
        for c in 0..3 {
            m[r * 3 + c] = (0..3).map(|k| a[r * 3 + k] * b[k * 3 + c]).sum();
        }
    }
    m
}

/// Transpose of a row-major 3 × 3 matrix.
fn transpose3(a: &[f64; 9]) -> [f64; 9] {
    [a[0], a[3], a[6], a[1], a[4], a[7], a[2], a[5], a[8]]
}

/// Noise of the "ground truth with noise" pose source (the paper's simulation mode for
/// localization), independent per reading.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct PoseNoiseParams {
    /// Standard deviation of each position coordinate, metres.
    pub position_std_m: f64,
    /// Standard deviation of the heading, radians.
    pub yaw_std_rad: f64,
}

impl Default for PoseNoiseParams {
    fn default() -> Self {
        PoseNoiseParams { position_std_m: 0.1, yaw_std_rad: 0.01 }
    }
}

/// A map-frame pose source that reports the true pose with Gaussian noise, as the paper's
/// simulation did instead of running the localizer.
#[derive(Clone, Debug)]
pub struct NoisyPoseSource {
    params: PoseNoiseParams,
    scale: f64,
    rng: ChaCha8Rng,
}

impl NoisyPoseSource {
    /// A pose source; `noise_scale` multiplies both deviations (0 = exact ground truth).
    pub fn new(params: PoseNoiseParams, noise_scale: f64, seed: u64) -> Self {
        let scale = if noise_scale.is_finite() { noise_scale.max(0.0) } else { 0.0 };
        let clean = |v: f64| if v.is_finite() { v.abs() } else { 0.0 };
        let params =
            PoseNoiseParams { position_std_m: clean(params.position_std_m), yaw_std_rad: clean(params.yaw_std_rad) };
        NoisyPoseSource { params, scale, rng: ChaCha8Rng::seed_from_u64(seed) }
    }

    /// A reading of `true_pose` at `stamp`, with its covariance.
    pub fn estimate(&mut self, stamp: Time, true_pose: Pose2) -> spomp_core::PoseEstimate {
        let sp = self.params.position_std_m * self.scale;
        let sy = self.params.yaw_std_rad * self.scale;
        let mut gauss = |std: f64| -> f64 {
            let z: f64 = self.rng.sample(StandardNormal);
            z * std
        };
        let pose =
            Pose2::new(true_pose.x + gauss(sp), true_pose.y + gauss(sp), normalize_angle(true_pose.yaw + gauss(sy)));
        let mut covariance = [0.0; 9];
        covariance[0] = sp * sp;
        covariance[4] = sp * sp;
        covariance[8] = sy * sy;
        spomp_core::PoseEstimate { stamp, pose, covariance, confidence: 1.0 }
    }
}

#[cfg(test)]
mod odometry_covariance_tests {
    use super::*;

    /// The true path: 10 m ahead, a quarter turn to the left, 10 m ahead, in 0.1 s steps at
    /// 1 m/s and 0.5 rad/s.
    fn path() -> Vec<(Pose2, Twist2)> {
        let mut out = Vec::new();
        let mut p = Pose2::new(3.0, -2.0, 0.4);
        for _ in 0..100 {
            p = p.compose(Pose2::new(0.1, 0.0, 0.0));
            out.push((p, Twist2 { v: 1.0, omega: 0.0 }));
        }
        for _ in 0..31 {
            p = p.compose(Pose2::new(0.0, 0.0, 0.05));
            out.push((p, Twist2 { v: 0.0, omega: 0.5 }));
        }
        for _ in 0..100 {
            p = p.compose(Pose2::new(0.1, 0.0, 0.0));
            out.push((p, Twist2 { v: 1.0, omega: 0.0 }));
        }
        out
    }

    #[test]
    fn propagated_covariance_matches_the_spread_of_many_noisy_runs() {
        let params = OdometryNoiseParams::default();
        let start = Pose2::new(3.0, -2.0, 0.4);
        let path = path();
        let runs = 3000;
        let mut ends = Vec::with_capacity(runs);
        let mut predicted = None;
        for seed in 0..runs as u64 {
            let mut m = OdometryModel::new(params.clone(), 1.0, start, seed);
            let mut last = Odometry::default();
            for (i, (p, t)) in path.iter().enumerate() {
                last = m.update(Time::from_secs_f64(i as f64 * 0.1), *p, *t);
            }
            ends.push(last.pose);
            predicted.get_or_insert(m.covariance());
        }
        let predicted = predicted.expect("runs");
        let n = runs as f64;
        let mean = |f: &dyn Fn(&Pose2) -> f64| ends.iter().map(f).sum::<f64>() / n;
        let (mx, my, myaw) = (mean(&|p| p.x), mean(&|p| p.y), mean(&|p| p.yaw));
        let d = |p: &Pose2| [p.x - mx, p.y - my, p.yaw - myaw];
        let mut empirical = [0.0; 9];
        for p in &ends {
            let e = d(p);
            for r in 0..3 {
                for c in 0..3 {
                    empirical[r * 3 + c] += e[r] * e[c] / (n - 1.0);
                }
            }
        }
        // Diagonals within 10 % (3000 samples: a variance's sampling error is ~2.6 %), the
        // x–yaw and y–yaw correlations (the largest off-diagonal terms) within 0.1 of it.
        for k in [0, 4, 8] {
            let rel = (predicted.pose[k] - empirical[k]).abs() / empirical[k];
            assert!(rel < 0.1, "entry {k}: predicted {} vs empirical {}", predicted.pose[k], empirical[k]);
        }
        for (a, b, k) in [(0, 8, 2), (4, 8, 5)] {
            let corr = |m: &[f64; 9]| m[k] / (m[a] * m[b]).sqrt();
            assert!(
                (corr(&predicted.pose) - corr(&empirical)).abs() < 0.1,
                "correlation {k}: {} vs {}",
                corr(&predicted.pose),
                corr(&empirical)
            );
        }
        // Driving straight at 1 m/s in the last step: only the translation and per-metre
        // heading terms.
        let v = 0.01_f64.powi(2);
        assert!((predicted.twist[0] - v).abs() < 1e-12, "{:?}", predicted.twist);
        assert!((predicted.twist[1] - 0.002_f64.powi(2)).abs() < 1e-12, "{:?}", predicted.twist);
    }

    #[test]
    fn a_robot_that_has_not_moved_reports_the_floor_not_zero() {
        let mut m = OdometryModel::new(OdometryNoiseParams::default(), 1.0, Pose2::default(), 1);
        m.update(Time::ZERO, Pose2::default(), Twist2::ZERO);
        let c = m.covariance();
        assert_eq!([c.pose[0], c.pose[4], c.pose[8]], [MIN_ODOMETRY_VARIANCE; 3]);
        assert_eq!(c.twist, [MIN_ODOMETRY_VARIANCE; 2]);
        // Perfect odometry (noise scale 0) stays at the floor however far it drives.
        let mut perfect = OdometryModel::new(OdometryNoiseParams::default(), 0.0, Pose2::default(), 1);
        for (i, (p, t)) in path().iter().enumerate() {
            perfect.update(Time::from_secs_f64(i as f64 * 0.1), *p, *t);
        }
        assert_eq!(perfect.covariance().pose[0], MIN_ODOMETRY_VARIANCE);
    }
}
