//! The command line: argument parsing and dispatch to the subcommands, over a node registry
//! that a lab's binary may extend ([`main_with`]).

use std::ffi::OsString;
use std::path::PathBuf;
use std::process::ExitCode;

use clap::{Parser, Subcommand, ValueEnum};
use spomp_behaviors::NodeRegistry;
use spomp_core::panorama::DEFAULT_RANGE_SCALE_M;
use spomp_core::{Point2, Pose2};
use spomp_robot::RobotRuntime;

use crate::{
    args, commands, experiment, log_cmd, memory_stage, operator_cmd, plan_cmd, replay_cmd, run_cmd, sim_cmd,
    terrain_cmd, world_cmd, world_import,
};

/// Mission framework for air–ground robot teams.
#[derive(Parser, Debug)]
#[command(name = "spomp", version = crate::deploy::VERSION, about, long_about = None)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

/// `spomp keys` subcommands.
#[derive(Subcommand, Debug)]
enum KeysCommand {
    /// One Ed25519 key pair and transport password per robot of the mission, the team's public
    /// keys and password dictionary, in a new folder (see docs/robots.md, "Team link").
    Generate {
        /// Mission file.
        mission: PathBuf,
        /// The folder to write (must not hold keys already).
        #[arg(long)]
        out: PathBuf,
    },
}

#[derive(Subcommand, Debug)]
enum Command {
    /// Check mission files: parse → schema → wiring → team → world (for a mission naming a world
    /// folder). Exit 0 only when all are valid; warnings do not fail.
    Validate {
        /// Mission files.
        #[arg(required = true)]
        files: Vec<PathBuf>,
        /// Print the diagnostics as a JSON array of {file, line, column, node_path, stage, message,
        /// severity}
        /// (with --dry-run: {diagnostics, dry_runs}).
        #[arg(long)]
        json: bool,
        /// Also run each valid mission once in the simulator (its world, or a generated city):
        /// does it end within its time limit, which nodes were ticked, the outcome.
        #[arg(long)]
        dry_run: bool,
        /// With --dry-run: simulate at most this many seconds (default: the mission's time limit).
        #[arg(long, value_parser = args::time_limit, requires = "dry_run", allow_hyphen_values = true)]
        time_limit_s: Option<f64>,
        /// With --dry-run: stop a dry run after this many wall-clock seconds (it then fails,
        /// outcome `interrupted`).
        #[arg(long, value_parser = args::wall_seconds, default_value_t = 300.0, requires = "dry_run")]
        max_wall_s: f64,
        /// A folder besides the mission's own that its includes, plan files and world may be in
        /// (repeatable).
        #[arg(long = "allow-dir", value_name = "DIR")]
        allow_dirs: Vec<PathBuf>,
        /// Hold the memory estimate of a simulated run against this many megabytes instead of
        /// the memory this machine has available (`MemAvailable`).
        #[arg(long, value_name = "MB", value_parser = args::memory_mb)]
        memory_budget_mb: Option<f64>,
        /// Skip the memory stage (a team estimated not to fit this machine is otherwise an
        /// error).
        #[arg(long, conflicts_with = "memory_budget_mb")]
        ignore_memory: bool,
    },
    /// Run a mission in the built-in simulator: summary table, `summary.json`, `run.mcap` and
    /// plots per trial under the output folder.
    Sim(sim_cmd::SimArgs),
    /// Run one robot of a mission over ROS 2: on a real robot, or driving a robot of
    /// `spomp sim --ros2`.
    Run(run_cmd::RunArgs),
    /// Act as the team's operator during a mission, over the signed team link: add, cancel and
    /// re-prioritise goals, recall, hold and resume robots, see the team's status (exit 0 when
    /// every robot reached acknowledged the command, 2 when not, 1 on an error; see
    /// docs/operators.md).
    Operator(operator_cmd::OperatorArgs),
    /// Make the team's keys: `spomp keys generate MISSION --out DIR`.
    Keys {
        #[command(subcommand)]
        action: KeysCommand,
    },
    /// Replay one robot of a log: a fresh robot fed the recorded inputs, its commands, node
    /// transitions and team messages compared with the recorded ones (exit 0 identical, 1 at the
    /// first divergence, 2 when the log cannot be replayed).
    Replay(replay_cmd::ReplayArgs),
    /// Run an experiment file's trials (configurations × seeds) in the simulator, one row per
    /// trial in OUT/trials.{jsonl,csv}; `report` merges output folders (shards) into report.md
    /// and plots. See docs/experiments.md.
    Experiment(experiment::ExperimentArgs),
    /// Print the JSON Schema of the mission language (for editors' YAML language servers).
    Schema,
    /// List the node types with their ports.
    Nodes {
        /// Print the node manifest as JSON.
        #[arg(long)]
        json: bool,
        /// Print the node reference as Markdown (docs/nodes.md is generated with it).
        #[arg(long, conflicts_with = "json")]
        markdown: bool,
        /// Show one node type only.
        name: Option<String>,
    },
    /// Generate, inspect and render simulator worlds.
    World {
        #[command(subcommand)]
        action: WorldCommand,
    },
    /// Run terrain analysis on a depth panorama (16-bit PNG of range counts), timing the robot's
    /// fused analysis and each stage.
    Terrain {
        /// Depth panorama: 16-bit grayscale PNG, rows = elevation (row 0 looks up), 0 = no return.
        pano: PathBuf,
        /// Metres per count.
        #[arg(long = "range-scale", default_value_t = DEFAULT_RANGE_SCALE_M)]
        range_scale_m: f64,
        /// Vertical field of view of the panorama, degrees.
        #[arg(long, default_value_t = 90.0)]
        v_fov_deg: f64,
        /// YAML file of terrain parameters (unknown keys rejected, missing keys default).
        #[arg(long)]
        params: Option<PathBuf>,
        /// Start from the paper's simulation values (slope 0.25, inflation 0.75 m).
        #[arg(long, conflicts_with = "params")]
        simulation: bool,
        /// Timed runs, after one untimed warm-up; the timings are medians over them.
        #[arg(long, default_value_t = 100)]
        repeat: usize,
        /// Folder for the stage images.
        #[arg(long)]
        out: Option<PathBuf>,
        /// Print {rows, cols, total_ms, total_min_ms, staged_total_ms, timings_ms, reachability,
        /// traversable_pixels} as JSON.
        #[arg(long)]
        json: bool,
    },
    /// Check or recover an MCAP log (e.g. one a crash or a kill cut short).
    Log {
        #[command(subcommand)]
        action: LogCommand,
    },
    /// Build the global planner's graph on a world's map and plan on it.
    Plan {
        /// World folder.
        dir: PathBuf,
        /// Start X,Y (metres, map frame).
        #[arg(long, value_parser = args::point, allow_hyphen_values = true, requires = "to", required_unless_present = "random_pairs")]
        from: Option<Point2>,
        /// Goal X,Y (metres, map frame).
        #[arg(long, value_parser = args::point, allow_hyphen_values = true, requires = "from")]
        to: Option<Point2>,
        /// Plan between N random pairs of cells on the easiest classes instead of --from/--to.
        #[arg(long, conflicts_with_all = ["from", "to"])]
        random_pairs: Option<usize>,
        /// Seed of the random pairs.
        #[arg(long, default_value_t = 0)]
        seed: u64,
        /// Hardest class rank a random start or goal may stand on (0 road, 1 gravel, ...).
        #[arg(long, default_value_t = 1)]
        pair_max_rank: u8,
        /// Learned traversability cost (on) or the class-rank ablation (off).
        #[arg(long, value_enum)]
        learning: Option<OnOff>,
        /// YAML file of global planner parameters.
        #[arg(long)]
        params: Option<PathBuf>,
        /// Folder for plan.png (map, graph edges, path).
        #[arg(long)]
        out: Option<PathBuf>,
        /// Print JSON.
        #[arg(long)]
        json: bool,
    },
}

/// `on` / `off`.
#[derive(Clone, Copy, Debug, ValueEnum)]
enum OnOff {
    On,
    Off,
}

#[derive(Subcommand, Debug)]
enum LogCommand {
    /// Read a log to its end, or to its last whole chunk if it was cut short: exit 0 when
    /// everything there reads, 1 when a record is corrupt or the file is no MCAP log.
    Check {
        /// The log.
        log: PathBuf,
        /// Print {file, closed, chunks, messages, topics, readable_bytes, lost_bytes, corrupt} as JSON.
        #[arg(long)]
        json: bool,
    },
    /// Write the readable messages of a log as a closed, indexed MCAP file.
    Recover {
        /// The log.
        log: PathBuf,
        /// The recovered log.
        #[arg(long)]
        out: PathBuf,
        /// Print JSON.
        #[arg(long)]
        json: bool,
    },
}

#[derive(Subcommand, Debug)]
enum WorldCommand {
    /// Generate a procedural city and write it as a world folder.
    Generate {
        /// City seed.
        #[arg(long)]
        seed: u64,
        /// World extent W,H in metres (default 400,300).
        #[arg(long, value_parser = args::size)]
        size_m: Option<(f64, f64)>,
        /// Vehicle clusters (default 15).
        #[arg(long)]
        clusters: Option<usize>,
        /// Roadblocks (default 6).
        #[arg(long)]
        roadblocks: Option<usize>,
        /// Output world folder.
        #[arg(long)]
        out: PathBuf,
        /// Print JSON.
        #[arg(long)]
        json: bool,
    },
    /// Load a world folder, print what it holds and write its top-down render.
    Show {
        /// World folder.
        dir: PathBuf,
        /// Output PNG (default DIR/render.png).
        #[arg(long)]
        out: Option<PathBuf>,
        /// Print JSON.
        #[arg(long)]
        json: bool,
    },
    /// Import a colour-coded semantic raster (an aerial survey's class map, PNG) as a world
    /// folder: class layer, elevation from the classes, start poses (see docs/missions.md).
    Import {
        /// The class raster (PNG; row 0 is the northern edge).
        raster: PathBuf,
        /// Class table YAML: `classes: [{index, name, rank, color: [R, G, B], height_m?}, …]`.
        #[arg(long)]
        classes: PathBuf,
        /// Metres per pixel.
        #[arg(long, required_unless_present = "pixels_per_m", conflicts_with = "pixels_per_m")]
        resolution_m: Option<f64>,
        /// Pixels per metre (instead of --resolution-m).
        #[arg(long)]
        pixels_per_m: Option<f64>,
        /// Cell size of the world, metres (default: one cell per pixel); each cell takes the
        /// most common class of its pixels.
        #[arg(long)]
        cell_m: Option<f64>,
        /// WGS-84 LAT,LON of the raster's north-west (top-left) corner, degrees.
        #[arg(long, value_parser = args::lat_lon, allow_hyphen_values = true)]
        gps_reference: Option<(f64, f64)>,
        /// Largest RGB distance (0–441) at which a colour counts as its class's; farther colours
        /// are snapped to the nearest class and their share reported.
        #[arg(long, default_value_t = world_import::DEFAULT_COLOUR_TOLERANCE)]
        colour_tolerance: f64,
        /// Place start poses nearest this X,Y (metres, map frame; default: the south-west corner).
        #[arg(long, value_parser = args::point, allow_hyphen_values = true)]
        start_near: Option<Point2>,
        /// Number of start poses.
        #[arg(long, default_value_t = 4)]
        starts: usize,
        /// The class whose clusters are the world's vehicle clusters (the goals a detection
        /// mission finds), as the table names it: a site's table may call it `car`.
        #[arg(long, default_value = "vehicle", value_name = "NAME")]
        vehicle_class: String,
        /// Curb cuts (ramps) this far apart along every curb, metres; 0: none, a curb stands
        /// wherever a raised class meets a lower one.
        #[arg(long, default_value_t = world_import::DEFAULT_RAMP_SPACING_M, value_name = "M")]
        ramp_spacing_m: f64,
        /// Import even if the resolution looks implausible or most colours match no class.
        #[arg(long)]
        force: bool,
        /// Output world folder.
        #[arg(long)]
        out: PathBuf,
        /// Print JSON.
        #[arg(long)]
        json: bool,
    },
    /// Render the depth panorama seen from a pose as a 16-bit PNG of range counts.
    Pano {
        /// World folder.
        dir: PathBuf,
        /// Sensor pose X,Y,YAW (metres, radians, map frame).
        #[arg(long, value_parser = args::pose, allow_hyphen_values = true)]
        at: Pose2,
        /// Rows (default 256).
        #[arg(long)]
        rows: Option<usize>,
        /// Columns (default 1024).
        #[arg(long)]
        cols: Option<usize>,
        /// Vertical field of view, degrees (default 90).
        #[arg(long)]
        v_fov_deg: Option<f64>,
        /// Sensor height above the ground, metres (default 0.4).
        #[arg(long)]
        sensor_height_m: Option<f64>,
        /// Longest range, metres (default 50).
        #[arg(long)]
        max_range_m: Option<f64>,
        /// Metres per count.
        #[arg(long = "range-scale", default_value_t = DEFAULT_RANGE_SCALE_M)]
        range_scale_m: f64,
        /// Output PNG.
        #[arg(long)]
        out: PathBuf,
        /// Print JSON.
        #[arg(long)]
        json: bool,
    },
}

fn run_world(action: WorldCommand) -> anyhow::Result<ExitCode> {
    match action {
        WorldCommand::Generate { seed, size_m, clusters, roadblocks, out, json } => {
            world_cmd::generate(&world_cmd::GenerateArgs { seed, size_m, clusters, roadblocks, out, json })
        }
        WorldCommand::Show { dir, out, json } => world_cmd::show(&dir, out.as_deref(), json),
        WorldCommand::Import {
            raster,
            classes,
            resolution_m,
            pixels_per_m,
            cell_m,
            gps_reference,
            colour_tolerance,
            start_near,
            starts,
            vehicle_class,
            ramp_spacing_m,
            force,
            out,
            json,
        } => {
            let scale = match (resolution_m, pixels_per_m) {
                (Some(m), _) => world_import::Scale::MetresPerPixel(m),
                (None, Some(p)) => world_import::Scale::PixelsPerMetre(p),
                (None, None) => anyhow::bail!("give --resolution-m or --pixels-per-m"),
            };
            world_import::import(&world_import::ImportArgs {
                raster,
                classes,
                scale,
                cell_m,
                gps_reference,
                colour_tolerance,
                start_near,
                starts,
                vehicle_class,
                ramp_spacing_m,
                force,
                out,
                json,
            })
        }
        WorldCommand::Pano {
            dir,
            at,
            rows,
            cols,
            v_fov_deg,
            sensor_height_m,
            max_range_m,
            range_scale_m,
            out,
            json,
        } => {
            let mut sensor = spomp_sim::SensorParams::default();
            sensor.rows = rows.unwrap_or(sensor.rows);
            sensor.cols = cols.unwrap_or(sensor.cols);
            sensor.v_fov_deg = v_fov_deg.unwrap_or(sensor.v_fov_deg);
            sensor.sensor_height_m = sensor_height_m.unwrap_or(sensor.sensor_height_m);
            sensor.max_range_m = max_range_m.unwrap_or(sensor.max_range_m);
            world_cmd::pano(&world_cmd::PanoArgs { dir, at, sensor, range_scale_m, out, json })
        }
    }
}

/// Runs the `spomp` command line with the built-in node types and mission sections (`spomp::registry()`).
pub fn main() -> ExitCode {
    main_with(crate::registry())
}

/// Runs the `spomp` command line on the process's arguments with `registry`: a lab's binary
/// adds its node types to `spomp::registry()` and calls this from its `main`.
pub fn main_with(registry: NodeRegistry<RobotRuntime>) -> ExitCode {
    run_with(std::env::args_os(), &registry)
}

/// Runs the `spomp` command line on `args` (the first is the program name) with `registry`,
/// and returns the process's exit code: 0 success, 1 failure (an invalid mission, a failed
/// run), 2 a usage error.
pub fn run_with<I, T>(args: I, registry: &NodeRegistry<RobotRuntime>) -> ExitCode
where
    I: IntoIterator<Item = T>,
    T: Into<OsString> + Clone,
{
    let cli = match Cli::try_parse_from(args) {
        Ok(c) => c,
        Err(e) => {
            // clap prints help and version to stdout with exit 0, usage errors to stderr with 2.
            let _ = e.print();
            return if e.use_stderr() { ExitCode::from(2) } else { ExitCode::SUCCESS };
        }
    };
    let result = match cli.command {
        Command::Validate {
            files,
            json,
            dry_run,
            time_limit_s,
            max_wall_s,
            allow_dirs,
            memory_budget_mb,
            ignore_memory,
        } => {
            let dry_run = dry_run.then_some(sim_cmd::DryRunLimits { time_limit_s, max_wall_s });
            let options = spomp_behaviors::mission::LoadOptions { allowed_dirs: allow_dirs };
            let memory = memory_stage::MemoryCheck::from_args(memory_budget_mb, ignore_memory);
            commands::validate(&files, json, dry_run, memory, &options, registry)
        }
        Command::Log { action: LogCommand::Check { log, json } } => log_cmd::check(&log, json),
        Command::Log { action: LogCommand::Recover { log, out, json } } => log_cmd::recover(&log, &out, json),
        Command::Sim(args) => sim_cmd::sim(&args, registry),
        Command::Experiment(args) => experiment::experiment(&args, registry),
        Command::Run(args) => run_cmd::run(&args, registry),
        Command::Operator(args) => operator_cmd::operator(&args, registry),
        Command::Keys { action: KeysCommand::Generate { mission, out } } => {
            crate::team_link::generate(&mission, &out, registry)
        }
        Command::Replay(args) => replay_cmd::replay(&args, registry),
        Command::Schema => commands::schema(registry),
        Command::Nodes { json, markdown, name } => commands::nodes(json, markdown, name.as_deref(), registry),
        Command::World { action } => run_world(action),
        Command::Terrain { pano, range_scale_m, v_fov_deg, params, simulation, repeat, out, json } => {
            terrain_cmd::terrain(&terrain_cmd::TerrainArgs {
                pano,
                range_scale_m,
                v_fov_deg,
                params,
                simulation,
                repeat,
                out,
                json,
            })
        }
        Command::Plan { dir, from, to, random_pairs, seed, pair_max_rank, learning, params, out, json } => {
            let queries = match (random_pairs, from, to) {
                (Some(count), _, _) => plan_cmd::Queries::RandomPairs { count, seed, max_rank: pair_max_rank },
                (None, Some(from), Some(to)) => plan_cmd::Queries::Single { from, to },
                _ => {
                    errln!("error: give --from and --to, or --random-pairs N");
                    return ExitCode::from(2);
                }
            };
            let learning = learning.map(|l| matches!(l, OnOff::On));
            plan_cmd::plan(&plan_cmd::PlanArgs { dir, queries, learning, params, out, json })
        }
    };
    match result {
        Ok(code) => code,
        Err(e) => {
            errln!("error: {e:#}");
            ExitCode::from(1)
        }
    }
}
