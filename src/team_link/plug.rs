//! The Zenoh link plugged into `spomp run`'s ROS 2 node, and the state file (the `deploy`
//! feature).

use std::collections::BTreeSet;
use std::sync::Arc;

use anyhow::{Context, Result};
use spomp_behaviors::mission::MissionSection;
use spomp_behaviors::mission::schema::MissionFile;
use spomp_core::RobotId;
use spomp_robot::Robot;
use spomp_ros2::{RobotNode, TeamChannel};
use spomp_teamstate::Tier;
use spomp_zenoh::{KeyDir, LinkConfig, TeamLink, TeamLinkSpec};

use super::TeamLinkArgs;

impl TeamLinkArgs {
    /// Whether the team state goes over the Zenoh link rather than ROS 2 topics.
    fn wanted(&self, mission: &MissionFile, robot: &str) -> bool {
        self.keys.is_some()
            || !self.listen.is_empty()
            || !self.connect.is_empty()
            || mission.team.iter().any(|r| r.id == robot && TeamLinkSpec::given_for(r))
    }
}

/// The Zenoh link as the ROS 2 node's team channel.
struct ZenohChannel(TeamLink);

impl TeamChannel for ZenohChannel {
    fn reachable(&self) -> BTreeSet<RobotId> {
        self.0.reachable()
    }
    fn send(&mut self, to: &RobotId, tier: Tier, bytes: Vec<u8>) {
        self.0.send(to, tier, bytes);
    }
    fn receive(&mut self) -> Vec<(RobotId, Vec<u8>)> {
        self.0.receive()
    }
    fn stats(&self) -> serde_json::Value {
        serde_json::to_value(self.0.stats()).unwrap_or_default()
    }
    fn refused(&self) -> Vec<(&'static str, u64)> {
        self.0.stats().refused.by_reason().to_vec()
    }
}

/// Secures the robot, resumes it from its state file and opens the team link, as the options
/// and the mission say. Call before the node runs.
pub fn set_up(args: &TeamLinkArgs, mission: &MissionFile, robot_id: &str, robot: &mut Robot) -> Result<SetUp> {
    let mut notes = Vec::new();
    let id = RobotId::new(robot_id);
    let keys = match &args.keys {
        Some(dir) => {
            let keys = KeyDir::load(dir)?;
            if keys.team() != mission.mission {
                anyhow::bail!(
                    "{}: the keys are of team `{}`, the mission is `{}`",
                    dir.display(),
                    keys.team(),
                    mission.mission
                );
            }
            robot.secure_team(Arc::new(keys.security(&id)?)).context("securing the team state")?;
            notes.push(format!("team state signed and checked with the keys in {}", dir.display()));
            Some(keys)
        }
        None => None,
    };
    // Every boot a larger session, so peers forget this robot's earlier messages.
    let session = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|d| d.as_nanos() as u64)
        .unwrap_or(1)
        .max(1);
    robot.set_team_session(session);
    if let Some(path) = &args.state_file {
        match spomp_zenoh::read_state(path, robot_id) {
            Ok(None) => notes.push(format!("no state file at {} yet: starting fresh", path.display())),
            Ok(Some(bytes)) => match robot.resume(spomp_core::Time::ZERO, bytes) {
                Ok(s) => {
                    notes.push(format!(
                        "resumed from {}: {} records, {} goals, {} own claims",
                        path.display(),
                        s.records,
                        s.goals,
                        s.own_claims
                    ));
                }
                Err(e) => notes.push(format!("state file {} ignored: {e}", path.display())),
            },
            // Something else is at the path: starting would overwrite it with the first save.
            Err(e @ spomp_zenoh::StateFileError::NotAStateFile { .. }) => {
                return Err(anyhow::Error::new(e).context("--state-file: refusing to start"));
            }
            Err(e) => notes.push(format!("state file ignored: {e}")),
        }
    }
    if !args.wanted(mission, robot_id) {
        return Ok(SetUp { link: None, notes });
    }
    let spec = match mission.team.iter().find(|r| r.id == robot_id) {
        Some(r) => TeamLinkSpec::of_robot(r)?,
        None => TeamLinkSpec::default(),
    };
    let mut config = LinkConfig::new(&mission.mission, id.clone());
    config.listen = if args.listen.is_empty() { spec.listen } else { args.listen.clone() };
    config.connect = if args.connect.is_empty() { spec.connect } else { args.connect.clone() };
    for e in config.listen.iter().chain(&config.connect) {
        spomp_zenoh::check_endpoint(e).map_err(|why| anyhow::anyhow!("--listen/--connect: {why}"))?;
    }
    config.multicast_scouting = spec.multicast_scouting;
    // Only the team may send: the key directory's members, or the mission's robots. Messages
    // naming anyone else are refused and counted by the link before anything is kept of them.
    config.members = Some(match &keys {
        Some(k) => k.members().cloned().collect(),
        // The operator (issue 37) is admitted like a robot.
        None => mission
            .team
            .iter()
            .map(|r| RobotId::new(&r.id))
            .chain(std::iter::once(RobotId::new(spomp_teamstate::OPERATOR_ID)))
            .collect(),
    });
    match &keys {
        Some(k) => config.credentials = Some(k.credentials(&id)?),
        None => notes.push("warning: team link without --keys: any process that reaches it is believed".into()),
    }
    let link = TeamLink::open(&config)?;
    notes.push(format!(
        "team link: Zenoh, listening on [{}], connecting to [{}]",
        config.listen.join(", "),
        config.connect.join(", ")
    ));
    Ok(SetUp { link: Some(link), notes })
}

/// What [`set_up`] did.
pub struct SetUp {
    /// The team link, when the team state goes over Zenoh.
    pub link: Option<TeamLink>,
    /// What to tell the operator.
    pub notes: Vec<String>,
}

/// Plugs the link and the state file into the node.
pub fn plug(node: &mut RobotNode, link: Option<TeamLink>, args: &TeamLinkArgs, robot_id: &str) {
    if let Some(link) = link {
        node.set_team_channel(Box::new(ZenohChannel(link)));
    }
    if let Some(path) = args.state_file.clone() {
        let robot = robot_id.to_string();
        node.set_state_sink(
            Box::new(move |bytes| {
                if let Err(e) = spomp_zenoh::write_state(&path, &robot, &bytes) {
                    errln!("warning: writing the state file: {e}");
                }
            }),
            args.state_period_s,
        );
    }
}
