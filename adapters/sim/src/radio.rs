//! The radio (the paper's simulated communication): which pairs of robots may exchange what,
//! and how many bytes, at a given time. Pure: store-and-forward and priorities are the team
//! state's business; the radio only answers "link (a, b) at time t: tier, byte budget".

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};
use spomp_core::{Point2, RobotId, Time};

use crate::error::SimError;

/// Parameters of the radio model (paper: positions within 50 m, everything within 30 m).
/// Distances are horizontal: the UAV's altitude does not count.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct RadioParams {
    /// Range within which the small tier (positions and claims) flows, metres.
    pub small_range_m: f64,
    /// Range within which all tiers flow, metres.
    pub full_range_m: f64,
    /// Byte rate of a link carrying only the small tier, bytes per second.
    pub small_bytes_per_s: f64,
    /// Byte rate of a link carrying all tiers, bytes per second.
    pub full_bytes_per_s: f64,
}

impl Default for RadioParams {
    /// A mission's `comms:` defaults (their one home is `spomp_robot::CommsSpec`); the small
    /// tier's rate is the radio's own.
    fn default() -> Self {
        let comms = spomp_robot::CommsSpec::default();
        RadioParams {
            small_range_m: comms.position_range_m,
            full_range_m: comms.data_range_m,
            small_bytes_per_s: 4_000.0,
            full_bytes_per_s: comms.bandwidth_bytes_per_s,
        }
    }
}

/// What may flow over a link.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum LinkTier {
    /// Positions and claims only.
    Small,
    /// Everything (scans, maps).
    All,
}

/// A link that is up.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Link {
    /// What may flow.
    pub tier: LinkTier,
    /// Bytes the link may carry this step, each way.
    pub budget_bytes: u64,
}

/// A region of the plane.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields, rename_all = "snake_case")]
pub enum Region {
    /// A disc.
    Circle {
        /// Centre, map frame.
        center: Point2,
        /// Radius, metres.
        radius_m: f64,
    },
    /// A simple polygon (even–odd rule), map frame.
    Polygon {
        /// Vertices in order.
        points: Vec<Point2>,
    },
}

impl Region {
    /// Whether `p` is inside.
    pub fn contains(&self, p: Point2) -> bool {
        match self {
            Region::Circle { center, radius_m } => center.distance(p) <= *radius_m,
            Region::Polygon { points } => {
                let mut inside = false;
                let n = points.len();
                for i in 0..n {
                    let (a, b) = (points[i], points[(i + n - 1) % n]);
                    if (a.y > p.y) != (b.y > p.y) && p.x < (b.x - a.x) * (p.y - a.y) / (b.y - a.y) + a.x {
                        inside = !inside;
                    }
                }
                inside
            }
        }
    }
}

/// A radio blackout: no link during [start_s, end_s), everywhere or wherever either end of a
/// link is inside the region.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Blackout {
    /// Start, seconds since the mission start.
    pub start_s: f64,
    /// End (exclusive), seconds since the mission start.
    pub end_s: f64,
    /// Where; everywhere when absent.
    #[serde(default)]
    pub region: Option<Region>,
}

impl Blackout {
    /// Whether the blackout cuts a link between `a` and `b` at `t`.
    pub fn cuts(&self, t: Time, a: Point2, b: Point2) -> bool {
        let s = t.as_secs_f64();
        s >= self.start_s && s < self.end_s && self.region.as_ref().is_none_or(|r| r.contains(a) || r.contains(b))
    }
}

/// A robot that dies at a time: from then on it neither moves, senses, sends nor receives.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct KillFault {
    /// The robot.
    pub robot: RobotId,
    /// When, seconds since the mission start.
    pub at_s: f64,
}

/// Faults to inject, as mission data.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct Faults {
    /// Robots to kill.
    pub kill: Vec<KillFault>,
    /// Radio blackouts.
    pub blackouts: Vec<Blackout>,
    /// Multiplies every odometry noise standard deviation (1 = nominal, 0 = perfect).
    pub odometry_noise_scale: f64,
    /// Multiplies the deviations of the ground-truth-with-noise pose source (1 = nominal).
    pub localization_noise_scale: f64,
}

impl Default for Faults {
    fn default() -> Self {
        Faults { kill: Vec::new(), blackouts: Vec::new(), odometry_noise_scale: 1.0, localization_noise_scale: 1.0 }
    }
}

impl Faults {
    /// Checks times, regions and the noise scale.
    pub fn validate(&self) -> Result<(), SimError> {
        for k in &self.kill {
            if !k.at_s.is_finite() {
                return Err(SimError::invalid("faults", format!("kill time of `{}` is not finite", k.robot)));
            }
        }
        for (i, b) in self.blackouts.iter().enumerate() {
            if !(b.start_s.is_finite() && b.end_s.is_finite() && b.start_s <= b.end_s) {
                return Err(SimError::invalid("faults", format!("blackout {i} needs finite start_s <= end_s")));
            }
            match &b.region {
                Some(Region::Circle { radius_m, center })
                    if !(radius_m.is_finite() && *radius_m >= 0.0 && center.x.is_finite() && center.y.is_finite()) =>
                {
                    return Err(SimError::invalid("faults", format!("blackout {i}: bad circle")));
                }
                Some(Region::Polygon { points })
                    if points.len() < 3 || points.iter().any(|p| !(p.x.is_finite() && p.y.is_finite())) =>
                {
                    return Err(SimError::invalid(
                        "faults",
                        format!("blackout {i}: a polygon needs at least 3 finite points"),
                    ));
                }
                _ => {}
            }
        }
        for (name, v) in [
            ("odometry_noise_scale", self.odometry_noise_scale),
            ("localization_noise_scale", self.localization_noise_scale),
        ] {
            if !(v.is_finite() && v >= 0.0) {
                return Err(SimError::invalid("faults", format!("{name} must be zero or more")));
            }
        }
        Ok(())
    }

    /// When a robot dies, if it is to be killed (the earliest kill counts).
    pub fn kill_time(&self, robot: &RobotId) -> Option<Time> {
        self.kill.iter().filter(|k| &k.robot == robot).map(|k| Time::from_secs_f64(k.at_s)).min()
    }

    /// Whether a robot is alive at `t`.
    pub fn is_alive(&self, robot: &RobotId, t: Time) -> bool {
        self.kill_time(robot).is_none_or(|k| t < k)
    }
}

/// One radio node at a step.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RadioNode {
    /// Where it is (horizontal position), map frame.
    pub position: Point2,
    /// Whether it is alive (a dead robot has no links).
    pub alive: bool,
}

/// The radio model.
#[derive(Clone, Debug, PartialEq)]
pub struct Radio {
    params: RadioParams,
    blackouts: Vec<Blackout>,
}

impl Radio {
    /// A radio with the blackouts of `faults`.
    pub fn new(params: RadioParams, faults: &Faults) -> Result<Self, SimError> {
        let ok = |v: f64| v.is_finite() && v >= 0.0;
        if !(ok(params.small_range_m)
            && ok(params.full_range_m)
            && ok(params.small_bytes_per_s)
            && ok(params.full_bytes_per_s))
        {
            return Err(SimError::invalid("radio parameters", "ranges and rates must be finite and non-negative"));
        }
        faults.validate()?;
        Ok(Radio { params, blackouts: faults.blackouts.clone() })
    }

    /// The parameters.
    pub fn params(&self) -> &RadioParams {
        &self.params
    }

    /// The link between `a` and `b` at `t` for a step of `dt_s` seconds, if it is up.
    pub fn link(&self, t: Time, a: &RadioNode, b: &RadioNode, dt_s: f64) -> Option<Link> {
        if !(a.alive && b.alive) {
            return None;
        }
        let d = a.position.distance(b.position);
        if !d.is_finite() {
            return None;
        }
        let (tier, rate) = if d <= self.params.full_range_m {
            (LinkTier::All, self.params.full_bytes_per_s)
        } else if d <= self.params.small_range_m {
            (LinkTier::Small, self.params.small_bytes_per_s)
        } else {
            return None;
        };
        if self.blackouts.iter().any(|bo| bo.cuts(t, a.position, b.position)) {
            return None;
        }
        // The same rule as a robot process's send round (one meaning of a link's bandwidth).
        let budget = spomp_robot::mission_section::round_budget_bytes(rate, dt_s);
        Some(Link { tier, budget_bytes: budget })
    }

    /// Every link that is up among `nodes`, as (i, j, link) with i < j, written into `out`
    /// (cleared first; reuse it across steps).
    pub fn links_into(&self, t: Time, nodes: &[RadioNode], dt_s: f64, out: &mut Vec<(usize, usize, Link)>) {
        out.clear();
        for i in 0..nodes.len() {
            for j in i + 1..nodes.len() {
                if let Some(l) = self.link(t, &nodes[i], &nodes[j], dt_s) {
                    out.push((i, j, l));
                }
            }
        }
    }
}
