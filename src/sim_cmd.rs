//! `spomp sim` and `spomp validate --dry-run`: run a mission in the built-in simulator, trials
//! in parallel, each recorded to MCAP with a summary and plots.

use std::io::{Seek, Write};
use std::net::SocketAddr;
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;

use anyhow::{Context, Result, bail};
use indicatif::{MultiProgress, ProgressBar, ProgressDrawTarget, ProgressStyle};
use rayon::prelude::*;
use serde::Serialize;
use spomp_behaviors::NodeRegistry;
use spomp_behaviors::mission::{LoadOptions, LoadedMission, MissionSection, load_mission_with};
use spomp_core::RobotId;
use spomp_mcap::{Recorder, RecorderOptions, SafeFile};
use spomp_robot::RobotRuntime;
use spomp_sim::run::{RunResult, RunSummary, SimOptions, Simulation};
use spomp_sim::{Blackout, Faults, KillFault};

use crate::recording::{LogObserver, ObserverSettings};

use crate::live::{Discard, LiveTap};
use crate::sim_plots;

/// Options of `spomp sim` (the command line's arguments).
#[derive(Debug, Clone, clap::Args)]
pub struct SimArgs {
    /// Mission file.
    pub mission: PathBuf,
    /// First seed (default: the mission's `sim.seed`, else 1); trial k uses seed + k.
    #[arg(long)]
    pub seed: Option<u64>,
    /// Trials, run in parallel on all cores (default: the mission's `sim.trials`, else 1).
    #[arg(long, value_parser = clap::value_parser!(u32).range(1..))]
    pub trials: Option<u32>,
    /// Output folder (default `runs/<mission>/`). Trial folders a previous run left there are
    /// replaced; a folder holding files `spomp sim` does not write is refused.
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Run even when the outputs are estimated to need more than 20 GB of disk, or the trials
    /// run side by side more memory than this machine has available.
    #[arg(long)]
    pub force: bool,
    /// Print the combined summary as JSON.
    #[arg(long)]
    pub json: bool,
    /// Override the mission's time limit, seconds (the rule of `time_limit_s`: positive, at most
    /// 604800).
    #[arg(long, value_parser = crate::args::time_limit, allow_hyphen_values = true)]
    pub time_limit_s: Option<f64>,
    /// Record a (downsampled) panorama per UGV every this many seconds in the MCAP (0: none).
    #[arg(long, default_value_t = 10.0, value_parser = crate::args::period, allow_hyphen_values = true)]
    pub pano_every_s: f64,
    /// Also save the recorded panoramas as 16-bit depth PNGs (the `spomp terrain` format).
    #[arg(long)]
    pub save_panos: bool,
    /// Do not write run.mcap.
    #[arg(long)]
    pub no_mcap: bool,
    /// Also record what `spomp replay` needs in run.mcap: the run's setup (mission files, seeds,
    /// operating area) and every call on each robot's seam (`/R/seam`: full-resolution
    /// panoramas, team-state bytes per link, ticks). See docs/replay.md for the size it costs.
    #[arg(long, conflicts_with = "no_mcap")]
    pub replayable: bool,
    /// Run the robots' heavy skills (panorama processing, global-planner upkeep) in the
    /// background as `spomp run` does, with this modelled compute time: `typical` (0.05 s per
    /// panorama, 0.8 s per planner job) or PERCEPTION_S,PLANNER_S. Deterministic; the default
    /// runs them inline, within the step.
    #[arg(long, value_parser = crate::args::skill_latency)]
    pub skill_latency: Option<spomp_sim::run::SkillLatency>,
    /// Kill a robot: ROBOT@SECONDS (repeatable).
    #[arg(long, value_parser = crate::args::kill)]
    pub kill: Vec<(String, f64)>,
    /// Radio blackout for everyone: FROM..TO seconds (repeatable).
    #[arg(long, value_parser = crate::args::window)]
    pub blackout: Vec<(f64, f64)>,
    /// Multiply the odometry noise (0 to 100).
    #[arg(long, value_parser = crate::args::scale, allow_hyphen_values = true)]
    pub odometry_noise: Option<f64>,
    /// Multiply the ground-truth localization noise (0 to 100).
    #[arg(long, value_parser = crate::args::scale, allow_hyphen_values = true)]
    pub localization_noise: Option<f64>,
    /// Print every node transition.
    #[arg(long)]
    pub trace: bool,
    /// A folder besides the mission's own that its includes, plan files and world may be in
    /// (repeatable).
    #[arg(long = "allow-dir", value_name = "DIR")]
    pub allow_dirs: Vec<PathBuf>,
    /// Run as a ROS 2 robot farm: publish the robots' sensors and `/clock` and take their
    /// commands from `spomp run --use-sim-time` processes (one per robot that has one; the
    /// simulator runs the others) instead of ticking their trees.
    #[arg(long)]
    pub ros2: bool,
    /// With --ros2: run in lockstep with the robots' processes (`spomp run --lockstep`): each step
    /// waits for every driven robot's answer, so the run does not depend on the machine's load,
    /// and it is the run `spomp sim` makes with the same seed and --skill-latency. As fast as the
    /// robots answer unless --rate is given.
    #[arg(long, requires = "ros2")]
    pub lockstep: bool,
    /// With --lockstep: a robot that does not answer a call within this long is reported and
    /// dropped (its body stops), wall seconds.
    #[arg(long, default_value_t = 30.0, value_parser = crate::args::wall_seconds, requires = "lockstep")]
    pub lockstep_timeout_s: f64,
    /// Serve the run live over the Foxglove WebSocket protocol (open ws://ADDR in Foxglove; see
    /// docs/live.md), paced at real time × --rate. ADDR: HOST:PORT, default 127.0.0.1:8765
    /// (port 0: any free port). Give it after the mission. One trial.
    #[arg(long, value_name = "ADDR", num_args = 0..=1, default_missing_value = "127.0.0.1:8765", value_parser = live_addr)]
    pub live: Option<SocketAddr>,
    /// With --ros2 or --live: simulated seconds per wall second (default 1).
    #[arg(long, value_parser = crate::args::rate)]
    pub rate: Option<f64>,
    /// With --ros2: the DDS domain (default: the driven robots' `ros2.domain_id`).
    #[arg(long, value_parser = clap::value_parser!(u16).range(0..=232), requires = "ros2")]
    pub domain_id: Option<u16>,
    /// With --ros2: only this local address carries DDS discovery (repeatable).
    #[arg(long = "interface", value_name = "IP", requires = "ros2")]
    pub interfaces: Vec<std::net::IpAddr>,
    /// With --ros2: drive only this robot over ROS 2 (repeatable; default every robot whose
    /// process reports within --wait-s).
    #[arg(long, value_name = "ID", requires = "ros2")]
    pub drive: Vec<String>,
    /// With --ros2: wait this long for the `spomp run` processes before the clock starts (it
    /// starts at once when every robot has reported), seconds.
    #[arg(long, default_value_t = 60.0, value_parser = crate::args::wall_seconds, requires = "ros2")]
    pub wait_s: f64,
}

/// The combined summary of all trials.
#[derive(Debug, Serialize)]
pub struct CombinedSummary {
    /// Mission name.
    pub mission: String,
    /// Trials run.
    pub trials: usize,
    /// The run was stopped (Ctrl-C, SIGTERM) before every trial ended: the summaries cover what
    /// ran, and the trials cut short end `interrupted`.
    pub interrupted: bool,
    /// Trials whose mission completed.
    pub completed: usize,
    /// Mean fraction of world clusters visited (generated worlds), else of goals visited.
    pub mean_visited_fraction: f64,
    /// Mean simulated seconds per wall second.
    pub mean_speedup: f64,
    /// Each trial.
    pub runs: Vec<RunSummary>,
}

/// Exit code of a run stopped by Ctrl-C or SIGTERM (128 + SIGINT, as shells report it).
const EXIT_INTERRUPTED: u8 = 130;

/// Disk a run may be estimated to need before it asks for `--force`, bytes.
const DISK_LIMIT_BYTES: f64 = 20e9;

/// MCAP bytes per robot per simulated second with the default recording (measured: 1.9 kB on
/// the first 300 s of `visit-all-vehicle-clusters.yaml`, 5 robots, a fifth of it `/tf`, `/map`,
/// `/goals` and the active paths; tripled for margin), and the plots, CSV and summary of a trial
/// (1.1 MB measured).
const MCAP_BYTES_PER_ROBOT_S: f64 = 6e3;
const TRIAL_FIXED_BYTES: f64 = 2e6;
/// What `--replayable` adds per robot per simulated second (measured: 58 kB on 600 s of
/// `visit-all-vehicle-clusters.yaml`, 5 robots, seed 3; tripled for margin: panoramas of other
/// worlds compress less).
const REPLAYABLE_BYTES_PER_ROBOT_S: f64 = 175e3;

/// A usage error: printed, exit 2.
fn usage(message: String) -> Result<ExitCode> {
    errln!("error: {message}");
    Ok(ExitCode::from(2))
}

/// `spomp sim`.
pub fn sim(args: &SimArgs, registry: &NodeRegistry<RobotRuntime>) -> Result<ExitCode> {
    let options = LoadOptions { allowed_dirs: args.allow_dirs.clone() };
    let loaded = load_mission_with(&args.mission, registry, &options);
    if !loaded.is_valid() {
        crate::commands::print_diagnostics(&loaded);
        return Ok(ExitCode::from(1));
    }
    let Some(mission) = loaded.mission.as_ref() else { bail!("mission did not load") };
    let sim_spec = spomp_world::SimSpec::of_mission(mission)?;
    let first_seed = args.seed.unwrap_or(sim_spec.first_seed());
    let trials = args.trials.or(sim_spec.trials).unwrap_or(spomp_world::SimSpec::DEFAULT_TRIALS).max(1);
    // The same rules as the mission's own fields.
    for (robot, _) in &args.kill {
        if !mission.team.iter().any(|r| &r.id == robot) {
            let ids: Vec<&str> = mission.team.iter().map(|r| r.id.as_str()).collect();
            return usage(format!("--kill {robot}@…: no robot `{robot}` in the team; robots are: {}", ids.join(", ")));
        }
    }
    if args.ros2 && !crate::deploy::BUILT {
        return crate::deploy::not_built("spomp sim --ros2");
    }
    if args.live.is_some() && !crate::deploy::BUILT {
        return crate::deploy::not_built("spomp sim --live");
    }
    if args.ros2 && trials > 1 {
        return usage(format!("--ros2 runs one trial (the robots' processes drive one world); got {trials} trials"));
    }
    if args.live.is_some() && trials > 1 {
        return usage(format!("--live shows one trial; got {trials} trials"));
    }
    if args.rate.is_some() && !args.ros2 && args.live.is_none() {
        return usage(
            "--rate paces a run for --ros2 or --live; without them the simulator runs as fast as it can".into(),
        );
    }
    for robot in &args.drive {
        if !mission.team.iter().any(|r| &r.id == robot) {
            let ids: Vec<&str> = mission.team.iter().map(|r| r.id.as_str()).collect();
            return usage(format!("--drive {robot}: no robot `{robot}` in the team; robots are: {}", ids.join(", ")));
        }
    }
    if first_seed.checked_add(u64::from(trials) - 1).is_none() {
        return usage(format!(
            "--seed {first_seed} with {trials} trials: trial seeds (seed + k) would pass {}",
            u64::MAX
        ));
    }
    let time_limit = args.time_limit_s.unwrap_or(mission.time_limit_s);
    let estimate = disk_estimate(trials, mission.team.len(), time_limit, !args.no_mcap, args.replayable);
    if estimate > DISK_LIMIT_BYTES && !args.force {
        return usage(format!(
            "{trials} trials of {time_limit:.0} s with {} robots would write about {:.0} GB (limit {:.0} GB); \
             give --force to run anyway, or fewer --trials, --no-mcap or a shorter --time-limit-s",
            mission.team.len(),
            estimate / 1e9,
            DISK_LIMIT_BYTES / 1e9
        ));
    }
    if !args.force
        && let Some(budget) = crate::memory_stage::machine_budget()
        && let Ok(mut sizes) = crate::memory_stage::sizes_of(mission, &loaded.base_dir())
    {
        sizes.duration_s = time_limit;
        let side_by_side = std::thread::available_parallelism().map_or(1, |n| n.get()).min(trials as usize);
        if let Err(message) = crate::memory_stage::judge(&sizes, side_by_side, &budget) {
            return usage(format!("{message}; give --force to run anyway"));
        }
    }
    let out_dir = args.out.clone().unwrap_or_else(|| PathBuf::from("runs").join(&mission.mission));
    if let Err(message) = clean_previous_outputs(&out_dir) {
        return usage(message);
    }
    std::fs::create_dir_all(&out_dir).with_context(|| format!("creating {}", out_dir.display()))?;
    let faults = cli_faults(args);
    let interrupted = stop_on_signals()?;

    let progress = MultiProgress::with_draw_target(if args.json || args.trace {
        ProgressDrawTarget::hidden()
    } else {
        ProgressDrawTarget::stderr()
    });
    let overall = (trials > 1).then(|| {
        let bar = progress.add(ProgressBar::new(u64::from(trials)));
        bar.set_style(
            ProgressStyle::with_template("trials {bar:30} {pos}/{len} [{elapsed_precise}]")
                .unwrap_or_else(|_| ProgressStyle::default_bar()),
        );
        bar
    });
    let seeds: Vec<u64> = (0..u64::from(trials)).map(|k| first_seed + k).collect();
    let parallel_robots = seeds.len() < rayon::current_num_threads();
    let results: Vec<Option<Result<RunSummary>>> = seeds
        .par_iter()
        .map(|&seed| {
            if interrupted.load(Ordering::Relaxed) {
                return None; // not started: nothing to summarise
            }
            let bar = progress.add(ProgressBar::new(time_limit.ceil().max(1.0) as u64));
            bar.set_style(
                ProgressStyle::with_template("seed {prefix:>3} {bar:30} {pos}/{len} s simulated {msg}")
                    .unwrap_or_else(|_| ProgressStyle::default_bar()),
            );
            bar.set_prefix(seed.to_string());
            let inputs = Loaded { mission: &loaded, registry, parallel_robots };
            let r = run_trial(inputs, seed, args, &faults, &out_dir, &bar, &interrupted);
            bar.finish_and_clear();
            progress.remove(&bar);
            if let Some(o) = &overall {
                o.inc(1);
            }
            Some(r)
        })
        .collect();
    if let Some(o) = overall {
        o.finish_and_clear();
    }
    let mut runs = Vec::new();
    for r in results.into_iter().flatten() {
        runs.push(r?);
    }
    let was_interrupted = interrupted.load(Ordering::Relaxed);
    let combined = combine(&mission.mission, runs, was_interrupted);
    let path = out_dir.join("summary.json");
    crate::output::write(&path, serde_json::to_string_pretty(&combined)?)?;
    if args.json {
        out!("{}", serde_json::to_string_pretty(&combined)?);
    } else {
        for run in &combined.runs {
            print_summary(run, &out_dir.join(format!("trial-{}", run.seed)), !args.no_mcap);
        }
        if combined.trials > 1 {
            print_combined(&combined);
        }
        if was_interrupted {
            out!("interrupted: {} of {trials} trials ran (those cut short end `Interrupted`)", combined.trials);
        }
        out!("summary: {}", path.display());
    }
    Ok(if was_interrupted {
        ExitCode::from(EXIT_INTERRUPTED)
    } else if combined.completed == combined.trials {
        ExitCode::SUCCESS
    } else {
        ExitCode::from(1)
    })
}

/// A flag raised by SIGINT or SIGTERM: the trials then finish their current step, close their
/// logs and write their summaries. A second signal of the same kind ends the process at once.
pub(crate) fn stop_on_signals() -> Result<Arc<AtomicBool>> {
    let flag = Arc::new(AtomicBool::new(false));
    for sig in [signal_hook::consts::SIGINT, signal_hook::consts::SIGTERM] {
        // Registered first, so it acts on the second signal only (when the flag is already set).
        signal_hook::flag::register_conditional_shutdown(sig, EXIT_INTERRUPTED.into(), flag.clone())
            .context("installing the signal handlers")?;
        signal_hook::flag::register(sig, flag.clone()).context("installing the signal handlers")?;
    }
    Ok(flag)
}

/// Bytes a run's outputs are expected to take.
fn disk_estimate(trials: u32, robots: usize, time_limit_s: f64, mcap: bool, replayable: bool) -> f64 {
    let per_robot_s = MCAP_BYTES_PER_ROBOT_S + if replayable { REPLAYABLE_BYTES_PER_ROBOT_S } else { 0.0 };
    let per_trial = TRIAL_FIXED_BYTES + if mcap { per_robot_s * robots as f64 * time_limit_s } else { 0.0 };
    f64::from(trials) * per_trial
}

/// What a trial folder holds when `spomp sim` wrote it.
const TRIAL_ENTRIES: &[&str] = &["summary.json", "run.mcap", "plots", "localization_error.csv", "panoramas"];

/// Removes the trial folders a previous run left in `out_dir` (their summary would otherwise sit
/// beside trial folders of another run); refuses when one holds something `spomp sim` does not
/// write, naming it.
fn clean_previous_outputs(out_dir: &Path) -> Result<(), String> {
    let Ok(entries) = std::fs::read_dir(out_dir) else { return Ok(()) };
    let mut stale = Vec::new();
    for e in entries.flatten() {
        let name = e.file_name().to_string_lossy().into_owned();
        let Some(seed) = name.strip_prefix("trial-") else { continue };
        let path = e.path();
        if seed.parse::<u64>().is_err() || !path.is_dir() || path.is_symlink() {
            return Err(format!(
                "{} is not a trial folder spomp sim wrote; choose another --out or move it",
                path.display()
            ));
        }
        let inner = std::fs::read_dir(&path).map_err(|e| format!("{}: {e}", path.display()))?;
        for f in inner.flatten() {
            let n = f.file_name().to_string_lossy().into_owned();
            if !TRIAL_ENTRIES.contains(&n.as_str()) || f.path().is_symlink() {
                return Err(format!(
                    "{} holds {n}, which spomp sim does not write; choose another --out or move it",
                    path.display()
                ));
            }
        }
        stale.push(path);
    }
    for p in stale {
        std::fs::remove_dir_all(&p).map_err(|e| format!("removing the previous run's {}: {e}", p.display()))?;
    }
    Ok(())
}

/// `dir/name` for a file or folder name the run makes up (a trial, a robot's panorama): refused
/// unless `name` is one plain path component, so no output lands outside `dir`.
pub(crate) fn output_path(dir: &Path, name: &str) -> Result<PathBuf> {
    let mut parts = Path::new(name).components();
    match (parts.next(), parts.next()) {
        (Some(std::path::Component::Normal(_)), None) => Ok(dir.join(name)),
        _ => bail!("refusing to write `{name}`: it is not a plain file name inside {}", dir.display()),
    }
}

fn cli_faults(args: &SimArgs) -> Faults {
    let mut f = Faults::default();
    for (robot, at_s) in &args.kill {
        f.kill.push(KillFault { robot: RobotId::new(robot), at_s: *at_s });
    }
    for (from, to) in &args.blackout {
        f.blackouts.push(Blackout { start_s: *from, end_s: *to, region: None });
    }
    if let Some(s) = args.odometry_noise {
        f.odometry_noise_scale = s;
    }
    if let Some(s) = args.localization_noise {
        f.localization_noise_scale = s;
    }
    f
}

/// The loaded mission and the node registry its trees are built with.
struct Loaded<'a> {
    mission: &'a LoadedMission,
    registry: &'a NodeRegistry<RobotRuntime>,
    /// Step each trial's robots in parallel: fewer trials than threads, so threads would idle
    /// otherwise (with more, a waiting step could pick up another whole trial meanwhile).
    parallel_robots: bool,
}

fn run_trial(
    inputs: Loaded<'_>,
    seed: u64,
    args: &SimArgs,
    faults: &Faults,
    out_dir: &Path,
    bar: &ProgressBar,
    interrupted: &AtomicBool,
) -> Result<RunSummary> {
    let Loaded { mission: loaded, registry, parallel_robots } = inputs;
    let Some(mission) = loaded.mission.as_ref() else { bail!("mission did not load") };
    let trial_dir = output_path(out_dir, &format!("trial-{seed}"))?;
    // Serving before the world is built, so a viewer can connect while the run is set up.
    let live = match args.live {
        Some(addr) => {
            let tap = LiveTap::start(addr, &format!("spomp sim {} (seed {seed})", mission.mission))?;
            bar.suspend(|| {
                errln!(
                    "live view: {} (Foxglove: Open connection → Foxglove WebSocket; docs/live.md), {}× real time",
                    tap.url(),
                    args.rate.unwrap_or(1.0)
                );
            });
            Some(tap)
        }
        None => None,
    };
    crate::output::create_dir(&trial_dir)?;
    crate::output::create_dir(&trial_dir.join("plots"))?;
    let world = spomp_world::world_for_mission(mission, &loaded.base_dir(), seed)
        .with_context(|| format!("building the world of `{}`", mission.mission))?;
    let options = SimOptions {
        seed,
        time_limit_s: args.time_limit_s,
        faults: faults.clone(),
        skill_latency: args.skill_latency,
        parallel_robots,
        ..SimOptions::default()
    };
    let run_info = if args.replayable {
        let area = spomp_world::operating_area(mission, &world)?;
        let level = options.map_compression.level;
        let info = spomp_mcap::replay::run_info(loaded, "sim", seed, &area, options.map_publish_period_s, level)?;
        Some(spomp_mcap::RunInfo { background_skills: options.skill_latency.is_some(), ..info })
    } else {
        None
    };
    let mut sim = Simulation::new(loaded, registry, Arc::new(world), options)
        .with_context(|| format!("setting up `{}` (seed {seed})", mission.mission))?;
    #[cfg(feature = "deploy")]
    if args.ros2 {
        let farm = crate::farm_cmd::FarmDrivers::new(
            mission,
            &crate::farm_cmd::FarmOptions {
                rate: args.rate,
                domain_id: args.domain_id,
                interfaces: args.interfaces.clone(),
                drive: args.drive.clone(),
                wait_s: args.wait_s,
                lockstep: args.lockstep.then_some(crate::farm_cmd::LockstepOptions {
                    seed,
                    skill_latency: args.skill_latency,
                    timeout_s: args.lockstep_timeout_s,
                }),
                notes: None,
            },
        )?;
        sim.drive_externally(Box::new(farm)).context("handing the robots to the farm")?;
    }
    if args.live.is_some() && !args.ros2 {
        // The farm paces a --ros2 run itself.
        sim.pace(args.rate.unwrap_or(1.0));
    }
    let mcap_path = trial_dir.join("run.mcap");
    let panos_dir = args.save_panos.then(|| trial_dir.join("panoramas"));
    if let Some(d) = &panos_dir {
        crate::output::create_dir(d)?;
    }
    let settings = ObserverSettings {
        pano_every_ns: (args.pano_every_s * 1e9) as i64,
        panos_dir,
        bar: Some(bar.clone()),
        trace: args.trace,
        replayable: args.replayable,
        classes: Some(sim.world().classes().clone()),
    };
    let stop = &mut || interrupted.load(Ordering::Relaxed);
    let result = match (args.no_mcap, live) {
        (true, None) => run_observed::<SafeFile>(sim, None, settings, stop)?.0,
        (true, Some(tap)) => {
            // Only the live view wants the messages: recorded into nothing, uncompressed.
            let options = RecorderOptions { compress: false, ..RecorderOptions::default() };
            let mut rec = Recorder::new(Discard::default(), options).context("starting the live view's recorder")?;
            set_log_conventions(&mut rec, mission)?;
            rec.set_tap(Box::new(tap));
            run_observed(sim, Some(rec), settings, stop)?.0
        }
        (false, live) => {
            let mut rec = Recorder::create(&mcap_path, RecorderOptions::default())
                .with_context(|| format!("creating {}", mcap_path.display()))?;
            set_log_conventions(&mut rec, mission)?;
            if let Some(info) = &run_info {
                rec.run_info(info).with_context(|| format!("writing the run's setup to {}", mcap_path.display()))?;
            }
            if let Some(tap) = live {
                rec.set_tap(Box::new(tap));
            }
            let (result, rec) = run_observed(sim, Some(rec), settings, stop)
                .with_context(|| format!("recording {}", mcap_path.display()))?;
            if let Some(rec) = rec {
                rec.finish().with_context(|| format!("finishing {}", mcap_path.display()))?;
            }
            result
        }
    };
    write_trial_outputs(&result, &trial_dir)?;
    Ok(result.summary)
}

/// Names and frames each robot's messages as its ROS 2 side would (its `ros2:` settings), so a
/// farm's log and a bag recorded from its DDS topics agree.
fn set_log_conventions<W: Write + Seek>(
    rec: &mut Recorder<W>,
    mission: &spomp_behaviors::mission::MissionFile,
) -> Result<()> {
    for r in &mission.team {
        let ros = spomp_ros2::Ros2Spec::of_robot(r)?;
        let given = spomp_ros2::Ros2Spec::given_for(r).then_some(&ros);
        let topics = spomp_ros2::TopicNames::resolve(&r.id, given);
        let conventions = spomp_mcap::RobotConventions {
            frames: spomp_ros2::frames::resolve(given, &topics),
            cmd_vel_type: ros.cmd_vel_type,
            tf: topics.get("tf").to_string(),
            tf_static: topics.get("tf_static").to_string(),
            depth_encoding: ros.depth_encoding,
            depth_scale_m: ros.depth_scale_m,
            logger: spomp_ros_msgs::rcl_logger_name(topics.namespace(), spomp_ros_msgs::ROBOT_NODE_NAME),
        };
        rec.set_conventions(&r.id, conventions);
    }
    Ok(())
}

fn write_trial_outputs(result: &RunResult, trial_dir: &Path) -> Result<()> {
    let path = trial_dir.join("summary.json");
    crate::output::write(&path, serde_json::to_string_pretty(&result.summary)?)?;
    sim_plots::map_plot(result, &trial_dir.join("plots").join("map.png"))?;
    sim_plots::goal_times_plot(&result.summary, &trial_dir.join("plots").join("goal_visits.png"))?;
    sim_plots::localization_error_plot(result, &trial_dir.join("plots").join("localization_error.png"))?;
    let path = trial_dir.join("localization_error.csv");
    crate::output::write(&path, localization_error_csv(result))?;
    Ok(())
}

/// Each UGV's localization error over time as CSV: `robot,time_s,error_m`, one row per sample
/// (at most one a second per robot).
fn localization_error_csv(result: &RunResult) -> String {
    use std::fmt::Write as _;
    let mut csv = String::from("robot,time_s,error_m\n");
    for (id, series) in &result.localization_errors {
        for (t, e) in series {
            let _ = writeln!(csv, "{id},{t:.1},{e:.3}");
        }
    }
    csv
}

/// Runs `sim` to its end (or until `stop`), recorded by `recorder` if any; returns the result
/// and the recorder, to be finished.
fn run_observed<W: Write + Seek>(
    sim: Simulation,
    recorder: Option<Recorder<W>>,
    settings: ObserverSettings,
    stop: &mut dyn FnMut() -> bool,
) -> Result<(RunResult, Option<Recorder<W>>)> {
    let mut observer = LogObserver::new(recorder, settings);
    let result = sim.run_until(&mut observer, stop);
    let recorder = observer.finish()?;
    Ok((result, recorder))
}

fn combine(mission: &str, runs: Vec<RunSummary>, interrupted: bool) -> CombinedSummary {
    let n = runs.len().max(1) as f64;
    let fraction = |r: &RunSummary| match r.clusters {
        Some(c) if c.total > 0 => c.visited as f64 / c.total as f64,
        _ if !r.goals.is_empty() => r.goals_visited as f64 / r.goals.len() as f64,
        _ => 0.0,
    };
    CombinedSummary {
        mission: mission.to_string(),
        trials: runs.len(),
        interrupted,
        completed: runs.iter().filter(|r| r.outcome.succeeded()).count(),
        mean_visited_fraction: runs.iter().map(fraction).sum::<f64>() / n,
        mean_speedup: runs.iter().map(|r| r.speedup).sum::<f64>() / n,
        runs,
    }
}

fn fmt_time(t: Option<f64>) -> String {
    t.map_or_else(|| "—".to_string(), |s| format!("{s:.0} s"))
}

fn print_summary(run: &RunSummary, trial_dir: &Path, with_mcap: bool) {
    out!("");
    out!(
        "mission `{}`, seed {}: {:?} at {:.0} s of {:.0} s ({:.0}× real time, {:.1} s wall)",
        run.mission,
        run.seed,
        run.outcome,
        run.end_s,
        run.time_limit_s,
        run.speedup,
        run.wall_s
    );
    out!("navigation: {}", run.navigation);
    if let Some(c) = run.clusters {
        out!("vehicle clusters: {} in the world, {} found, {} visited", c.total, c.found, c.visited);
    }
    out!("");
    out!("{:<14} {:>16} {:>12} {:>16} {:>12} {:>10}", "goal", "position", "identified", "claimed", "visited", "by");
    for g in &run.goals {
        out!(
            "{:<14} {:>16} {:>12} {:>16} {:>12} {:>10}",
            g.id,
            format!("({:.0}, {:.0})", g.position[0], g.position[1]),
            fmt_time(Some(g.identified_s)),
            match (&g.claimed_s, &g.claimed_by) {
                (Some(t), Some(b)) => format!("{t:.0} s {b}"),
                _ => "—".to_string(),
            },
            // A goal the operator cancelled before anyone visited it says so, and by whom.
            match (g.visited_s, g.cancelled_s) {
                (None, Some(t)) => format!("cancel {t:.0} s"),
                (visited, _) => fmt_time(visited),
            },
            match (g.visited_by.as_deref(), g.cancelled_s) {
                (Some(by), _) => by,
                (None, Some(_)) => "operator",
                (None, None) => "—",
            }
        );
    }
    let cancelled = run.goals.iter().filter(|g| g.visited_s.is_none() && g.cancelled_s.is_some()).count();
    if cancelled > 0 {
        out!("goals visited: {}/{} ({cancelled} cancelled by the operator)", run.goals_visited, run.goals.len());
    } else {
        out!("goals visited: {}/{}", run.goals_visited, run.goals.len());
    }
    if !run.operator.is_empty() {
        out!("operator commands (sim.operator):");
        for c in &run.operator {
            let applied: Vec<String> = c.acked_by.iter().map(|(robot, t)| format!("{robot} {t:.0} s")).collect();
            let applied = if applied.is_empty() { "nobody".to_string() } else { applied.join(", ") };
            out!("  {:>6.0} s  {:<12} {}; applied by {}", c.issued_s, c.id, c.action, applied);
        }
    }
    if let Some(link) = &run.operator_link {
        let [coordination, scans, maps] = link.received_bytes_by_tier;
        out!(
            "operator link: received {} messages, {:.1} kB (coordination {:.1}, scans {:.1}, maps {:.1} kB); sent {} messages, {:.1} kB",
            link.received_messages,
            link.received_bytes as f64 / 1e3,
            coordination as f64 / 1e3,
            scans as f64 / 1e3,
            maps as f64 / 1e3,
            link.sent_messages,
            link.sent_bytes as f64 / 1e3
        );
    }
    out!("");
    out!(
        "{:<8} {:<12} {:>11} {:>9} {:>11} {:>8} {:<12} {:>16}",
        "robot",
        "kind",
        "distance",
        "visited",
        "heading to",
        "collis.",
        "localization",
        "error med/max"
    );
    for r in &run.robots {
        out!(
            "{:<8} {:<12} {:>9.0} m {:>9} {:>10.0}% {:>8} {:<12} {:>16}{}",
            r.id,
            r.kind,
            r.distance_m,
            r.goals_visited,
            r.heading_to_goal_fraction * 100.0,
            r.collisions,
            r.localization,
            r.localization_error_m.map_or_else(|| "—".to_string(), |e| format!("{:.2}/{:.2} m", e.median, e.max)),
            r.killed_s.map_or_else(String::new, |t| format!("  (killed at {t:.0} s)"))
        );
    }
    out!("nodes exercised: {}/{}", run.nodes_exercised, run.nodes_total);
    if !run.problems.is_empty() {
        out!("problems reported ({} distinct; all in summary.json):", run.problems.len());
        for p in run.problems.iter().take(5) {
            out!("  {} ×{} (first at {:.0} s): {}", p.robot, p.count, p.first_s, p.message);
        }
    }
    let mcap = if with_mcap { " run.mcap," } else { "" };
    out!("wrote {}/{{summary.json,{mcap} plots/}}", trial_dir.display());
}

fn print_combined(c: &CombinedSummary) {
    out!("");
    out!("{:<6} {:<12} {:>8} {:>10} {:>10} {:>9}", "seed", "outcome", "end", "clusters", "goals", "speed");
    for r in &c.runs {
        out!(
            "{:<6} {:<12} {:>6.0} s {:>10} {:>10} {:>8.0}×",
            r.seed,
            format!("{:?}", r.outcome),
            r.end_s,
            r.clusters.map_or_else(|| "—".to_string(), |k| format!("{}/{}", k.visited, k.total)),
            format!("{}/{}", r.goals_visited, r.goals.len()),
            r.speedup
        );
    }
    out!(
        "{} of {} trials completed; mean visited fraction {:.0}%; mean speed {:.0}× real time",
        c.completed,
        c.trials,
        c.mean_visited_fraction * 100.0,
        c.mean_speedup
    );
}

/// Caps of a dry run.
#[derive(Debug, Clone, Copy)]
pub struct DryRunLimits {
    /// Simulated seconds at most (the mission's time limit when `None`).
    pub time_limit_s: Option<f64>,
    /// Wall-clock seconds at most; past them the run stops `interrupted` (and fails).
    pub max_wall_s: f64,
}

/// `spomp validate --dry-run` for one valid mission: runs it once in the simulator and reports
/// whether it ends within its time limit, which nodes were ticked and the outcome.
pub fn dry_run(
    loaded: &LoadedMission,
    json: bool,
    limits: DryRunLimits,
    registry: &NodeRegistry<RobotRuntime>,
) -> Result<(bool, serde_json::Value)> {
    let Some(mission) = loaded.mission.as_ref() else { bail!("mission did not load") };
    let seed = spomp_world::SimSpec::of_mission(mission)?.first_seed();
    let world = spomp_world::world_for_mission(mission, &loaded.base_dir(), seed)
        .with_context(|| format!("building the world of `{}`", mission.mission))?;
    let spec = *world.spec();
    let options = SimOptions { seed, time_limit_s: limits.time_limit_s, ..SimOptions::default() };
    let sim = Simulation::new(loaded, registry, Arc::new(world), options)
        .with_context(|| format!("setting up `{}` in the simulator", mission.mission))?;
    let start = Instant::now();
    let mut watch = OffMap { spec, left: Vec::new() };
    let result = sim.run_until(&mut watch, &mut || start.elapsed().as_secs_f64() > limits.max_wall_s);
    let s = &result.summary;
    // A run in which a robot left the map did not do what the mission means, whatever its
    // outcome: a flight mostly off the map is not a complete dry run.
    let ok = s.outcome.succeeded() && watch.left.is_empty();
    let stopped = s.outcome == spomp_sim::run::Outcome::Interrupted;
    if !json {
        out!(
            "  dry run (seed {seed}): {:?} at {:.0} s of {:.0} s; {}/{} nodes ticked; {}/{} goals visited",
            s.outcome,
            s.end_s,
            s.time_limit_s,
            s.nodes_exercised,
            s.nodes_total,
            s.goals_visited,
            s.goals.len()
        );
        if stopped {
            out!(
                "  stopped after {} s of wall time (--max-wall-s); give a shorter --time-limit-s or a larger --max-wall-s",
                limits.max_wall_s
            );
        }
        for (robot, at_s, p) in &watch.left {
            out!(
                "  {robot} left the map at {at_s:.0} s, at ({:.1}, {:.1}): the dry run fails (the world spans x {:.1}…{:.1} \
                 m, y {:.1}…{:.1} m)",
                p.x,
                p.y,
                spec.origin.x,
                spec.origin.x + spec.size_m().0,
                spec.origin.y,
                spec.origin.y + spec.size_m().1
            );
        }
        if !s.nodes_never_ticked.is_empty() {
            out!("  never ticked:");
            for n in &s.nodes_never_ticked {
                out!("    {n}");
            }
        }
    }
    let value = serde_json::json!({
        "outcome": s.outcome,
        "terminated_within_time_limit": ok,
        "end_s": s.end_s,
        "time_limit_s": s.time_limit_s,
        "nodes_ticked": s.nodes_exercised,
        "nodes_total": s.nodes_total,
        "never_ticked": s.nodes_never_ticked,
        "goals_visited": s.goals_visited,
        "goals": s.goals.len(),
        "left_the_map": watch.left.iter().map(|(r, t, p)| serde_json::json!({ "robot": r, "at_s": t, "x": p.x, "y": p.y }))
            .collect::<Vec<_>>(),
    });
    Ok((ok, value))
}

/// Notes each robot's first position off the world's map during a dry run.
struct OffMap {
    spec: spomp_core::GridSpec,
    /// Robot, simulated seconds, where.
    left: Vec<(String, f64, spomp_core::Point2)>,
}

impl spomp_robot::RobotObserver for OffMap {}

impl spomp_sim::run::SimObserver for OffMap {
    fn on_state(&mut self, robot: &spomp_core::RobotId, now: spomp_core::Time, state: &spomp_sim::run::RobotSnapshot) {
        let p = state.truth.position();
        if self.spec.cell_at(p).is_none() && !self.left.iter().any(|(r, _, _)| r == robot.as_str()) {
            self.left.push((robot.as_str().to_string(), now.as_secs_f64(), p));
        }
    }
}

/// `--live ADDR`: HOST:PORT with an IP address (`127.0.0.1:8765`, `[::1]:8765`, `0.0.0.0:8765`
/// to be reachable from other machines).
fn live_addr(text: &str) -> Result<SocketAddr, String> {
    text.trim().parse().map_err(|_| {
        format!("expected HOST:PORT with an IP address, such as 127.0.0.1:8765 (give --live after the mission), got `{text}`")
    })
}
