//! Dynamic Window Approach controller (paper §Local Ground Planner, Controller; Fox et al. 1997).
//!
//! Samples (v, ω) uniformly in the window the acceleration limits allow around the current
//! command, rolls each out as a constant-twist arc over the horizon, and picks the cheapest:
//! C(τ) = C_g(τ) + C_o(τ), with C_g = ‖g − τ(T_w)‖ + |g × τ(T_w)| / ‖g‖ (the second term taken
//! as the distance to the ray towards g, i.e. ‖τ(T_w)‖ when τ(T_w) is behind the robot) and
//! C_o = (1/T_w)·Σ −D(Φ(τ(t)))·Δt, each trajectory point taken a look-ahead distance in front of
//! the robot. Points outside the safe region cost `outside_penalty` per second instead of −D.

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};
use spomp_core::{Point2, Pose2, Twist2};

use crate::error::{ParamsError, non_negative, positive};
use crate::region::SafeRegion;

/// Parameters of the DWA controller.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct DwaParams {
    /// Control rate; the dynamic window spans one period of acceleration, Hz.
    pub rate_hz: f64,
    /// Largest forward speed, m/s (never negative: no reversing).
    pub max_speed_mps: f64,
    /// Largest turn rate magnitude, rad/s.
    pub max_turn_rate_radps: f64,
    /// Linear acceleration limit, m/s².
    pub max_accel_mps2: f64,
    /// Angular acceleration limit, rad/s².
    pub max_angular_accel_radps2: f64,
    /// Number of speed samples across the window.
    pub speed_samples: u32,
    /// Number of turn-rate samples across the window.
    pub turn_rate_samples: u32,
    /// T_w: roll-out horizon, s.
    pub horizon_s: f64,
    /// Roll-out time step, s.
    pub step_s: f64,
    /// Distance in front of the robot at which trajectory points are evaluated, m.
    pub lookahead_m: f64,
    /// Weight of the obstacle term C_o relative to the goal term C_g.
    pub obstacle_weight: f64,
    /// Cost per second of trajectory spent outside the safe region.
    pub outside_penalty: f64,
}

impl Default for DwaParams {
    fn default() -> Self {
        DwaParams {
            rate_hz: 10.0,
            max_speed_mps: 1.5,
            max_turn_rate_radps: 1.0,
            max_accel_mps2: 2.0,
            max_angular_accel_radps2: 2.0,
            speed_samples: 10,
            turn_rate_samples: 4,
            horizon_s: 1.5,
            step_s: 0.1,
            lookahead_m: 0.3,
            obstacle_weight: 1.0,
            outside_penalty: 1000.0,
        }
    }
}

impl DwaParams {
    /// Checks every field's range.
    pub fn validate(&self) -> Result<(), ParamsError> {
        positive("rate_hz", self.rate_hz)?;
        non_negative("max_speed_mps", self.max_speed_mps)?;
        non_negative("max_turn_rate_radps", self.max_turn_rate_radps)?;
        non_negative("max_accel_mps2", self.max_accel_mps2)?;
        non_negative("max_angular_accel_radps2", self.max_angular_accel_radps2)?;
        if self.speed_samples == 0 || self.speed_samples > 1000 {
            return Err(ParamsError::new("speed_samples", "must be in 1..=1000"));
        }
        if self.turn_rate_samples == 0 || self.turn_rate_samples > 1000 {
            return Err(ParamsError::new("turn_rate_samples", "must be in 1..=1000"));
        }
        positive("horizon_s", self.horizon_s)?;
        positive("step_s", self.step_s)?;
        if self.horizon_s / self.step_s > 10_000.0 {
            return Err(ParamsError::new("step_s", "horizon_s / step_s must be <= 10000"));
        }
        non_negative("lookahead_m", self.lookahead_m)?;
        non_negative("obstacle_weight", self.obstacle_weight)?;
        non_negative("outside_penalty", self.outside_penalty)?;
        Ok(())
    }
}

/// Spacing of the points [`Dwa::reverse_step`] checks behind the robot, metres.
const REVERSE_CHECK_SPACING_M: f64 = 0.05;

/// The DWA controller. Holds only its parameters; a step allocates nothing.
#[derive(Clone, Debug)]
pub struct Dwa {
    params: DwaParams,
    steps: usize,
    last_cost: f64,
}

/// Evenly spaced samples over [lo, hi] (the midpoint when there is one sample).
#[inline]
fn sample(lo: f64, hi: f64, i: u32, n: u32) -> f64 {
    if n <= 1 { 0.5 * (lo + hi) } else { lo + (hi - lo) * i as f64 / (n - 1) as f64 }
}

impl Dwa {
    /// A controller with validated parameters.
    pub fn new(params: DwaParams) -> Result<Self, ParamsError> {
        params.validate()?;
        let steps = (params.horizon_s / params.step_s).round().max(1.0) as usize;
        Ok(Dwa { params, steps, last_cost: f64::NAN })
    }

    /// The parameters in use.
    pub fn params(&self) -> &DwaParams {
        &self.params
    }

    /// Cost of the command chosen by the last step (NaN before the first).
    pub fn last_cost(&self) -> f64 {
        self.last_cost
    }

    /// The reachable window of (v, ω) around `current`: one control period of acceleration,
    /// clipped to [0, v_max] × [−ω_max, ω_max].
    pub fn window(&self, current: Twist2) -> ((f64, f64), (f64, f64)) {
        let p = &self.params;
        let dt = 1.0 / p.rate_hz;
        let v = if current.v.is_finite() { current.v } else { 0.0 };
        let w = if current.omega.is_finite() { current.omega } else { 0.0 };
        let clip_v = |x: f64| x.clamp(0.0, p.max_speed_mps);
        let clip_w = |x: f64| x.clamp(-p.max_turn_rate_radps, p.max_turn_rate_radps);
        (
            (clip_v(v - p.max_accel_mps2 * dt), clip_v(v + p.max_accel_mps2 * dt)),
            (clip_w(w - p.max_angular_accel_radps2 * dt), clip_w(w + p.max_angular_accel_radps2 * dt)),
        )
    }

    /// A recovery step backwards: the command that reverses straight at up to `speed_mps`
    /// (within one control period of acceleration from `current`), or `None` when the ground
    /// behind is not known safe. Normal control ([`Dwa::step_in_region`]) never reverses; a
    /// recovery behaviour that backs a wedged robot out uses this instead, and it must still not
    /// drive blind: every point of the straight line from the robot (`robot`, its pose in the
    /// region's frame) to `distance_m` behind it, plus the controller's `lookahead_m`, must lie
    /// in the safe region (sampled every 5 cm).
    pub fn reverse_step(
        &self,
        current: Twist2,
        robot: Pose2,
        distance_m: f64,
        speed_mps: f64,
        region: &SafeRegion,
    ) -> Option<Twist2> {
        let p = &self.params;
        let finite_pose = robot.x.is_finite() && robot.y.is_finite() && robot.yaw.is_finite();
        let usable = distance_m.is_finite() && distance_m >= 0.0 && speed_mps.is_finite() && speed_mps > 0.0;
        if !(finite_pose && usable) {
            return None;
        }
        let reach = distance_m + p.lookahead_m;
        let samples = (reach / REVERSE_CHECK_SPACING_M).ceil().max(1.0) as usize;
        let (s, c) = robot.yaw.sin_cos();
        let clear = (1..=samples).all(|k| {
            let back = reach * k as f64 / samples as f64;
            region.contains(Point2::new(robot.x - c * back, robot.y - s * back))
        });
        if !clear {
            return None;
        }
        let dt = 1.0 / p.rate_hz;
        let v = if current.v.is_finite() { current.v } else { 0.0 };
        let target = -speed_mps.min(p.max_speed_mps);
        Some(Twist2 { v: v + (target - v).clamp(-p.max_accel_mps2 * dt, p.max_accel_mps2 * dt), omega: 0.0 })
    }

    /// One control step with the region in the robot's current frame: `goal` is the local goal
    /// in that frame.
    pub fn step(&mut self, current: Twist2, goal: Point2, region: &SafeRegion) -> Twist2 {
        self.step_in_region(current, Pose2::default(), goal, region)
    }

    /// One control step when the robot has moved since the region was computed: `robot` is the
    /// robot's pose in the region's frame and `goal` the local goal in the region's frame.
    pub fn step_in_region(&mut self, current: Twist2, robot: Pose2, goal: Point2, region: &SafeRegion) -> Twist2 {
        let p = &self.params;
        let ((v_lo, v_hi), (w_lo, w_hi)) = self.window(current);
        let robot =
            if robot.x.is_finite() && robot.y.is_finite() && robot.yaw.is_finite() { robot } else { Pose2::default() };
        let goal_robot = if goal.x.is_finite() && goal.y.is_finite() {
            robot.inverse_transform_point(goal)
        } else {
            Point2::default()
        };
        let goal_norm = goal_robot.norm();
        let (rs, rc) = robot.yaw.sin_cos();
        let dt = p.step_s;
        let horizon = self.steps as f64 * dt;
        let weight = p.obstacle_weight * dt / horizon;
        let look = p.lookahead_m;
        let mut best = (f64::INFINITY, Twist2 { v: v_lo, omega: 0.5 * (w_lo + w_hi) });
        for wi in 0..p.turn_rate_samples {
            let omega = sample(w_lo, w_hi, wi, p.turn_rate_samples);
            let turn = omega * dt;
            let (turn_s, turn_c) = turn.sin_cos();
            let (half_s, half_c) = (0.5 * turn).sin_cos();
            // Chord of an arc of angle `turn`, per unit of path length.
            let chord_ratio = if turn.abs() > 1e-9 { half_s / (0.5 * turn) } else { 1.0 };
            for vi in 0..p.speed_samples {
                let v = sample(v_lo, v_hi, vi, p.speed_samples);
                let chord = v * dt * chord_ratio;
                let (mut x, mut y, mut hc, mut hs) = (0.0f64, 0.0f64, 1.0f64, 0.0f64);
                let mut obstacle_cost = 0.0;
                let mut end = Point2::new(look, 0.0);
                for _ in 0..self.steps {
                    // Advance along the chord at the mid-step heading, then turn.
                    x += chord * (hc * half_c - hs * half_s);
                    y += chord * (hs * half_c + hc * half_s);
                    let (nc, ns) = (hc * turn_c - hs * turn_s, hs * turn_c + hc * turn_s);
                    hc = nc;
                    hs = ns;
                    end = Point2::new(x + look * hc, y + look * hs);
                    let in_region = Point2::new(robot.x + rc * end.x - rs * end.y, robot.y + rs * end.x + rc * end.y);
                    obstacle_cost += match region.clearance_at(in_region) {
                        Some(d) => -(d as f64) * weight,
                        None => p.outside_penalty * dt,
                    };
                }
                let mut goal_cost = goal_robot.distance(end);
                if goal_norm > 0.0 {
                    // Distance of τ(T_w) from the ray towards g: the paper's |g × τ|/‖g‖ in front
                    // of the robot; behind it, ‖τ‖, so that facing away from a goal behind the
                    // robot is not a minimum of the cost.
                    goal_cost +=
                        if goal_robot.dot(end) >= 0.0 { goal_robot.cross(end).abs() / goal_norm } else { end.norm() };
                }
                let cost = goal_cost + obstacle_cost;
                if cost < best.0 {
                    best = (cost, Twist2 { v, omega });
                }
            }
        }
        self.last_cost = best.0;
        best.1
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]

    use super::*;

    /// A region of 8 bins, 5 m everywhere but `behind_m` straight behind (bin 4, azimuth π).
    fn region(behind_m: f32) -> SafeRegion {
        let mut ranges = [5.0f32; 8];
        ranges[4] = behind_m;
        SafeRegion::from_ranges(&ranges, &[false; 8], 1.0).unwrap()
    }

    #[test]
    fn reversing_needs_known_safe_ground_behind() {
        let dwa = Dwa::new(DwaParams::default()).unwrap();
        let open = dwa.reverse_step(Twist2::ZERO, Pose2::default(), 1.5, 0.3, &region(5.0)).unwrap();
        assert!(open.v < 0.0 && open.v >= -0.3 && open.omega == 0.0, "{open:?}");
        // An obstacle 1 m behind: no backing 1.5 m into it.
        assert!(dwa.reverse_step(Twist2::ZERO, Pose2::default(), 1.5, 0.3, &region(1.0)).is_none());
        // Turned around since the panorama (facing −x): "behind" is the open side ahead of it.
        let turned = Pose2::new(0.0, 0.0, std::f64::consts::PI);
        assert!(dwa.reverse_step(Twist2::ZERO, turned, 1.5, 0.3, &region(1.0)).is_some());
        // Accelerates within the window: from standstill, one period of 2 m/s² at 10 Hz.
        let slow = dwa.reverse_step(Twist2::ZERO, Pose2::default(), 1.5, 1.0, &region(5.0)).unwrap();
        assert!((slow.v + 0.2).abs() < 1e-9, "{slow:?}");
        assert!(dwa.reverse_step(Twist2::ZERO, Pose2::default(), f64::NAN, 0.3, &region(5.0)).is_none());
    }
}
