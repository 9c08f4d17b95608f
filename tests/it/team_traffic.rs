//! Issue 35: the experiment's byte counts come from what each robot counted of its own
//! traffic (`Robot::team_traffic`), not from recording every seam call. The counts must be the
//! ones the recorded `TeamOut` answers give, byte for byte, tier for tier.

#![allow(clippy::unwrap_used, clippy::expect_used)] // tests fail loudly by design

use std::collections::BTreeMap;
use std::path::Path;
use std::sync::Arc;

use spomp_behaviors::mission::{LoadOptions, load_mission_with};
use spomp_core::{RobotId, Time};
use spomp_robot::{RobotObserver, SeamCall, TeamTraffic};
use spomp_sim::run::{SimObserver, SimOptions, Simulation};
use spomp_teamstate::{SyncMessage, TierSet};
use spomp_world::world_for_mission;

/// Counts the answers of the recorded `TeamOut` calls, as the experiment's counter did.
#[derive(Default)]
struct RecordedOut(BTreeMap<RobotId, TeamTraffic>);

impl RobotObserver for RecordedOut {
    fn wants_seam(&self) -> bool {
        true
    }
    fn on_seam(&mut self, robot: &RobotId, _now: Time, call: &SeamCall) {
        let t = self.0.entry(robot.clone()).or_default();
        match call {
            SeamCall::TeamOut { tiers, sent: Some(bytes), .. } => {
                t.sent_messages += 1;
                if *tiers == TierSet::ALL {
                    t.sent_bytes_all_tiers += bytes.len() as u64;
                } else {
                    t.sent_bytes_fewer_tiers += bytes.len() as u64;
                }
                let split = SyncMessage::decode(bytes).unwrap().bytes_by_tier(bytes.len());
                for (total, b) in t.sent_bytes_by_tier.iter_mut().zip(split) {
                    *total += b;
                }
            }
            SeamCall::TeamIn { bytes, .. } => {
                t.received_messages += 1;
                t.received_bytes += bytes.len() as u64;
            }
            _ => {}
        }
    }
}

impl SimObserver for RecordedOut {}

#[test]
fn the_robots_own_traffic_counts_are_the_recorded_team_out_answers() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("missions/visit-all-vehicle-clusters.yaml");
    let registry = spomp::registry();
    let loaded = load_mission_with(&path, &registry, &LoadOptions::default());
    assert!(loaded.is_valid(), "{:#?}", loaded.diagnostics);
    let mission = loaded.mission.as_ref().unwrap();
    let world = world_for_mission(mission, &loaded.base_dir(), 1).unwrap();
    let options = SimOptions { seed: 1, time_limit_s: Some(40.0), ..SimOptions::default() };
    let sim = Simulation::new(&loaded, &registry, Arc::new(world), options).unwrap();
    let mut recorded = RecordedOut::default();
    let result = sim.run(&mut recorded);
    let counted: BTreeMap<RobotId, TeamTraffic> =
        result.team_traffic.iter().filter(|(_, t)| *t != TeamTraffic::default()).cloned().collect();
    // Both kinds of link carried messages, and every tier went somewhere.
    let all: u64 = counted.values().map(|t| t.sent_bytes_all_tiers).sum();
    let fewer: u64 = counted.values().map(|t| t.sent_bytes_fewer_tiers).sum();
    let maps: u64 = counted.values().map(|t| t.sent_bytes_by_tier[2]).sum();
    assert!(all > 0 && fewer > 0 && maps > 0, "{counted:#?}");
    assert_eq!(counted, recorded.0);
}
