//! The ground robot: skid-steer (unicycle) kinematics with speed and acceleration limits,
//! collisions against the world's geometry, and odometry that drifts.

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};
use spomp_core::{Odometry, Point2, Pose2, Time, Twist2, normalize_angle};

use crate::error::SimError;
use crate::terrain::{Obstacle, UgvLimits};
use crate::world::World;

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
        // Geometry alone would let a robot stand on a roof: starts on impassable classes are
        // refused as well.
        if world
            .class_at(pose.position())
            .is_some_and(|c| world.classes().rank(c) >= spomp_core::classes::IMPASSABLE_RANK)
        {
            return Err(SimError::invalid(
                "UGV start pose",
                format!("({:.2}, {:.2}) is on an impassable class", pose.x, pose.y),
            ));
        }
        let base = world.elevation_at(pose.position()).unwrap_or(f32::NAN);
        let base_m = params.limits.admits(world, pose.position(), base).ok_or_else(|| {
            SimError::invalid("UGV start pose", format!("the robot cannot stand at ({:.2}, {:.2})", pose.x, pose.y))
        })?;
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
    rng: ChaCha8Rng,
}

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
            rng: ChaCha8Rng::seed_from_u64(seed),
        }
    }

    /// Updates with the robot's new true pose and returns the odometry reading.
    pub fn update(&mut self, stamp: Time, true_pose: Pose2, twist: Twist2) -> Odometry {
        let delta = self.last_true.between(true_pose);
        self.last_true = true_pose;
        let dist = delta.x.hypot(delta.y);
        let turn = delta.yaw.abs();
        let p = &self.params;
        let mut gauss = |std: f64| -> f64 {
            let z: f64 = self.rng.sample(StandardNormal);
            z * std * self.scale
        };
        let noisy = Pose2::new(
            delta.x + gauss(p.translation_std_per_m * dist),
            delta.y + gauss(p.translation_std_per_m * dist),
            delta.yaw + gauss(p.rotation_std_per_rad * turn + p.rotation_std_per_m * dist),
        );
        self.odom = self.odom.compose(noisy);
        Odometry { stamp, pose: self.odom, twist }
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
