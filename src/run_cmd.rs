//! `spomp run`: one robot of a mission, on a real robot (or a simulator farm) over ROS 2.

use std::net::IpAddr;
use std::path::PathBuf;

// The robot over DDS, its team link and live view: a build with the `deploy` feature.
#[cfg(feature = "deploy")]
mod node;
#[cfg(feature = "deploy")]
pub use node::run;

/// Options of `spomp run`.
#[derive(Debug, Clone, clap::Args)]
pub struct RunArgs {
    /// Mission file.
    pub mission: PathBuf,
    /// The robot of the mission's team this process is.
    #[arg(long)]
    pub robot: String,
    /// DDS domain id (default: the robot's `ros2.domain_id`, else `ROS_DOMAIN_ID`, else 0).
    #[arg(long, value_parser = clap::value_parser!(u16).range(0..=232))]
    pub domain_id: Option<u16>,
    /// Only this local address carries DDS discovery (repeatable; e.g. 127.0.0.1). Default:
    /// the robot's `ros2.interfaces`, or every interface.
    #[arg(long = "interface", value_name = "IP")]
    pub interfaces: Vec<IpAddr>,
    /// Take time from `/clock` (a simulator's), whatever the mission says.
    #[arg(long)]
    pub use_sim_time: bool,
    /// ROS 2 arguments, as `ros2 run` and launch files pass them, up to `--` or the end:
    /// `-p use_sim_time:=true` and `--params-file FILE` (its `use_sim_time`). Anything else is
    /// refused: the robot's other settings are in the mission's `ros2:` section.
    #[arg(long = "ros-args", value_name = "ARG", num_args = 0.., allow_hyphen_values = true,
          value_terminator = "--", action = clap::ArgAction::Append)]
    pub ros_args: Vec<String>,
    /// Follow a `spomp sim --ros2 --lockstep` farm: take each step's inputs from it, tick, and
    /// answer, so the farm's time advances only when this robot is done (implies
    /// --use-sim-time; the robot's --seed must be the farm's).
    #[arg(long)]
    pub lockstep: bool,
    /// With --lockstep: give the farm up for gone when it sends nothing for this long once it
    /// has started, wall seconds.
    #[arg(long, default_value_t = 120.0, value_parser = crate::args::wall_seconds, requires = "lockstep")]
    pub lockstep_timeout_s: f64,
    /// Record every input and output to this MCAP log (the channels of `spomp sim`'s logs).
    #[arg(long, value_name = "LOG.mcap")]
    pub record: Option<PathBuf>,
    /// Seed of the robot's random stream (default: the mission's `sim.seed`, else 1 — the
    /// simulator's, so a farm run and a simulated run start alike).
    #[arg(long)]
    pub seed: Option<u64>,
    /// Stop after this much robot time, seconds (default: run until SIGINT/SIGTERM).
    #[arg(long, value_parser = crate::args::time_limit, allow_hyphen_values = true)]
    pub until_s: Option<f64>,
    /// Print the run's figures as JSON at the end.
    #[arg(long)]
    pub json: bool,
    /// Print the topic table and exit.
    #[arg(long)]
    pub topics: bool,
    /// Serve the robot live over the Foxglove WebSocket protocol (open ws://ADDR in Foxglove;
    /// see docs/live.md): the channels `--record` writes. ADDR: HOST:PORT, default
    /// 127.0.0.1:8765; bind another address only when asked.
    #[arg(long, value_name = "ADDR", num_args = 0..=1, default_missing_value = "127.0.0.1:8765")]
    pub live: Option<std::net::SocketAddr>,
    /// With --live: take points a viewer publishes (Foxglove's 3-D panel "Publish point",
    /// display frame `map`) as the operator's "add goal" commands, signed with the operator's
    /// key — which --keys must hold (operator.key.json). See docs/operators.md.
    #[arg(long, requires = "live")]
    pub live_operator: bool,
    /// Take rviz's "Publish Point" clicks (`geometry_msgs/PointStamped` in the map frame on
    /// TOPIC, default `/clicked_point`) as the operator's "add goal" commands, signed with the
    /// operator's key — which --keys must hold (operator.key.json). See docs/operators.md.
    #[arg(long, value_name = "TOPIC", num_args = 0..=1, default_missing_value = "/clicked_point")]
    pub clicked_point: Option<String>,
    /// A folder besides the mission's own that its includes, plan files and world may be in
    /// (repeatable).
    #[arg(long = "allow-dir", value_name = "DIR")]
    pub allow_dirs: Vec<PathBuf>,
    /// Resolve the mission's relative paths (includes, plan files, world folder) as if the
    /// file were in DIR, not in its own folder: how `spomp experiment --deployed` runs a
    /// configuration's patched mission, written to the trial's folder.
    #[arg(long, value_name = "DIR")]
    pub resolve_in: Option<PathBuf>,
    /// The team link between robot processes, the team's keys, the state file.
    #[command(flatten)]
    pub team_link: crate::team_link::TeamLinkArgs,
}

/// Runs `spomp run`: in a build without the `deploy` feature, the note of how to get it.
#[cfg(not(feature = "deploy"))]
pub fn run(
    _args: &RunArgs,
    _registry: &spomp_behaviors::NodeRegistry<spomp_robot::RobotRuntime>,
) -> anyhow::Result<std::process::ExitCode> {
    crate::deploy::not_built("spomp run")
}
