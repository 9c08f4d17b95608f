//! A run's settings that are not in the mission.

use super::*;

/// Settings of a run that are not in the mission.
#[derive(Clone, Debug)]
pub struct SimOptions {
    /// Trial seed: the world (unless the mission fixes its seed), noise and every skill's RNG.
    pub seed: u64,
    /// Physics and sensor step, seconds.
    pub dt_s: f64,
    /// How often each radio link carries a sync message each way, seconds.
    pub sync_period_s: f64,
    /// How often the UAV publishes its map as a new version, seconds.
    pub map_publish_period_s: f64,
    /// PNG effort for the published map layers.
    pub map_compression: CompressionParams,
    /// Overrides the mission's time limit, seconds.
    pub time_limit_s: Option<f64>,
    /// Faults on top of the mission's.
    pub faults: Faults,
    /// Panoramic sensor of the UGVs.
    pub sensor: SensorParams,
    /// UGV body.
    pub ugv: UgvParams,
    /// UAV flight and camera.
    pub uav: UavParams,
    /// Odometry noise.
    pub odometry_noise: OdometryNoiseParams,
    /// Run the robots' heavy skills as background work that takes this long, as `spomp run`
    /// does on its worker threads; `None`: inline, within the step (the default).
    pub skill_latency: Option<SkillLatency>,
    /// Step the robots' sensing, perception and ticks on rayon's threads (when it has more than
    /// one). Results are the same either way: each robot's work touches only that robot, and
    /// observers are told in robot order after it.
    pub parallel_robots: bool,
}

/// Modelled compute time of the heavy skills when they run in the background
/// ([`SimOptions::skill_latency`]): each job is taken between steps, done at once, and handed
/// back to its robot at the first step this long after — deterministic, unlike threads, so a
/// run repeats bit for bit and its log replays.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct SkillLatency {
    /// A panorama's localization and terrain analysis, seconds.
    pub perception_s: f64,
    /// The global planner's graph growth and training, seconds.
    pub planner_s: f64,
}

impl SkillLatency {
    /// Figures of the order `spomp run` measures on a 2-core machine (a panorama in tens of
    /// milliseconds, a graph rebuild in most of a second).
    pub const TYPICAL: SkillLatency = SkillLatency { perception_s: 0.05, planner_s: 0.8 };
}

impl From<SkillLatency> for spomp_robot::WorkLatency {
    fn from(l: SkillLatency) -> Self {
        spomp_robot::WorkLatency { perception_s: l.perception_s, planner_s: l.planner_s }
    }
}

impl Default for SimOptions {
    fn default() -> Self {
        SimOptions {
            seed: 1,
            dt_s: 0.1,
            sync_period_s: 0.5,
            map_publish_period_s: 10.0,
            // The whole map is re-encoded on every publish: favour speed over the last bytes.
            map_compression: CompressionParams { level: PngLevel::Fast },
            time_limit_s: None,
            faults: Faults::default(),
            sensor: SensorParams::default(),
            ugv: UgvParams::default(),
            uav: UavParams::default(),
            odometry_noise: OdometryNoiseParams::default(),
            skill_latency: None,
            parallel_robots: true,
        }
    }
}
