//! The robot runtime: what domain nodes reach through `TickContext::env`.
//!
//! An adapter (the simulator, the ROS 2 node, MCAP replay) owns one `RobotRuntime` per robot,
//! keeps its inputs current (pose, received team-state messages) and hands it to the executor
//! on every tick. Nodes downcast `env` with [`runtime`]; a node ticked without it fails and says
//! so, rather than guessing.

use std::collections::HashMap;

use spomp_core::{GridSpec, Pose2, PoseEstimate, RobotId, RobotKind};
use spomp_mapping::{CompressedMap, GoalDetector, MappingError, Orthomap};
use spomp_teamstate::{RecordKey, TeamState, TeamStateError, TeamStateParams};

use crate::node::TickContext;

/// One robot's state and skills as the behaviour nodes see them.
pub struct RobotRuntime {
    /// The robot.
    pub id: RobotId,
    /// Its kind.
    pub kind: RobotKind,
    /// The replicated team database.
    pub team: TeamState,
    /// Latest map-frame pose (from the localizer or GPS), kept current by the adapter.
    pub pose: Option<PoseEstimate>,
    /// Start pose (home).
    pub start: Pose2,
    /// This robot's copy of the aerial map, grown from map versions received in the team state.
    pub map: Option<Orthomap>,
    /// Goal detection as the mission's `goals.detect` configures it (none: no detection).
    pub detector: Option<GoalDetector>,
    /// Map version the last detection pass ran on.
    pub detected_version: Option<u64>,
    /// Grid of the operating area, for the map copy received maps grow.
    pub map_spec: Option<GridSpec>,
    /// Newest map version applied, per publishing robot.
    applied_maps: HashMap<RobotId, u64>,
}

impl RobotRuntime {
    /// A runtime with an empty team state. `priority` orders UGV claims (lower = higher).
    pub fn new(
        id: RobotId,
        kind: RobotKind,
        priority: u32,
        start: Pose2,
        team: TeamStateParams,
    ) -> Result<Self, TeamStateError> {
        let team = TeamState::new(id.clone(), priority, team)?;
        Ok(RobotRuntime {
            id,
            kind,
            team,
            pose: None,
            start,
            map: None,
            detector: None,
            detected_version: None,
            map_spec: None,
            applied_maps: HashMap::new(),
        })
    }

    /// Applies map versions that arrived in the team state since the last call to this robot's
    /// map copy (created over `spec` on first use). Returns the number of cells changed; a
    /// corrupt blob is an error and changes nothing (later versions still apply next call).
    pub fn ingest_team_maps(&mut self, spec: GridSpec) -> Result<usize, MappingError> {
        let fresh: Vec<(RobotId, u64, std::sync::Arc<Vec<u8>>)> = self
            .team
            .records()
            .filter_map(|r| match &r.key {
                RecordKey::Map(robot) => {
                    let v = self.team.latest_map(robot)?;
                    let newer = self.applied_maps.get(robot).is_none_or(|&seen| v.version > seen);
                    newer.then(|| (robot.clone(), v.version, v.blob.clone()))
                }
                _ => None,
            })
            .collect();
        let mut changed = 0;
        for (robot, version, blob) in fresh {
            let compressed = CompressedMap::from_bytes(&blob)?;
            let map = self.map.get_or_insert_with(|| Orthomap::new(spec));
            changed += map.apply_compressed(&compressed)?;
            self.applied_maps.insert(robot, version);
        }
        Ok(changed)
    }
}

/// The runtime in `ctx.env`, or a report naming the node that needed it.
pub fn runtime<'c>(ctx: &'c mut TickContext<'_>, node: &str) -> Option<&'c mut RobotRuntime> {
    if ctx.env.is::<RobotRuntime>() {
        ctx.env.downcast_mut::<RobotRuntime>()
    } else {
        ctx.blackboard.report(format!(
            "node `{node}` needs a robot runtime; run the mission through an adapter (spomp sim / run)"
        ));
        None
    }
}
