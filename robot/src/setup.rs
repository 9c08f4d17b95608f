//! The one translation from a mission to a robot: a loaded mission, a robot id and the
//! operating area (class table, grid, an optional prior map — never a simulator world) become
//! the robot's [`RuntimeConfig`]. Every adapter builds its robots through here.

use std::sync::Arc;

use spomp_behaviors::mission::MissionFile;
use spomp_behaviors::mission::schema::{
    DEFAULT_PRIOR_SIGMA_DEG, DEFAULT_PRIOR_SIGMA_M, DEFAULT_TICK_HZ, DEFAULT_TIME_LIMIT_PER_M_S, LocalizationMode,
};
use spomp_core::{AerialMap, ClassTable, GeoPoint, GoalId, GridSpec, Pose2, RobotId, RobotKind};
use spomp_localization::LocalizationParams;
use spomp_mapping::{CompressionParams, GoalDetectionParams, PngLevel};
use spomp_teamstate::TeamStateParams;

use crate::class_names::ClassNames;
use crate::runtime::{LocalizationSetup, RuntimeConfig, UpdateSchedule};
use crate::settings::{NavigationSettings, SettingsError};

/// Where the robots operate: what every robot's maps are laid over.
#[derive(Clone, Debug)]
pub struct OperatingArea {
    /// The semantic class table.
    pub classes: ClassTable,
    /// Grid of the aerial map the team builds.
    pub grid: GridSpec,
    /// An aerial map the robots start with (surveyed before the mission); `None`: they know only
    /// what the team maps. Shared: every robot set up over the area holds this one map until it
    /// changes its own copy.
    pub prior_map: Option<Arc<AerialMap>>,
    /// Where the map frame's origin (0, 0) lies on the Earth, when the area is georeferenced
    /// (an imported world's `gps_origin`): QGroundControl plans are placed by their coordinates
    /// through it. `None`: a robot's own georeference if its sections give one (its
    /// `ros2.gps_origin`, see `Robot::from_setup`), else each plan is laid out around its planned
    /// home.
    pub map_origin: Option<GeoPoint>,
}

impl OperatingArea {
    /// An area of `grid` with `classes`, no prior map and no georeference: the robots know only
    /// what the team maps, and QGroundControl plans are laid out around their planned homes.
    pub fn new(classes: ClassTable, grid: GridSpec) -> Self {
        OperatingArea { classes, grid, prior_map: None, map_origin: None }
    }
}

/// Where a robot's map-frame pose comes from, as the adapter must supply it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum PoseInput {
    /// The robot localizes itself (cross-view localizer on its panoramas and odometry); the
    /// adapter feeds odometry and panoramas only.
    OwnEstimate,
    /// The adapter feeds a map-frame pose (GPS on the UAV, the basestation's surveyed position).
    External,
    /// Simulator ground truth with Gaussian noise of this standard deviation (metres): the
    /// paper's simulation switch, only where the mission asks for it (`localization: { mode:
    /// ground_truth }`).
    GroundTruth {
        /// Position noise, metres (1σ).
        noise_m: f64,
    },
}

impl PoseInput {
    /// Name for summaries.
    pub fn name(&self) -> &'static str {
        match self {
            PoseInput::OwnEstimate => "cross_view",
            PoseInput::External => "external",
            PoseInput::GroundTruth { .. } => "ground_truth",
        }
    }
}

/// A robot of a mission, ready to build.
#[derive(Clone, Debug)]
pub struct RobotSetup {
    /// Its index in the mission's team.
    pub index: usize,
    /// The runtime configuration.
    pub config: RuntimeConfig,
    /// Where its pose comes from.
    pub pose_input: PoseInput,
    /// Its role's name.
    pub role: String,
    /// Tick rate of its tree, per second.
    pub tick_hz: f64,
    /// What the setup had to leave out (class names the area's table lacks), each with the
    /// mission field that named it: the robot reports them once as problems.
    pub warnings: Vec<String>,
    /// Where the map frame's origin lies on the Earth: the area's (its tree's QGroundControl
    /// plans are placed through it; without it, the robot's own sections may give one when it
    /// is built).
    pub map_origin: Option<GeoPoint>,
}

/// Why a mission's robot could not be set up.
#[derive(Debug, thiserror::Error)]
pub enum SetupError {
    /// No robot with that id in the team.
    #[error("no robot `{0}` in the mission's team")]
    UnknownRobot(String),
    /// A setting is invalid (the skill's own validation).
    #[error(transparent)]
    Settings(#[from] SettingsError),
    /// A class the robot's skills need is not in the area's class table.
    #[error("{field}: {message}")]
    Class {
        /// The mission field that names it.
        field: String,
        /// What is wrong.
        message: String,
    },
}

/// The seed of one robot's random stream from a run's seed: distinct, reproducible streams per
/// robot and run, whatever adapter runs them.
pub fn robot_seed(run_seed: u64, robot_index: usize) -> u64 {
    run_seed.wrapping_mul(0x9E37_79B9_7F4A_7C15).wrapping_add(robot_index as u64 + 1)
}

/// How often the mapping robot publishes its map as a new version, seconds.
pub const MAP_PUBLISH_PERIOD_S: f64 = 10.0;

/// What the adapter adds to the mission for the translation ([`RobotSetup::from_mission_with`]):
/// given to it, never patched into the configuration afterwards.
#[derive(Clone, Debug)]
pub struct SetupOptions {
    /// How often the mapping robot publishes its map as a new version, seconds.
    pub map_publish_period_s: f64,
    /// PNG effort of the published map layers.
    pub map_compression: CompressionParams,
    /// The robot's own seed, when it is known already (a replay takes the recorded one);
    /// `None`: [`robot_seed`] of the run's seed.
    pub robot_seed: Option<u64>,
}

impl Default for SetupOptions {
    fn default() -> Self {
        SetupOptions {
            map_publish_period_s: MAP_PUBLISH_PERIOD_S,
            // The whole map is re-encoded on every publish: favour speed over the last bytes.
            map_compression: CompressionParams { level: PngLevel::Fast },
            robot_seed: None,
        }
    }
}

impl RobotSetup {
    /// The robot `id` of `mission` over `area`; `run_seed` seeds its random stream
    /// ([`robot_seed`]).
    pub fn from_mission(
        mission: &MissionFile,
        id: &str,
        area: &OperatingArea,
        run_seed: u64,
    ) -> Result<Self, SetupError> {
        Self::from_mission_with(mission, id, area, run_seed, &SetupOptions::default())
    }

    /// [`Self::from_mission`] with the adapter's own inputs (map publishing, a known seed).
    pub fn from_mission_with(
        mission: &MissionFile,
        id: &str,
        area: &OperatingArea,
        run_seed: u64,
        options: &SetupOptions,
    ) -> Result<Self, SetupError> {
        let index = mission.team.iter().position(|r| r.id == id).ok_or_else(|| SetupError::UnknownRobot(id.into()))?;
        let spec = &mission.team[index];
        let start = Pose2::new(spec.start.x_m, spec.start.y_m, spec.start.yaw_deg.to_radians());
        let goals = mission.goals.as_ref();
        let team = team_params(mission);
        let names = ClassNames::new(mission, &area.classes);
        let (classes, mut notes) = names.robot(mission, index);
        notes.extend(names.mapping_notes());
        if let Some(e) = notes.iter().find(|n| n.error) {
            return Err(SetupError::Class { field: e.field.clone(), message: e.message.clone() });
        }
        let warnings = notes.iter().map(|n| format!("{}: {}", n.field, n.message)).collect();
        let detection = goals.and_then(|g| g.detect.as_ref()).and_then(|d| {
            let detects = matches!(spec.kind, RobotKind::Ugv | RobotKind::Basestation);
            let defaults = GoalDetectionParams::default();
            detects.then(|| GoalDetectionParams {
                class: classes.goal_class.clone().unwrap_or_else(|| d.class.clone()),
                merge_distance_m: d.merge_distance_m.unwrap_or(defaults.merge_distance_m),
                min_size_m: d.min_size_m.unwrap_or(defaults.min_size_m),
                placement_region_m: d.placement_region_m.unwrap_or(defaults.placement_region_m),
                deconfliction_radius_m: team.deconfliction_radius_m,
                ..defaults
            })
        });
        let (localization, pose_input) = match (spec.kind, spec.localization.as_ref()) {
            (RobotKind::Ugv, Some(l)) if l.mode == LocalizationMode::GroundTruth => {
                (LocalizationSetup::External, PoseInput::GroundTruth { noise_m: l.noise_m })
            }
            (RobotKind::Ugv, l) => (
                LocalizationSetup::CrossView {
                    params: Box::new(LocalizationParams {
                        kld_sampling: l
                            .and_then(|l| l.kld_sampling)
                            .unwrap_or_else(|| LocalizationParams::default().kld_sampling),
                        ground_classes: classes.ground_classes.clone(),
                        class_weights: classes.class_weights.clone(),
                        ..LocalizationParams::default()
                    }),
                    prior_sigma_m: l.map_or(DEFAULT_PRIOR_SIGMA_M, |l| l.prior_sigma_m),
                    prior_sigma_rad: l.map_or(DEFAULT_PRIOR_SIGMA_DEG, |l| l.prior_sigma_deg).to_radians(),
                    schedule: UpdateSchedule::default(),
                },
                PoseInput::OwnEstimate,
            ),
            _ => (LocalizationSetup::External, PoseInput::External),
        };
        let role = mission.roles.get(&spec.role);
        let nav = if spec.kind == RobotKind::Ugv {
            let layers: Vec<&serde_json::Value> =
                role.and_then(|r| r.navigation.as_ref()).into_iter().chain(spec.navigation.as_ref()).collect();
            let mut nav = NavigationSettings::resolve(&layers)?.into_nav_params();
            // The planner reports a name its table lacks; a mapped name is the table's.
            for name in &mut nav.global.graph.class_order {
                if let Some(resolved) = names.resolve(name) {
                    *name = resolved;
                }
            }
            Some(nav)
        } else {
            None
        };
        let config = RuntimeConfig {
            id: RobotId::new(&spec.id),
            kind: spec.kind,
            priority: spec.priority.unwrap_or(0),
            start,
            classes: area.classes.clone(),
            map_spec: Some(area.grid),
            team,
            detection,
            localization,
            nav,
            goal_time_per_m_s: goals.map_or(DEFAULT_TIME_LIMIT_PER_M_S, |g| g.time_limit_per_m_s),
            seed: options.robot_seed.unwrap_or_else(|| robot_seed(run_seed, index)),
            map_publish_period_s: options.map_publish_period_s,
            map_compression: options.map_compression.clone(),
            prior_map: area.prior_map.clone(),
            ground_teammates: mission
                .team
                .iter()
                .filter(|r| r.kind == RobotKind::Ugv && r.id != spec.id)
                .map(|r| RobotId::new(&r.id))
                .collect(),
        };
        Ok(RobotSetup {
            index,
            config,
            pose_input,
            role: spec.role.clone(),
            tick_hz: role.map_or(DEFAULT_TICK_HZ, |r| r.tick_hz),
            warnings,
            map_origin: area.map_origin,
        })
    }
}

/// The mission's named goals (`goals.manual` entries with a `name`) and the ids every robot
/// gives them (`mission/<index>`, as [`spomp_teamstate::TeamState::add_mission_goal`] does):
/// how an operator's command addresses a goal by its name in the mission.
pub fn mission_goal_names(mission: &MissionFile) -> Vec<(String, GoalId)> {
    mission
        .goals
        .iter()
        .flat_map(|g| g.manual.iter().enumerate())
        .filter_map(|(k, g)| {
            let id = GoalId { origin: RobotId::new(spomp_teamstate::MISSION_WRITER), seq: k as u32 };
            g.name.clone().map(|name| (name, id))
        })
        .collect()
}

/// The team-state parameters of a mission: its deconfliction radius and claim lease over the
/// skill's defaults. Scans are shared through the global planner's sharing filter (one owner),
/// so the team state keeps every scan it is given.
pub fn team_params(mission: &MissionFile) -> TeamStateParams {
    let defaults = TeamStateParams::default();
    let goals = mission.goals.as_ref();
    TeamStateParams {
        deconfliction_radius_m: goals.and_then(|g| g.deconfliction_radius_m).unwrap_or(defaults.deconfliction_radius_m),
        claim_lease_s: goals.and_then(|g| g.claim_lease_s).unwrap_or(defaults.claim_lease_s),
        scan_min_spacing_m: 0.0,
        ..defaults
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::expect_used)] // tests fail loudly by design

    use super::*;
    use spomp_core::Point2;

    fn mission_with_localization(localization: &str) -> MissionFile {
        let text = format!(
            "mission: kld\n\
             team:\n  - {{ id: ugv1, kind: ugv, role: idle, priority: 1, start: {{ x_m: 5, y_m: 5 }}, localization: {localization} }}\n\
             roles:\n  idle: {{ tree: {{ wait: {{ duration_s: 10 }} }} }}\n\
             complete_when: time_limit\ntime_limit_s: 10\n"
        );
        let loaded = spomp_behaviors::mission::load_mission_str(
            &text,
            std::path::Path::new("kld.yaml"),
            &crate::registry(),
            &Default::default(),
        );
        assert!(loaded.is_valid(), "{:#?}", loaded.diagnostics);
        loaded.mission.unwrap()
    }

    fn kld_of(mission: &MissionFile) -> bool {
        let area = OperatingArea::new(ClassTable::default_table(), GridSpec::new(Point2::new(0.0, 0.0), 0.5, 40, 40));
        let setup = RobotSetup::from_mission(mission, "ugv1", &area, 1).unwrap();
        match setup.config.localization {
            LocalizationSetup::CrossView { params, .. } => params.kld_sampling,
            LocalizationSetup::External => panic!("a cross-view robot"),
        }
    }

    /// A robot named after the team state's writer of mission goals would share their ids
    /// (issue 36): the loader refuses every such name, located at the robot's id.
    #[test]
    fn the_mission_goal_writer_is_a_reserved_robot_id() {
        let reserved = spomp_behaviors::mission::limits::RESERVED_ROBOT_IDS;
        assert!(reserved.contains(&spomp_teamstate::MISSION_WRITER), "{reserved:?}");
        let text = format!(
            "mission: clash\n\
             team:\n  - {{ id: {}, kind: ugv, role: idle, priority: 1, start: {{ x_m: 5, y_m: 5 }} }}\n\
             roles:\n  idle: {{ tree: {{ wait: {{ duration_s: 10 }} }} }}\n\
             complete_when: time_limit\ntime_limit_s: 10\n",
            spomp_teamstate::MISSION_WRITER
        );
        let loaded = spomp_behaviors::mission::load_mission_str(
            &text,
            std::path::Path::new("clash.yaml"),
            &crate::registry(),
            &Default::default(),
        );
        assert!(!loaded.is_valid());
        let d = &loaded.diagnostics[0];
        assert_eq!((d.line, d.node_path.as_str()), (3, "team[0].id"), "{d}");
        assert!(d.message.contains("is reserved"), "{d}");
    }

    #[test]
    fn kld_sampling_follows_the_mission_else_the_localizer_default() {
        assert!(kld_of(&mission_with_localization("{ mode: cross_view, kld_sampling: true }")));
        assert!(!kld_of(&mission_with_localization("{ mode: cross_view, kld_sampling: false }")));
        let default = LocalizationParams::default().kld_sampling;
        assert_eq!(kld_of(&mission_with_localization("{ mode: cross_view }")), default);
    }
}
