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
pub use spomp_ros_msgs::DepthEncoding;

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
    #[serde(default)]
    pub comms: CommsSpec,
    /// Settings for `spomp sim` and dry runs.
    #[serde(default)]
    pub sim: Option<SimSpec>,
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
    #[serde(default)]
    pub ros2: Option<Ros2Spec>,
    /// The team link of `spomp run` (team state between robot processes over Zenoh).
    #[serde(default)]
    pub team_link: Option<TeamLinkSpec>,
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

/// How a robot's `spomp run` process meets its teammates (Zenoh endpoints; see docs/robots.md).
#[derive(Debug, Clone, Default, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct TeamLinkSpec {
    /// Endpoints this robot listens on, `tcp/HOST:PORT` (e.g. `tcp/0.0.0.0:7447` on the radio).
    #[serde(default)]
    pub listen: Vec<String>,
    /// Endpoints of teammates it connects to, `tcp/HOST:PORT`.
    #[serde(default)]
    pub connect: Vec<String>,
    /// Also find teammates by UDP multicast scouting (off: multicast reaches the whole network).
    #[serde(default)]
    pub multicast_scouting: bool,
}

/// ROS 2 settings of a robot.
#[derive(Debug, Clone, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Ros2Spec {
    /// Topic namespace (default `/<id>`).
    #[serde(default)]
    pub namespace: Option<String>,
    /// DDS domain id (`spomp run --domain-id` and `ROS_DOMAIN_ID` override it).
    #[serde(default)]
    pub domain_id: u16,
    /// Topic names by role, replacing the defaults (`odom`, `panorama/depth`, `cmd_vel`, …; see
    /// `docs/robots.md`); a name without a leading `/` is under the namespace.
    #[serde(default)]
    pub topics: std::collections::BTreeMap<String, String>,
    /// Only these local IPv4 addresses carry DDS discovery and data (e.g. `[127.0.0.1]`); empty:
    /// every interface.
    #[serde(default)]
    pub interfaces: Vec<String>,
    /// Stop (zero velocity) when odometry is older than this, seconds.
    #[serde(default = "default_odometry_timeout")]
    pub odometry_timeout_s: f64,
    /// Stop when the newest panorama is older than this, seconds.
    #[serde(default = "default_panorama_timeout")]
    pub panorama_timeout_s: f64,
    /// Encoding of the robot's depth images (`sensor_msgs/Image`): `32FC1` (default: REP-118's
    /// canonical metres), `16UC1` (REP-118's millimetres) or `mono16` (counts of 1/512 m,
    /// spomp's earlier form). A simulator farm publishes this one and logs record it; `spomp
    /// run` reads any of the three by the image's own `encoding` field.
    #[serde(default)]
    pub depth_encoding: DepthEncoding,
    /// Metres per count of a `16UC1`/`mono16` depth image (default: 0.001 for `16UC1`, 1/512
    /// for `mono16`; 0 counts mean no return). Only with an integer `depth_encoding`.
    #[serde(default)]
    pub depth_scale_m: Option<f64>,
    /// Vertical field of view of the panorama images, degrees (rows spread evenly over it,
    /// centred on the horizon).
    #[serde(default = "default_v_fov")]
    pub panorama_v_fov_deg: f64,
    /// Height of the panorama sensor above the ground, metres.
    #[serde(default = "default_sensor_height")]
    pub sensor_height_m: f64,
    /// Take time from `/clock` (a simulator's) instead of the wall clock.
    #[serde(default)]
    pub use_sim_time: bool,
    /// The GNSS reference: `sensor_msgs/NavSatFix` positions are converted to the map frame
    /// (east = +x, north = +y) around this point. Without it, NavSatFix input is refused.
    #[serde(default)]
    pub gps_origin: Option<GpsOrigin>,
    /// Type of the velocity command on `cmd_vel`: `twist_stamped` (default: what ros2_control's
    /// `diff_drive_controller` takes — on Jazzy only that — and Nav2's stamped default) or
    /// `twist` (Gazebo's diff-drive bridge, teleop tools, older drivers).
    #[serde(default)]
    pub cmd_vel_type: CmdVelType,
    /// Prefix of the default `odom`, `base_link` and sensor frame ids (never of `map`). Default:
    /// the namespace (`ugv1/`, `husky/`) while tf is the global `/tf`, none when the robot's tf
    /// topics are namespaced (each robot then has a tree of its own, as in Nav2's multi-robot
    /// bringup) or the namespace is the root.
    #[serde(default)]
    pub frame_prefix: Option<String>,
    /// Frame ids, each replacing its default (REP-105: `map`, `odom`, `base_link`; the panorama
    /// sensor's `lidar`), used as written (no prefix).
    #[serde(default)]
    pub frames: FramesSpec,
}

/// Type of a robot's velocity command on `cmd_vel`.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum CmdVelType {
    /// `geometry_msgs/Twist`.
    Twist,
    /// `geometry_msgs/TwistStamped` (stamp and `base_link` frame in the header).
    #[default]
    TwistStamped,
}

/// Frame ids of a robot, each replacing its default (see [`Ros2Spec::frames`]).
#[derive(Debug, Clone, Default, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct FramesSpec {
    /// The world-fixed frame of the estimate, paths, goals and setpoints (default `map`).
    #[serde(default)]
    pub map: Option<String>,
    /// The odometry frame (default `<prefix>odom`).
    #[serde(default)]
    pub odom: Option<String>,
    /// The robot's body frame (default `<prefix>base_link`).
    #[serde(default)]
    pub base_link: Option<String>,
    /// The panorama sensor's frame (default `<prefix>lidar`).
    #[serde(default)]
    pub sensor: Option<String>,
}

impl FramesSpec {
    /// Every frame given, as (field, id).
    pub fn given(&self) -> impl Iterator<Item = (&'static str, &str)> {
        [("map", &self.map), ("odom", &self.odom), ("base_link", &self.base_link), ("sensor", &self.sensor)]
            .into_iter()
            .filter_map(|(k, v)| v.as_deref().map(|v| (k, v)))
    }
}

impl Default for Ros2Spec {
    fn default() -> Self {
        Ros2Spec {
            namespace: None,
            domain_id: 0,
            topics: Default::default(),
            interfaces: Vec::new(),
            odometry_timeout_s: default_odometry_timeout(),
            panorama_timeout_s: default_panorama_timeout(),
            depth_encoding: DepthEncoding::default(),
            depth_scale_m: None,
            panorama_v_fov_deg: default_v_fov(),
            sensor_height_m: default_sensor_height(),
            use_sim_time: false,
            gps_origin: None,
            cmd_vel_type: CmdVelType::default(),
            frame_prefix: None,
            frames: FramesSpec::default(),
        }
    }
}

/// A WGS 84 point: the map frame's origin for GNSS input.
#[derive(Debug, Clone, Copy, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct GpsOrigin {
    /// Degrees, positive north.
    pub latitude_deg: f64,
    /// Degrees, positive east.
    pub longitude_deg: f64,
    /// Metres above the ellipsoid (of the map frame's z = 0).
    #[serde(default)]
    pub altitude_m: f64,
}

fn default_odometry_timeout() -> f64 {
    0.5
}

fn default_panorama_timeout() -> f64 {
    3.0
}

fn default_v_fov() -> f64 {
    90.0
}

fn default_sensor_height() -> f64 {
    0.4
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

/// Radio settings (the paper's simulation values by default).
#[derive(Debug, Clone, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct CommsSpec {
    /// Within this range robots exchange positions and claims, metres.
    #[serde(default = "default_pos_range")]
    pub position_range_m: f64,
    /// Within this range robots exchange everything, metres.
    #[serde(default = "default_data_range")]
    pub data_range_m: f64,
    /// Bytes per second per link, each way: what a link between two robots may carry. The
    /// simulator's radio gives a link `bandwidth × step` bytes per step; a robot process over
    /// ROS 2 gives each peer `bandwidth × period` bytes per round of team messages (one round
    /// a second). Unused bytes carry over while the link stays up, so an item larger than one
    /// round's budget (a map version) goes through after enough rounds.
    #[serde(default = "default_bandwidth")]
    pub bandwidth_bytes_per_s: f64,
    /// Disable direct UGV-to-UGV links (data only via the UAV and basestation).
    #[serde(default)]
    pub ugv_to_ugv: Option<bool>,
}

fn default_pos_range() -> f64 {
    50.0
}

fn default_data_range() -> f64 {
    30.0
}

fn default_bandwidth() -> f64 {
    1_000_000.0
}

impl Default for CommsSpec {
    fn default() -> Self {
        CommsSpec {
            position_range_m: default_pos_range(),
            data_range_m: default_data_range(),
            bandwidth_bytes_per_s: default_bandwidth(),
            ugv_to_ugv: None,
        }
    }
}

/// Simulation settings.
#[derive(Debug, Clone, Serialize, Deserialize, JsonSchema)]
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
    /// Operator commands scripted at simulated times (issue 37; see `operator_script`).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub operator: Vec<super::operator_script::ScriptedCommand>,
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

fn default_size() -> [f64; 2] {
    [400.0, 300.0]
}

fn default_clusters() -> u32 {
    15
}

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
