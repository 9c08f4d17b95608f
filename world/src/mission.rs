//! A mission's world and the operating area its robots are set up over: what `spomp sim` and
//! `spomp run` both need, so neither reaches the other for it.

use std::path::Path;

use spomp_behaviors::mission::MissionFile;
use spomp_behaviors::mission::MissionSection;
use spomp_robot::OperatingArea;

use crate::city::{CityParams, generate_city};
use crate::error::WorldError;
use crate::mission_section::{SimSpec, WorldSpec};
use crate::world::World;

/// The world a mission names: generated (seeded by the mission's world seed, else the trial
/// seed) or loaded from a folder relative to the mission file. A mission without `sim.world`
/// gets the default generated city.
pub fn world_for_mission(mission: &MissionFile, base_dir: &Path, trial_seed: u64) -> Result<World, WorldError> {
    match sim_section(mission)?.world {
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

/// The operating area robots are set up over in `world`: its class table and grid, and the
/// whole aerial map when the mission says the robots start with it (`sim.prior_map`).
pub fn operating_area(mission: &MissionFile, world: &World) -> Result<OperatingArea, WorldError> {
    Ok(OperatingArea {
        classes: world.classes().clone(),
        grid: *world.spec(),
        prior_map: sim_section(mission)?.prior_map.then(|| world.shared_map()),
        map_origin: world.meta.gps_origin,
    })
}

/// The mission's `sim:` section (its defaults when left out).
fn sim_section(mission: &MissionFile) -> Result<SimSpec, WorldError> {
    SimSpec::of_mission(mission).map_err(|e| WorldError::Invalid { what: "mission section", message: e.to_string() })
}
