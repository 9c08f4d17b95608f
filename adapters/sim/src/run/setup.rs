//! From a validated mission to the simulated team's surroundings: the world, the operating
//! area the robots are set up over (the robots themselves come from `spomp-robot`), the radio
//! and the faults.

use std::path::Path;

use spomp_behaviors::mission::MissionFile;
use spomp_behaviors::mission::schema::{FaultSpec, WorldSpec};
use spomp_core::RobotId;
use spomp_robot::OperatingArea;

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

/// The operating area robots are set up over in `world`: its class table and grid, and the
/// whole aerial map when the mission says the robots start with it (`sim.prior_map`).
pub fn operating_area(mission: &MissionFile, world: &World) -> OperatingArea {
    OperatingArea {
        classes: world.classes().clone(),
        grid: *world.spec(),
        prior_map: mission.sim.as_ref().is_some_and(|s| s.prior_map).then(|| world.shared_map()),
        map_origin: world.meta.gps_origin,
    }
}
