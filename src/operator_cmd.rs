//! `spomp operator`: the team's operator as a short-lived member of the signed team link.
//!
//! It joins the Zenoh team link with the operator's credentials (`operator.key.json` of the
//! team's key folder), syncs with the robots it reaches until it holds what they hold (so its
//! command numbers follow theirs and goal names resolve), writes one command signed with the
//! operator's key, and syncs until every robot it reaches has acknowledged it or `--wait-s`
//! passes; then it says which robots have and which have not. A robot it does not reach applies
//! the command when a teammate that holds it comes into range (the team state relays it).
//!
//! Exit codes: 0 every robot the command concerns that was reachable acknowledged it (and at
//! least one did); 2 the command was written but some reachable robot did not acknowledge it in
//! time, or no robot was reached (then no robot holds it: issue it again); 1 nothing was issued
//! (bad arguments, keys, mission, an unknown goal). `status` exits 0 once it has synced with at
//! least one robot, 2 otherwise.

use std::path::PathBuf;

use spomp_core::Point2;

// The operator's member of the team link: a build with the `deploy` feature.
#[cfg(feature = "deploy")]
mod member;
#[cfg(feature = "deploy")]
pub use member::operator;

/// Options of `spomp operator`.
#[derive(Debug, Clone, clap::Args)]
pub struct OperatorArgs {
    /// Mission file: the team's name, robots and goals, and its team-state parameters (the
    /// deconfliction radius the goals are grouped with), read as the robots read them.
    pub mission: PathBuf,
    /// The team's key folder (`spomp keys generate`); `operator.key.json` must be in it.
    #[arg(long, value_name = "DIR")]
    pub keys: PathBuf,
    /// A robot's team-link endpoint to connect to, `tcp/HOST:PORT` (repeatable; one reachable
    /// robot is enough, Zenoh finds the rest).
    #[arg(long = "connect", value_name = "ENDPOINT", required = true)]
    pub connect: Vec<String>,
    /// How long to wait for the robots, wall seconds: first to sync with every robot reached,
    /// then for their acknowledgements.
    #[arg(long, default_value_t = 10.0, value_parser = crate::args::wall_seconds)]
    pub wait_s: f64,
    /// Print the outcome as JSON.
    #[arg(long)]
    pub json: bool,
    /// What to do.
    #[command(subcommand)]
    pub command: OperatorCommandArg,
}

/// `spomp operator` subcommands.
#[derive(Debug, Clone, clap::Subcommand)]
pub enum OperatorCommandArg {
    /// Goals: add, cancel, re-prioritise.
    Goal {
        /// What to do with goals.
        #[command(subcommand)]
        action: GoalArg,
    },
    /// Send a robot (or `all`) home, to stay there until resumed.
    Recall {
        /// A robot id, or `all`.
        target: String,
    },
    /// Stop a robot (or `all`) where it is until resumed.
    Hold {
        /// A robot id, or `all`.
        target: String,
    },
    /// Lift a hold or a recall: back to the mission.
    Resume {
        /// A robot id, or `all`.
        target: String,
    },
    /// The team as the robots reached see it: goals, claims, visits, robots last heard,
    /// operator commands and their acknowledgements.
    Status,
}

/// `spomp operator … goal` subcommands.
#[derive(Debug, Clone, clap::Subcommand)]
pub enum GoalArg {
    /// Add a goal at a map-frame position.
    Add {
        /// Where: `X,Y` in metres, map frame.
        #[arg(long, value_parser = crate::args::point, allow_hyphen_values = true)]
        at: Point2,
        /// A name to address it by (goal cancel/priority NAME).
        #[arg(long)]
        name: Option<String>,
        /// Its priority: 0 ordinary, higher more urgent (robots take the most urgent first).
        #[arg(long, default_value_t = 0, allow_hyphen_values = true)]
        priority: i32,
        /// What is there (a detector class name), for the log.
        #[arg(long)]
        class: Option<String>,
    },
    /// Cancel a goal (by its name or id, e.g. `mission/0`, `operator/1700000000`): robots drop a
    /// claim on it and never claim it again.
    Cancel {
        /// The goal's name or id.
        goal: String,
    },
    /// Change a goal's priority.
    Priority {
        /// The goal's name or id.
        goal: String,
        /// The new priority: 0 ordinary, higher more urgent.
        #[arg(allow_hyphen_values = true)]
        priority: i32,
    },
}

/// Runs `spomp operator`: in a build without the `deploy` feature, the note of how to get it.
#[cfg(not(feature = "deploy"))]
pub fn operator(
    _args: &OperatorArgs,
    _registry: &spomp_behaviors::NodeRegistry<spomp_robot::RobotRuntime>,
) -> anyhow::Result<std::process::ExitCode> {
    crate::deploy::not_built("spomp operator")
}
