//! `spomp` as a library: the command-line tool's entry points, so that a lab's own binary is one
//! `main` that adds its node types to the registry and runs the same CLI.
//!
//! ```no_run
//! use std::process::ExitCode;
//!
//! fn main() -> ExitCode {
//!     let mut registry = spomp::registry();
//!     // registry.try_register(my_node_type()) …
//!     spomp::cli::main_with(registry)
//! }
//! ```
//!
//! `validate`, `sim`, `run`, `nodes` and `schema` then see the added node types (the JSON Schema and
//! the node reference include them), and the mission sections of the adapters this binary links
//! (see [`register_sections`]). See `examples/custom-node/`.
//!
//! Features: the default build is the simulator and its tools; `deploy` adds what robots run —
//! `spomp run` over ROS 2, the Zenoh team link, `spomp operator`, the live view, the ROS 2 robot
//! farm and deployed experiment trials. A lab's binary for robots asks for `deploy`.

/// `println!` that stops quietly when stdout is closed (e.g. piped into `head`) instead of
/// panicking.
macro_rules! out {
    ($($arg:tt)*) => {{
        use std::io::Write as _;
        let _ = writeln!(std::io::stdout().lock(), $($arg)*);
    }};
}

/// `eprintln!` that never panics: a message to a closed or failing stderr (a closed pipe, a full
/// disk) is dropped, and the command still ends with its own exit code.
macro_rules! errln {
    ($($arg:tt)*) => {{
        use std::io::Write as _;
        let _ = writeln!(std::io::stderr().lock(), $($arg)*);
    }};
}

mod args;
pub mod cli;
mod commands;
mod deploy;
pub mod experiment;
#[cfg(feature = "deploy")]
mod farm_cmd;
mod live;
mod log_cmd;
mod memory_stage;
mod operator_cmd;
#[cfg(feature = "deploy")]
mod operator_desk;
mod output;
mod plan_cmd;
mod recording;
mod replay_cmd;
#[cfg(feature = "deploy")]
mod ros_args;
mod run_cmd;
mod sim_cmd;
mod sim_plots;
mod team_link;
mod terrain_cmd;
mod world_cmd;
mod world_import;
mod world_stage;

pub use spomp_behaviors::NodeRegistry;
pub use spomp_robot::RobotRuntime;

/// The node registry the CLI loads missions with: the engine's node types, the robot layer's
/// domain nodes and the owners of every mission section ([`register_sections`]); add a lab's own
/// types to it and hand it to [`cli::main_with`].
pub fn registry() -> NodeRegistry<RobotRuntime> {
    let mut r = spomp_robot::registry();
    register_sections(&mut r);
    r
}

/// Registers the owners of the adapter sections of a mission this binary can run, as it
/// registers node types: `sim:` (the world model, `spomp-world`), a robot's `ros2:`
/// (`spomp-ros2`) and `team_link:` (`spomp-zenoh`); `comms:` comes with the robot layer's
/// registry. Each owner gives the section's JSON Schema, defaults and checks.
pub fn register_sections(r: &mut NodeRegistry<RobotRuntime>) {
    use spomp_behaviors::mission::owner;
    r.register_section(owner::<spomp_world::SimSpec>());
    r.register_section(owner::<spomp_ros2::Ros2Spec>());
    r.register_section(owner::<spomp_zenoh::TeamLinkSpec>());
}
