//! `spomp run`'s team link: the Zenoh link of `spomp-zenoh` plugged into the ROS 2 node, the
//! team's keys, and the resume state file; and `spomp keys generate`.

use std::path::{Path, PathBuf};
use std::process::ExitCode;

use anyhow::Result;
use spomp_behaviors::NodeRegistry;
use spomp_behaviors::mission::{LoadOptions, load_mission_with};
use spomp_core::RobotId;
use spomp_robot::RobotRuntime;
use spomp_zenoh::KeyDir;

// The link itself: a build with the `deploy` feature. Keys are made without it.
#[cfg(feature = "deploy")]
mod plug;
#[cfg(feature = "deploy")]
pub use plug::{plug, set_up};

/// The team-link options of `spomp run`.
#[derive(Debug, Clone, clap::Args)]
pub struct TeamLinkArgs {
    /// The team's key directory (`spomp keys generate`): records and messages are signed and
    /// checked, and the team link admits only the team's robots. Without it the team link runs
    /// unauthenticated (a warning says so).
    #[arg(long, value_name = "DIR")]
    pub keys: Option<PathBuf>,
    /// A team-link endpoint to listen on, `tcp/HOST:PORT` (repeatable; default: the robot's
    /// `team_link.listen`).
    #[arg(long = "listen", value_name = "ENDPOINT")]
    pub listen: Vec<String>,
    /// A teammate's endpoint to connect to, `tcp/HOST:PORT` (repeatable; default: the robot's
    /// `team_link.connect`).
    #[arg(long = "connect", value_name = "ENDPOINT")]
    pub connect: Vec<String>,
    /// Keep the robot's team state (and its role's `persist` entries) in this file, written
    /// atomically every `--state-period-s` and at shutdown; at start the robot resumes from it
    /// if it is there and checks out (a damaged state file is reported and ignored; anything
    /// else at the path — another file, a link, another robot's state — stops the start).
    #[arg(long, value_name = "FILE")]
    pub state_file: Option<PathBuf>,
    /// How often the state file is written, seconds of robot time.
    #[arg(long, default_value_t = 5.0, value_parser = crate::args::period)]
    pub state_period_s: f64,
}

/// `spomp keys generate MISSION --out DIR`.
pub fn generate(mission: &Path, out: &Path, registry: &NodeRegistry<RobotRuntime>) -> Result<ExitCode> {
    let loaded = load_mission_with(mission, registry, &LoadOptions::default());
    if !loaded.is_valid() {
        crate::commands::print_diagnostics(&loaded);
        return Ok(ExitCode::from(1));
    }
    let Some(m) = loaded.mission.as_ref() else { anyhow::bail!("mission did not load") };
    let robots: Vec<RobotId> = m.team.iter().map(|r| RobotId::new(&r.id)).collect();
    match KeyDir::generate(out, &m.mission, &robots) {
        Ok(_) => {
            out!(
                "keys of team `{}` for {} robots and the operator in {}: team.json and transport.passwords go to every robot, <robot>.key.json only to its robot, operator.key.json to the operator (and a robot that serves an operator interface)",
                m.mission,
                robots.len(),
                out.display()
            );
            Ok(ExitCode::SUCCESS)
        }
        Err(e) => {
            errln!("error: {e}");
            Ok(ExitCode::from(1))
        }
    }
}
