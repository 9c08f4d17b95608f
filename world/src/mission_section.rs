//! The mission's `sim:` section, owned by the world model: which world a mission is simulated
//! in (a world folder or a generated city), whether the robots start with its aerial map, and
//! the scenario run on it (trials, seeds, faults). It lives here rather than in `spomp-sim`
//! because `spomp run` needs a mission's world and operating area too and must not depend on
//! the simulator for them ([`crate::world_for_mission`]); the simulator reads the faults. One
//! field per line, so the section grows by adding one.

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};
use spomp_behaviors::mission::limits;
use spomp_behaviors::mission::{MissionSection, SectionContext};

use crate::city::CityParams;

/// Simulation settings.
#[derive(Debug, Clone, Default, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct SimSpec {
    /// The world: generated or from a folder.
    #[serde(default)]
    pub world: Option<WorldSpec>,
    /// Default number of trials for `spomp sim`.
    #[serde(default)]
    pub trials: Option<u32>,
    /// Default first seed.
    #[serde(default)]
    pub seed: Option<u64>,
    /// Faults to inject.
    #[serde(default)]
    pub faults: Vec<FaultSpec>,
    /// Every robot starts with the whole aerial map of the world, as if it had been surveyed
    /// before the mission (the UAV, if any, still maps and shares updates). For missions
    /// without a UAV.
    #[serde(default)]
    pub prior_map: bool,
    /// Operator commands scripted at simulated times, each issued over the modelled radio.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub operator: Vec<crate::operator_script::ScriptedCommand>,
}

/// Which world to simulate.
#[derive(Debug, Clone, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields, rename_all = "snake_case")]
pub enum WorldSpec {
    /// A procedural city.
    Generate(GenerateSpec),
    /// A world folder (`world.yaml` and layers), relative to the mission.
    Dir(String),
}

/// Procedural city settings.
#[derive(Debug, Clone, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct GenerateSpec {
    /// Width and height, metres.
    #[serde(default = "default_size")]
    pub size_m: [f64; 2],
    /// Vehicle clusters.
    #[serde(default = "default_clusters")]
    pub vehicle_clusters: u32,
    /// Roadblocks.
    #[serde(default = "default_roadblocks")]
    pub roadblocks: u32,
    /// World seed (default: the trial seed).
    #[serde(default)]
    pub seed: Option<u64>,
}

// A generated world's defaults are the city generator's own (`CityParams::default`).
fn default_size() -> [f64; 2] {
    let city = CityParams::default();
    [city.width_m, city.height_m]
}

fn default_clusters() -> u32 {
    u32::try_from(CityParams::default().vehicle_clusters).unwrap_or(u32::MAX)
}

// A mission's generated city has fewer roadblocks than the generator's own default (6): the
// shipped missions' setting since the section was written.
fn default_roadblocks() -> u32 {
    3
}

/// A fault to inject in simulation.
#[derive(Debug, Clone, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields, rename_all = "snake_case")]
pub enum FaultSpec {
    /// Kill a robot.
    Kill {
        /// Robot id.
        robot: String,
        /// When, seconds.
        at_s: f64,
    },
    /// Radio blackout: every link (or every link with an end inside `region`) is cut.
    Blackout {
        /// Start, seconds.
        from_s: f64,
        /// End, seconds.
        to_s: f64,
        /// Where; everywhere when absent.
        #[serde(default)]
        region: Option<CircleSpec>,
    },
    /// Scale odometry noise.
    OdometryNoise {
        /// Multiplier of the default noise.
        scale: f64,
    },
    /// Scale the noise of ground-truth localization (`localization: { mode: ground_truth }`).
    LocalizationNoise {
        /// Multiplier of the configured noise.
        scale: f64,
    },
}

/// A disc in the map frame.
#[derive(Debug, Clone, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct CircleSpec {
    /// Centre east, metres.
    pub x_m: f64,
    /// Centre north, metres.
    pub y_m: f64,
    /// Radius, metres.
    pub radius_m: f64,
}

impl SimSpec {
    /// The first seed when neither the command line nor the mission gives one: the one home of
    /// this default (`spomp sim`, its dry run and `spomp run` take it).
    pub const DEFAULT_SEED: u64 = 1;
    /// Trials of `spomp sim` when neither the command line nor the mission gives a number.
    pub const DEFAULT_TRIALS: u32 = 1;

    /// The first seed: the mission's, else [`SimSpec::DEFAULT_SEED`].
    pub fn first_seed(&self) -> u64 {
        self.seed.unwrap_or(Self::DEFAULT_SEED)
    }
}

impl MissionSection for SimSpec {
    const NAME: &'static str = "sim";

    fn check(&self, ctx: &SectionContext<'_>, bad: &mut dyn FnMut(&[&str], String)) {
        if let Some(WorldSpec::Dir(dir)) = &self.world
            && let Some(own) = ctx.roots.first()
            && let Err(e) = limits::resolve_inside(ctx.roots, own, dir)
        {
            bad(&["world"], format!("the world folder {e}"));
        }
        if let Some(WorldSpec::Generate(g)) = &self.world
            && g.size_m.iter().any(|s| !(*s >= 50.0 && *s <= 5000.0))
        {
            bad(
                &["world", "generate", "size_m"],
                format!("each side must be between 50 and 5000 m, found {:?}", g.size_m),
            );
        }
        if self.trials == Some(0) {
            bad(&["trials"], "expected at least one trial".into());
        }
        for (i, f) in self.faults.iter().enumerate() {
            let idx = i.to_string();
            let negative = match f {
                FaultSpec::Kill { at_s, .. } => limits::duration_from_secs(*at_s).is_err(),
                FaultSpec::Blackout { from_s, to_s, region } => {
                    limits::duration_from_secs(*from_s).is_err()
                        || limits::duration_from_secs(*to_s).is_err()
                        || to_s < from_s
                        || region.as_ref().is_some_and(|c| c.radius_m.is_nan() || c.radius_m < 0.0)
                }
                FaultSpec::OdometryNoise { scale } | FaultSpec::LocalizationNoise { scale } => {
                    !(scale.is_finite() && (0.0..=100.0).contains(scale))
                }
            };
            if negative {
                bad(
                    &["faults", &idx],
                    "times must be between 0 and 1e9 s and in order, radii non-negative, scales between 0 and 100"
                        .into(),
                );
            }
            if let FaultSpec::Kill { robot, .. } = f
                && !ctx.mission.team.iter().any(|r| &r.id == robot)
            {
                bad(&["faults", &idx, "kill", "robot"], format!("no robot `{robot}` in the team"));
            }
        }
        let robots: Vec<&str> = ctx.mission.team.iter().map(|r| r.id.as_str()).collect();
        for (i, entry) in self.operator.iter().enumerate() {
            if let Err((field, message)) = entry.check(&robots) {
                let idx = i.to_string();
                let mut at = vec!["operator", idx.as_str()];
                if !field.is_empty() {
                    at.push(field.as_str());
                }
                bad(&at, message);
            }
        }
    }
}
