//! From a validated mission to the simulated team's surroundings: the radio and the faults
//! (the world and the operating area come from `spomp-world`, the robots from `spomp-robot`).

use spomp_behaviors::mission::{MissionFile, MissionSection};
use spomp_core::RobotId;
use spomp_robot::CommsSpec;
use spomp_world::{FaultSpec, SimSpec};

use crate::error::SimError;
use crate::radio::{Blackout, Faults, KillFault, RadioParams, Region};

/// Faults of the mission's `sim.faults`, merged with `extra` (from the command line).
pub fn faults_for_mission(mission: &MissionFile, extra: &Faults) -> Result<Faults, SimError> {
    let sim = SimSpec::of_mission(mission).map_err(|e| SimError::invalid("mission", e.to_string()))?;
    let mut faults = extra.clone();
    for f in &sim.faults {
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
    Ok(faults)
}

/// Radio parameters from the mission's `comms`.
pub fn radio_for_mission(mission: &MissionFile) -> Result<RadioParams, SimError> {
    let c = CommsSpec::of_mission(mission).map_err(|e| SimError::invalid("mission", e.to_string()))?;
    Ok(RadioParams {
        small_range_m: c.position_range_m,
        full_range_m: c.data_range_m,
        full_bytes_per_s: c.bandwidth_bytes_per_s,
        ..RadioParams::default()
    })
}
