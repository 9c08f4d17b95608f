//! From a validated mission to the simulated team: the world, each robot's body, runtime and
//! tree, the radio and the faults.

use std::path::Path;

use spomp_behaviors::mission::MissionFile;
use spomp_behaviors::mission::schema::{FaultSpec, LocalizationMode, WorldSpec};
use spomp_behaviors::runtime::{LocalizationSetup, NavParams, RuntimeConfig, UpdateSchedule};
use spomp_core::{Pose2, RobotId, RobotKind};
use spomp_global_planner::GlobalPlannerParams;
use spomp_local_planner::LocalPlannerParams;
use spomp_mapping::GoalDetectionParams;
use spomp_teamstate::TeamStateParams;

use crate::city::{CityParams, generate_city};
use crate::error::SimError;
use crate::radio::{Blackout, Faults, KillFault, RadioParams, Region};
use crate::world::World;

/// The world a mission names: generated (seeded by the mission's world seed, else the trial
/// seed) or loaded from a folder relative to the mission file. A mission without `sim.world`
/// gets the default generated city.
pub fn world_for_mission(mission: &MissionFile, base_dir: &Path, trial_seed: u64) -> Result<World, SimError> {
    let spec = mission.sim.as_ref().and_then(|s| s.world.clone());
    match spec {
        Some(WorldSpec::Dir(dir)) => World::load(base_dir.join(dir)),
        Some(WorldSpec::Generate(g)) => {
            let params = CityParams {
                width_m: g.size_m[0],
                height_m: g.size_m[1],
                vehicle_clusters: g.vehicle_clusters as usize,
                roadblocks: g.roadblocks as usize,
                ..CityParams::default()
            };
            generate_city(&params, g.seed.unwrap_or(trial_seed))
        }
        None => generate_city(&CityParams::default(), trial_seed),
    }
}

/// Faults of the mission's `sim.faults`, merged with `extra` (from the command line).
pub fn faults_for_mission(mission: &MissionFile, extra: &Faults) -> Faults {
    let mut faults = extra.clone();
    for f in mission.sim.as_ref().map(|s| s.faults.as_slice()).unwrap_or_default() {
        match f {
            FaultSpec::Kill { robot, at_s } => faults.kill.push(KillFault { robot: RobotId::new(robot), at_s: *at_s }),
            FaultSpec::Blackout { from_s, to_s, region } => faults.blackouts.push(Blackout {
                start_s: *from_s,
                end_s: *to_s,
                region: region
                    .as_ref()
                    .map(|c| Region::Circle { center: spomp_core::Point2::new(c.x_m, c.y_m), radius_m: c.radius_m }),
            }),
            FaultSpec::OdometryNoise { scale } => faults.odometry_noise_scale *= scale,
            FaultSpec::LocalizationNoise { scale } => faults.localization_noise_scale *= scale,
        }
    }
    faults
}

/// Radio parameters from the mission's `comms`.
pub fn radio_for_mission(mission: &MissionFile) -> RadioParams {
    let c = &mission.comms;
    RadioParams {
        small_range_m: c.position_range_m,
        full_range_m: c.data_range_m,
        full_bytes_per_s: c.bandwidth_bytes_per_s,
        ..RadioParams::default()
    }
}

/// Where a UGV's pose comes from in the simulator.
#[derive(Clone, Debug, PartialEq)]
pub enum PoseMode {
    /// The cross-view localizer on the robot's own panoramas (the default for UGVs).
    CrossView,
    /// Simulator ground truth with Gaussian noise of this standard deviation (metres); what the
    /// paper's simulation used. Only when the mission asks for it.
    GroundTruth {
        /// Position noise, metres (1σ).
        noise_m: f64,
    },
}

impl PoseMode {
    /// Name for summaries.
    pub fn name(&self) -> &'static str {
        match self {
            PoseMode::CrossView => "cross_view",
            PoseMode::GroundTruth { .. } => "ground_truth",
        }
    }
}

/// A robot's runtime configuration from the mission, plus its simulated pose mode.
pub fn runtime_config(
    mission: &MissionFile,
    robot_index: usize,
    world: &World,
    trial_seed: u64,
) -> Result<(RuntimeConfig, PoseMode), SimError> {
    let spec = mission
        .team
        .get(robot_index)
        .ok_or_else(|| SimError::invalid("mission", format!("no robot at index {robot_index}")))?;
    let start = Pose2::new(spec.start.x_m, spec.start.y_m, spec.start.yaw_deg.to_radians());
    let goals = mission.goals.as_ref();
    let deconfliction = goals.map(|g| g.deconfliction_radius_m).unwrap_or(10.0);
    // The global planner's sharing filter decides which scans are shared (one owner).
    // Claims are leases: a dead or silent holder's goal becomes claimable after the mission's lease.
    let team = TeamStateParams {
        deconfliction_radius_m: deconfliction,
        scan_min_spacing_m: 0.0,
        claim_lease_s: goals.map(|g| g.claim_lease_s).unwrap_or(TeamStateParams::default().claim_lease_s),
        ..Default::default()
    };
    let detection = goals.and_then(|g| g.detect.as_ref()).and_then(|d| {
        let detects = matches!(spec.kind, RobotKind::Ugv | RobotKind::Basestation);
        detects.then(|| GoalDetectionParams {
            class: d.class.clone(),
            merge_distance_m: d.merge_distance_m,
            min_size_m: d.min_size_m,
            placement_region_m: d.placement_region_m,
            deconfliction_radius_m: deconfliction,
            ..GoalDetectionParams::default()
        })
    });
    let (localization, mode) = match (spec.kind, spec.localization.as_ref()) {
        (RobotKind::Ugv, Some(l)) if l.mode == LocalizationMode::GroundTruth => {
            (LocalizationSetup::External, PoseMode::GroundTruth { noise_m: l.noise_m })
        }
        (RobotKind::Ugv, l) => (
            LocalizationSetup::CrossView {
                params: Box::default(),
                prior_sigma_m: l.map(|l| l.prior_sigma_m).unwrap_or(2.0),
                prior_sigma_rad: l.map(|l| l.prior_sigma_deg).unwrap_or(5.0).to_radians(),
                schedule: UpdateSchedule::default(),
            },
            PoseMode::CrossView,
        ),
        _ => (LocalizationSetup::External, PoseMode::GroundTruth { noise_m: 0.0 }),
    };
    let nav = (spec.kind == RobotKind::Ugv)
        .then(|| NavParams { local: LocalPlannerParams::simulation(), global: GlobalPlannerParams::default() });
    let config = RuntimeConfig {
        id: RobotId::new(&spec.id),
        kind: spec.kind,
        priority: spec.priority.unwrap_or(0),
        start,
        classes: world.classes().clone(),
        map_spec: Some(*world.spec()),
        team,
        detection,
        localization,
        nav,
        goal_time_per_m_s: goals.map(|g| g.time_limit_per_m_s).unwrap_or(2.0),
        // Distinct, reproducible streams per robot and trial.
        seed: trial_seed.wrapping_mul(0x9E37_79B9_7F4A_7C15).wrapping_add(robot_index as u64 + 1),
    };
    Ok((config, mode))
}
