//! The typed mission file. Unknown keys are rejected everywhere; units are in key names
//! (`_s` seconds, `_m` metres, `_deg` degrees, `_mps` metres per second, `_hz` per second).
//!
//! Behaviour trees (`roles.*.tree`, `subtrees.*`) are compiled from the YAML node tree directly
//! (see `compile`), because their keys are node types from the registry; their JSON schema is
//! generated from the node manifest.

use std::collections::BTreeMap;

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};
use spomp_core::RobotKind;

use super::sections::Section;

/// A mission file.
#[derive(Debug, Clone, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct MissionFile {
    /// Mission name.
    pub mission: String,
    /// What the mission is for.
    #[serde(default)]
    pub description: Option<String>,
    /// Files with reusable `subtrees:`, relative to this file.
    #[serde(default)]
    pub include: Vec<String>,
    /// The robots.
    pub team: Vec<RobotSpec>,
    /// Where goals come from.
    #[serde(default)]
    pub goals: Option<GoalsSpec>,
    /// Behaviour of each role.
    pub roles: BTreeMap<String, RoleSpec>,
    /// Reusable trees, used with `subtree: {name: …}`.
    #[serde(default)]
    pub subtrees: BTreeMap<String, TreeNode>,
    /// When the mission is complete.
    #[serde(default)]
    pub complete_when: CompleteWhen,
    /// Mission time limit, seconds.
    pub time_limit_s: f64,
    /// Radio settings.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub comms: Option<Section>,
    /// Settings for `spomp sim` and dry runs.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sim: Option<Section>,
    /// Class names as the world's class table spells them, for the names the mission and the
    /// skills use: `{ grass_sidewalk: sidewalk, vehicle: car }`. Names not listed are looked up
    /// as they are (spellings that differ only in case and punctuation, `grass/sidewalk`, match
    /// without a listing).
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub classes: BTreeMap<String, String>,
}

/// A behaviour-tree node: a mapping with one key, the node type, whose value holds the node's
/// ports (and `children` / `child` / `states`). Its schema is generated from the node manifest.
#[derive(Debug, Clone, Default, Serialize, Deserialize)]
#[serde(transparent)]
pub struct TreeNode(pub serde_json::Value);

impl JsonSchema for TreeNode {
    fn schema_name() -> std::borrow::Cow<'static, str> {
        "TreeNode".into()
    }
    fn json_schema(_: &mut schemars::SchemaGenerator) -> schemars::Schema {
        // Replaced by the manifest-generated definition in `json_schema::mission_schema`.
        schemars::json_schema!({ "type": "object", "minProperties": 1, "maxProperties": 1 })
    }
}

/// One robot of the team.
#[derive(Debug, Clone, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct RobotSpec {
    /// Unique id (`ugv1`).
    pub id: String,
    /// `ugv`, `uav` or `basestation`.
    pub kind: RobotKind,
    /// Role name from `roles`.
    pub role: String,
    /// UGV priority, unique; lower number = higher priority (as in the paper).
    #[serde(default)]
    pub priority: Option<u32>,
    /// Start pose in the map frame.
    pub start: StartPose,
    /// Where the robot's map-frame pose comes from (UGVs).
    #[serde(default)]
    pub localization: Option<LocalizationSpec>,
    /// ROS 2 adapter settings.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ros2: Option<Section>,
    /// The team link of `spomp run` (team state between robot processes over Zenoh).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub team_link: Option<Section>,
    /// Navigation settings of this robot (UGVs), applied field by field over its role's. The
    /// section's types, defaults and rules are the skills' (see `docs/missions.md`).
    #[serde(default)]
    pub navigation: Option<serde_json::Value>,
}

/// A start pose.
#[derive(Debug, Clone, Copy, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct StartPose {
    /// East, metres.
    pub x_m: f64,
    /// North, metres.
    pub y_m: f64,
    /// Heading, degrees counter-clockwise from east.
    #[serde(default)]
    pub yaw_deg: f64,
}

/// Localization mode of a robot.
#[derive(Debug, Clone, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct LocalizationSpec {
    /// `cross_view` (the particle filter against the aerial map) or `ground_truth` (simulator
    /// only, with noise).
    pub mode: LocalizationMode,
    /// Prior position uncertainty at the start, metres (1σ).
    #[serde(default = "default_prior_position")]
    pub prior_sigma_m: f64,
    /// Prior heading uncertainty at the start, degrees (1σ).
    #[serde(default = "default_prior_yaw")]
    pub prior_sigma_deg: f64,
    /// Noise added to ground truth in `ground_truth` mode, metres (1σ).
    #[serde(default)]
    pub noise_m: f64,
    /// `cross_view` only: KLD-adaptive particle counts (AMCL's rule: few particles while
    /// tracking, all of them when lost); unset: the localizer's default (`kld_sampling` in
    /// spomp-localization's parameters).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub kld_sampling: Option<bool>,
    /// `cross_view` only: the classes the robot stands on (matched to the aerial map as ground;
    /// re-localisation spreads particles over them); unset: the localizer's default (road,
    /// grass_sidewalk, gravel). Names as in `classes:` or the world's class table.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ground_classes: Option<Vec<String>>,
    /// `cross_view` only: how much each class counts when a view is matched to the aerial map
    /// (0 = not at all); unset: the localizer's defaults. A class the world lacks is dropped
    /// with a warning.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub class_weights: Option<BTreeMap<String, f64>>,
}

/// A UGV's prior position uncertainty at the start when the mission leaves
/// `localization.prior_sigma_m` out, metres (1σ): the one home of this default.
pub const DEFAULT_PRIOR_SIGMA_M: f64 = 2.0;

/// A UGV's prior heading uncertainty at the start when the mission leaves
/// `localization.prior_sigma_deg` out, degrees (1σ): the one home of this default.
pub const DEFAULT_PRIOR_SIGMA_DEG: f64 = 5.0;

fn default_prior_position() -> f64 {
    DEFAULT_PRIOR_SIGMA_M
}

fn default_prior_yaw() -> f64 {
    DEFAULT_PRIOR_SIGMA_DEG
}

/// Localization modes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum LocalizationMode {
    /// Cross-view semantic localizer.
    CrossView,
    /// Simulator ground truth plus noise (the paper's simulation switch).
    GroundTruth,
}

/// Goal sources and coordination limits.
#[derive(Debug, Clone, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct GoalsSpec {
    /// Automatic detection in the aerial map.
    #[serde(default)]
    pub detect: Option<DetectSpec>,
    /// Operator-specified goals.
    #[serde(default)]
    pub manual: Vec<ManualGoal>,
    /// Goals closer than this are the same goal, metres; unset: the team state's default
    /// (10 m, the paper's).
    #[serde(default)]
    pub deconfliction_radius_m: Option<f64>,
    /// Time limit per metre of planned path, seconds (the paper's per-goal time limit).
    #[serde(default = "default_time_per_m")]
    pub time_limit_per_m_s: f64,
    /// A claim is a lease, seconds: its holder renews it while it holds the goal; a claim of
    /// another robot not renewed for this long no longer counts, so a goal held by a dead robot
    /// (or one out of contact that long) becomes claimable again. Must be > 0; unset: the team
    /// state's default (300 s).
    #[serde(default)]
    pub claim_lease_s: Option<f64>,
}

/// The per-goal time limit per metre of planned path when the mission leaves
/// `goals.time_limit_per_m_s` out (or has no `goals:`), seconds per metre: the one home of this
/// default.
pub const DEFAULT_TIME_LIMIT_PER_M_S: f64 = 2.0;

fn default_time_per_m() -> f64 {
    DEFAULT_TIME_LIMIT_PER_M_S
}

/// Goal detection settings.
#[derive(Debug, Clone, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct DetectSpec {
    /// Class to cluster.
    #[serde(default = "default_class")]
    pub class: String,
    /// Clusters closer than this merge into one, metres; unset: the detector's default (15 m).
    #[serde(default)]
    pub merge_distance_m: Option<f64>,
    /// Minimum cluster size, metres; unset: the detector's default (8 m).
    #[serde(default)]
    pub min_size_m: Option<f64>,
    /// Placement region around a cluster, metres; unset: the detector's default (7 m).
    #[serde(default)]
    pub placement_region_m: Option<f64>,
}

fn default_class() -> String {
    "vehicle".into()
}

/// A goal given by the operator.
#[derive(Debug, Clone, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct ManualGoal {
    /// East, metres.
    pub x_m: f64,
    /// North, metres.
    pub y_m: f64,
    /// Optional label.
    #[serde(default)]
    pub name: Option<String>,
}

/// A role: the behaviour tree its robots run.
#[derive(Debug, Clone, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct RoleSpec {
    /// What the role does.
    #[serde(default)]
    pub description: Option<String>,
    /// Initial blackboard entries: `name: value` (type from the ports they feed).
    #[serde(default)]
    pub blackboard: BTreeMap<String, serde_json::Value>,
    /// Blackboard entries that survive a reboot: `spomp run` keeps their values in the robot's
    /// state file with its team state and restores them at start (e.g. the UAV's next survey
    /// waypoint). Each needs an initial value in `blackboard`.
    #[serde(default)]
    pub persist: Vec<String>,
    /// Tick rate of the tree.
    #[serde(default = "default_tick")]
    pub tick_hz: f64,
    /// Navigation settings of the role's robots (UGVs): `profile`, `terrain`, `local_goal`,
    /// `control`, `global_planner`, `watchdog`; a robot's own `navigation` overrides them field
    /// by field.
    #[serde(default)]
    pub navigation: Option<serde_json::Value>,
    /// The tree.
    pub tree: TreeNode,
}

/// A role's tree ticks this often when the mission leaves `tick_hz` out, per second: the one
/// home of this default (the loader, the robot and the adapters take the role's value).
pub const DEFAULT_TICK_HZ: f64 = 10.0;

fn default_tick() -> f64 {
    DEFAULT_TICK_HZ
}

/// Mission completion.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum CompleteWhen {
    /// Every goal visited by at least one UGV (the paper's criterion).
    #[default]
    AllGoalsVisited,
    /// Every robot's tree finished.
    AllTreesDone,
    /// Only the time limit ends it.
    TimeLimit,
}

/// A file of reusable subtrees (`include:` target).
#[derive(Debug, Clone, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct IncludeFile {
    /// Further includes, relative to this file.
    #[serde(default)]
    pub include: Vec<String>,
    /// The subtrees.
    pub subtrees: BTreeMap<String, TreeNode>,
}

impl MissionFile {
    /// An adapter section of the mission (`comms`, `sim`) as written, when given.
    pub fn section(&self, name: &str) -> Option<&serde_json::Value> {
        match name {
            "comms" => self.comms.as_ref(),
            "sim" => self.sim.as_ref(),
            _ => None,
        }
        .map(|s| &s.0)
    }

    /// The slot of an adapter section of the mission (`comms`, `sim`), to patch it.
    pub fn section_mut(&mut self, name: &str) -> Option<&mut Option<Section>> {
        match name {
            "comms" => Some(&mut self.comms),
            "sim" => Some(&mut self.sim),
            _ => None,
        }
    }
}

impl RobotSpec {
    /// An adapter section of this robot (`ros2`, `team_link`) as written, when given.
    pub fn section(&self, name: &str) -> Option<&serde_json::Value> {
        match name {
            "ros2" => self.ros2.as_ref(),
            "team_link" => self.team_link.as_ref(),
            _ => None,
        }
        .map(|s| &s.0)
    }

    /// The slot of an adapter section of this robot (`ros2`, `team_link`), to patch it.
    pub fn section_mut(&mut self, name: &str) -> Option<&mut Option<Section>> {
        match name {
            "ros2" => Some(&mut self.ros2),
            "team_link" => Some(&mut self.team_link),
            _ => None,
        }
    }
}
