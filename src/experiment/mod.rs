//! `spomp experiment`: run an experiment file's trials (configurations × seeds) in the
//! simulator, one crash-safe row per finished trial, resumable and shardable; `report` merges
//! folders of rows into `report.md` and plots; `schema` prints the file's JSON Schema.
//!
//! See `docs/experiments.md`.

// Trials run as robots run them: a farm and `spomp run` processes (the `deploy` feature).
#[cfg(feature = "deploy")]
pub mod deployed;
pub mod report;
pub mod rows;
pub mod spec;

use std::collections::BTreeMap;
use std::io::IsTerminal;
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Instant;

use anyhow::{Context, Result, bail};
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use serde::{Deserialize, Serialize};
use spomp_behaviors::NodeRegistry;
use spomp_behaviors::mission::limits::{MAX_SOURCE_BYTES, read_text};
use spomp_robot::RobotRuntime;
use spomp_sim::run::{Outcome, SimOptions, Simulation};

use rows::{ByteCounter, RowSink, TrialRow};
use spec::{
    Claim, LoadedExperiment, ResolvedConfiguration, TeamChannel, Trial, deployed_trial, load_experiment, shard_of,
    trial_hash,
};

/// Exit code of a run stopped by Ctrl-C or SIGTERM (128 + SIGINT, as shells report it).
const EXIT_INTERRUPTED: u8 = 130;

/// What `spomp experiment` writes beside the rows: the experiment as it was run, so `report`
/// knows the configurations' order and the claims, and can tell shards of different
/// experiments apart.
pub const META: &str = "experiment.json";

/// `spomp experiment` and its subcommands.
#[derive(Debug, Clone, clap::Args)]
#[command(args_conflicts_with_subcommands = true, subcommand_negates_reqs = true)]
pub struct ExperimentArgs {
    /// Experiment file (`experiments/*.yaml`).
    #[arg(required = true)]
    pub file: Option<PathBuf>,
    /// Trials run at once (default: the number of cores).
    #[arg(long, value_parser = clap::value_parser!(u32).range(1..=256))]
    pub jobs: Option<u32>,
    /// Output folder (default `runs/experiments/<name>`): `trials.jsonl`, `trials.csv`,
    /// `experiment.json`.
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Skip the trials already complete in the output folder (same configuration, seed and
    /// hash); a trial whose configuration changed since is refused.
    #[arg(long)]
    pub resume: bool,
    /// Run only shard I of N: the trials whose index mod N is I − 1.
    #[arg(long, value_name = "I/N", value_parser = shard_arg)]
    pub shard: Option<(usize, usize)>,
    /// Run only this configuration (repeatable): a part of a study, whose rows a later run of
    /// the whole study takes with --resume.
    #[arg(long, value_name = "NAME")]
    pub only: Vec<String>,
    /// Run only this seed of the experiment's (repeatable).
    #[arg(long = "seed", value_name = "SEED")]
    pub seeds: Vec<u64>,
    /// Print a JSON summary instead of the progress bar and table.
    #[arg(long)]
    pub json: bool,
    /// Run even when a configuration's trials, run side by side, are estimated to need more
    /// memory than this machine has available.
    #[arg(long)]
    pub force: bool,
    /// A folder besides the experiment's own that its missions and worlds may be in
    /// (repeatable).
    #[arg(long = "allow-dir", value_name = "DIR")]
    pub allow_dirs: Vec<PathBuf>,
    /// Also run each selected trial deployed, as robots run it: the simulator as a lockstep
    /// robot farm and one `spomp run` process per robot over loopback, the team state over the
    /// farm's radio model (`--deployed`, `--deployed=radio`) or the signed Zenoh link
    /// (`--deployed=zenoh`); repeatable. Rows are marked with the channel; `report` sets them
    /// beside the in-process rows. A configuration's `deployed:` list does the same in the file.
    #[arg(long, value_name = "CHANNEL", num_args = 0..=1, require_equals = true, default_missing_value = "radio")]
    pub deployed: Vec<TeamChannel>,
    /// `report`, `schema` or `validate` instead of a run.
    #[command(subcommand)]
    pub action: Option<ExperimentCommand>,
}

/// Subcommands of `spomp experiment`.
#[derive(Debug, Clone, clap::Subcommand)]
pub enum ExperimentCommand {
    /// Merge the rows of one or more output folders (shards) and write report.md and plots.
    Report {
        /// Output folders of `spomp experiment` runs (shards of one experiment).
        #[arg(required = true)]
        dirs: Vec<PathBuf>,
        /// Report folder (default: the first folder).
        #[arg(long)]
        out: Option<PathBuf>,
        /// Print the merged summary as JSON.
        #[arg(long)]
        json: bool,
    },
    /// Print the JSON Schema of experiment files (experiments/experiment.schema.json).
    Schema,
    /// Check experiment files (each configuration's patched mission included): exit 0 only
    /// when all are valid.
    Validate {
        /// Experiment files.
        #[arg(required = true)]
        files: Vec<PathBuf>,
        /// A folder besides the experiment's own that its missions and worlds may be in.
        #[arg(long = "allow-dir", value_name = "DIR")]
        allow_dirs: Vec<PathBuf>,
    },
}

/// `--shard I/N` with 1 ≤ I ≤ N.
fn shard_arg(text: &str) -> Result<(usize, usize), String> {
    let bad = || format!("expected I/N with 1 ≤ I ≤ N (e.g. 2/4), got `{text}`");
    let (i, n) = text.split_once('/').ok_or_else(bad)?;
    match (i.trim().parse::<usize>(), n.trim().parse::<usize>()) {
        (Ok(i), Ok(n)) if i >= 1 && i <= n => Ok((i, n)),
        _ => Err(bad()),
    }
}

/// The experiment as run: written to `experiment.json` in the output folder.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ExperimentMeta {
    /// Experiment name.
    pub experiment: String,
    /// Configuration names, in file order.
    pub configurations: Vec<String>,
    /// Seeds, in order.
    pub seeds: Vec<u64>,
    /// The claims.
    pub claims: Vec<Claim>,
}

/// `spomp experiment …`.
pub fn experiment(args: &ExperimentArgs, registry: &NodeRegistry<RobotRuntime>) -> Result<ExitCode> {
    match &args.action {
        Some(ExperimentCommand::Report { dirs, out, json }) => report::report(dirs, out.as_deref(), *json),
        Some(ExperimentCommand::Schema) => {
            let schema = experiment_schema(registry);
            out!("{}", serde_json::to_string_pretty(&schema).context("serialising the schema")?);
            Ok(ExitCode::SUCCESS)
        }
        Some(ExperimentCommand::Validate { files, allow_dirs }) => {
            let mut ok = true;
            for f in files {
                let loaded = load_experiment(f, registry, allow_dirs);
                if loaded.is_valid() {
                    out!(
                        "✔ {}: experiment `{}` is valid ({} configurations, {} trials)",
                        f.display(),
                        loaded.file.as_ref().map_or("", |x| x.experiment.as_str()),
                        loaded.configurations.len(),
                        loaded.trials.len()
                    );
                } else {
                    print_problems(f, &loaded);
                    ok = false;
                }
            }
            Ok(if ok { ExitCode::SUCCESS } else { ExitCode::from(1) })
        }
        None => match &args.file {
            Some(file) => run(file, args, registry),
            None => usage("give an experiment file, or `report DIR...`".into()),
        },
    }
}

/// The JSON Schema of experiment files: the serde types', with every `navigation` override
/// described by the robots' own navigation schema (the one missions use).
pub fn experiment_schema(registry: &NodeRegistry<RobotRuntime>) -> serde_json::Value {
    let mut root = serde_json::to_value(schemars::schema_for!(spec::ExperimentFile)).unwrap_or_default();
    if let Some(checks) = registry.robot_checks() {
        let mut nav = checks.navigation_schema();
        let nav_defs = nav.as_object_mut().and_then(|o| o.remove("$defs"));
        if let Some(o) = nav.as_object_mut() {
            o.remove("$schema");
        }
        if let Some(serde_json::Value::Object(defs)) = root.get_mut("$defs") {
            if let Some(serde_json::Value::Object(extra)) = nav_defs {
                for (k, v) in extra {
                    defs.entry(k).or_insert(v);
                }
            }
            defs.insert("Navigation".into(), nav);
            for owner in ["Configuration", "RoleOverride", "RobotOverride"] {
                if let Some(p) = defs.get_mut(owner).and_then(|d| d.pointer_mut("/properties/navigation")) {
                    let description = p.get("description").cloned().unwrap_or(serde_json::Value::Null);
                    *p = serde_json::json!({"description": description, "$ref": "#/$defs/Navigation"});
                }
            }
        }
    }
    if let serde_json::Value::Object(o) = &mut root {
        o.insert("title".into(), serde_json::Value::String("spomp experiment".into()));
    }
    root
}

/// A usage error: printed, exit 2.
fn usage(message: String) -> Result<ExitCode> {
    errln!("error: {message}");
    Ok(ExitCode::from(2))
}

fn print_problems(file: &Path, loaded: &LoadedExperiment) {
    let source_of = |f: &Path| loaded.sources.get(f).cloned().unwrap_or_default();
    let mut text = crate::commands::render_located(&loaded.diagnostics, &source_of);
    text.push_str(&format!("✘ {}: {} problem(s)\n", file.display(), loaded.diagnostics.len()));
    out!("{}", text.trim_end());
}

/// Runs the experiment's (shard of) trials.
fn run(file: &Path, args: &ExperimentArgs, registry: &NodeRegistry<RobotRuntime>) -> Result<ExitCode> {
    let loaded = load_experiment(file, registry, &args.allow_dirs);
    if !loaded.is_valid() {
        print_problems(file, &loaded);
        return Ok(ExitCode::from(1));
    }
    let Some(spec_file) = loaded.file.as_ref() else { bail!("the experiment did not load") };
    let out_dir =
        args.out.clone().unwrap_or_else(|| PathBuf::from("runs").join("experiments").join(&spec_file.experiment));
    let meta = ExperimentMeta {
        experiment: spec_file.experiment.clone(),
        configurations: loaded.configurations.iter().map(|c| c.name.clone()).collect(),
        seeds: loaded.seeds(),
        claims: spec_file.claims.clone(),
    };
    let existing = rows::read_rows(&out_dir)?;
    if !existing.is_empty() && !args.resume {
        return usage(format!(
            "{} already holds {} trial rows; give --resume to continue that run, or another --out",
            out_dir.display(),
            existing.len()
        ));
    }
    let hash_of = |t: &Trial| trial_hash(&loaded.configurations[t.configuration], t.seed);
    let names: Vec<&str> = loaded.configurations.iter().map(|c| c.name.as_str()).collect();
    if let Some(bad) = args.only.iter().find(|o| !names.contains(&o.as_str())) {
        return usage(format!("--only {bad}: no such configuration; configurations are: {}", names.join(", ")));
    }
    let seeds = loaded.seeds();
    if let Some(bad) = args.seeds.iter().find(|s| !seeds.contains(s)) {
        return usage(format!("--seed {bad}: not a seed of the experiment"));
    }
    // The file's trials, and the deployed runs --deployed asks for besides.
    let in_process = loaded.trials.iter().filter(|t| t.deployed.is_none()).count();
    let mut trials = loaded.trials.clone();
    for t in loaded.trials.iter().filter(|t| t.deployed.is_none()) {
        for channel in &args.deployed {
            let d = deployed_trial(t, *channel, in_process);
            if !trials.iter().any(|x| x.index == d.index) {
                trials.push(d);
            }
        }
    }
    trials.sort_by_key(|t| t.index);
    let selected: Vec<Trial> = match args.shard {
        Some((i, n)) => shard_of(&trials, i, n),
        None => trials,
    }
    .into_iter()
    .filter(|t| args.only.is_empty() || args.only.contains(&loaded.configurations[t.configuration].name))
    .filter(|t| args.seeds.is_empty() || args.seeds.contains(&t.seed))
    .collect();
    // Rows already there: each must be a trial of this experiment as it is now (a deployed row
    // is its in-process trial run another way, with the same hash).
    let mut done: BTreeMap<(String, u64, Option<TeamChannel>), &TrialRow> = BTreeMap::new();
    for r in &existing {
        let trial = loaded.trials.iter().find(|t| {
            t.deployed.is_none() && loaded.configurations[t.configuration].name == r.configuration && t.seed == r.seed
        });
        match trial {
            Some(t) if hash_of(t) == r.config_hash => {
                done.insert((r.configuration.clone(), r.seed, r.deployed), r);
            }
            Some(_) => {
                errln!(
                    "error: {}: the row of configuration `{}` seed {} was run with another version of that \
                     configuration (its base mission or overrides changed since); run the edited experiment \
                     into another --out",
                    out_dir.join(rows::JSONL).display(),
                    r.configuration,
                    r.seed
                );
                return Ok(ExitCode::from(1));
            }
            None => {
                errln!(
                    "error: {} holds a row of configuration `{}` seed {}, which the experiment no longer has; \
                     run it into another --out",
                    out_dir.join(rows::JSONL).display(),
                    r.configuration,
                    r.seed
                );
                return Ok(ExitCode::from(1));
            }
        }
    }
    if let Ok(text) = read_text(&out_dir.join(META), MAX_SOURCE_BYTES)
        && let Ok(previous) = serde_json::from_str::<ExperimentMeta>(&text)
        && !existing.is_empty()
        && (previous.experiment != meta.experiment || previous.configurations != meta.configurations)
    {
        errln!(
            "error: {} holds rows of experiment `{}` (configurations {}); run `{}` into another --out",
            out_dir.display(),
            previous.experiment,
            previous.configurations.join(", "),
            meta.experiment
        );
        return Ok(ExitCode::from(1));
    }
    let pending: Vec<Trial> = selected
        .iter()
        .filter(|t| !done.contains_key(&(loaded.configurations[t.configuration].name.clone(), t.seed, t.deployed)))
        .cloned()
        .collect();
    if !crate::deploy::BUILT && pending.iter().any(|t| t.deployed.is_some()) {
        return crate::deploy::not_built("deployed trials (--deployed, a configuration's `deployed:`)");
    }
    let jobs = args.jobs.map_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get()), |j| j as usize);
    if !args.force
        && let Some(budget) = crate::memory_stage::machine_budget()
        && let Err(message) = check_memory(&loaded.configurations, &pending, jobs, &budget)
    {
        return usage(format!("{message}; give --force to run anyway"));
    }
    std::fs::create_dir_all(&out_dir).with_context(|| format!("creating {}", out_dir.display()))?;
    rows::write_synced(&out_dir.join(META), serde_json::to_string_pretty(&meta)?.as_bytes())?;
    let skipped = selected.len() - pending.len();
    let existing_owned: Vec<TrialRow> = existing.clone();
    let sink = Mutex::new(RowSink::open(&out_dir, &existing_owned)?);
    let interrupted = crate::sim_cmd::stop_on_signals()?;
    let quiet = args.json || !std::io::stderr().is_terminal();
    let bar = ProgressBar::with_draw_target(
        Some(pending.len() as u64),
        if quiet { ProgressDrawTarget::hidden() } else { ProgressDrawTarget::stderr() },
    );
    bar.set_style(
        ProgressStyle::with_template("trials {bar:30} {pos}/{len} [{elapsed_precise}, ~{eta} left] {msg}")
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    let pool = rayon::ThreadPoolBuilder::new().num_threads(jobs).build().context("starting the trial threads")?;
    // Fewer trials than threads: each trial steps its robots in parallel too (same results).
    let parallel_robots = pending.len() < jobs;
    let costs: Vec<f64> = loaded.configurations.iter().map(expected_cost).collect();
    let order = longest_first(&pending, &costs);
    let start = Instant::now();
    let failures: Mutex<Vec<String>> = Mutex::new(Vec::new());
    let written = std::sync::atomic::AtomicUsize::new(0);
    let next = std::sync::atomic::AtomicUsize::new(0);
    // The experiment's folder (`.` for a file named without one: an empty path is no argument).
    let file_dir = file.parent().filter(|d| !d.as_os_str().is_empty()).unwrap_or(Path::new("."));
    let mut allow_dirs: Vec<PathBuf> = vec![file_dir.to_path_buf()];
    allow_dirs.extend(args.allow_dirs.iter().cloned());
    #[cfg(feature = "deploy")]
    let work_dir = out_dir.join("deployed");
    #[cfg(feature = "deploy")]
    let deployment = deployed::Deployment { allow_dirs: &allow_dirs, work_dir: &work_dir };
    let run_one = |t: &Trial| {
        if interrupted.load(Ordering::Relaxed) {
            return;
        }
        let configuration = &loaded.configurations[t.configuration];
        let hash = hash_of(t);
        let outcome = match t.deployed {
            None => run_trial(t, configuration, &hash, registry, parallel_robots, &interrupted),
            #[cfg(feature = "deploy")]
            Some(_) => deployed::run_deployed_trial(t, configuration, &hash, registry, &deployment, &interrupted),
            // Refused before any trial ran (above).
            #[cfg(not(feature = "deploy"))]
            Some(_) => Err(crate::deploy::not_built_error("a deployed trial")),
        };
        match outcome {
            Ok(Some(row)) => {
                let appended = sink
                    .lock()
                    .map_err(|_| anyhow::anyhow!("a trial thread panicked"))
                    .and_then(|mut s| s.append(&row));
                match appended {
                    Ok(()) => {
                        written.fetch_add(1, Ordering::Relaxed);
                        let how = row.deployed.map_or_else(String::new, |c| format!(" (deployed, {c})"));
                        bar.set_message(format!("{} seed {}{how}: {}", row.configuration, row.seed, row.outcome));
                    }
                    Err(e) => push(&failures, format!("{e:#}")),
                }
            }
            Ok(None) => {} // cut short by a signal: not a finished trial
            Err(e) => {
                let how = t.deployed.map_or_else(String::new, |c| format!(" (deployed, {c})"));
                push(&failures, format!("configuration `{}` seed {}{how}: {e:#}", configuration.name, t.seed));
            }
        }
        bar.inc(1);
    };
    // One worker per job, each taking the next trial of one shared queue when it is free. (A
    // `par_iter` over the trials splits them into fixed halves and quarters up front, and a
    // quarter already started is never split again: the paper's study ran its first 60 trials
    // on one thread while the other sat idle for the last 7 of its 17.5 minutes.)
    pool.scope(|scope| {
        for _ in 0..jobs.min(order.len()) {
            scope.spawn(|_| {
                while let Some(t) = order.get(next.fetch_add(1, Ordering::Relaxed)) {
                    run_one(t);
                }
            });
        }
    });
    bar.finish_and_clear();
    let failures = failures.into_inner().unwrap_or_default();
    let was_interrupted = interrupted.load(Ordering::Relaxed);
    let ran = written.load(Ordering::Relaxed);
    let summary = serde_json::json!({
        "experiment": meta.experiment,
        "out": out_dir,
        "shard": args.shard.map(|(i, n)| format!("{i}/{n}")),
        "trials_selected": selected.len(),
        "trials_skipped": skipped,
        "trials_run": ran,
        "failures": failures,
        "interrupted": was_interrupted,
        "wall_s": start.elapsed().as_secs_f64(),
    });
    if args.json {
        out!("{}", serde_json::to_string_pretty(&summary)?);
    } else {
        let shard = args.shard.map_or_else(String::new, |(i, n)| format!(" (shard {i}/{n})"));
        out!(
            "experiment `{}`{shard}: {ran} trials run, {skipped} already complete, of {} selected, in {:.1} s",
            meta.experiment,
            selected.len(),
            start.elapsed().as_secs_f64()
        );
        for f in &failures {
            out!("  failed: {f}");
        }
        if was_interrupted {
            out!(
                "interrupted: the finished trials are in {}; run again with --resume",
                out_dir.join(rows::JSONL).display()
            );
        }
        out!("rows: {} and {}", out_dir.join(rows::JSONL).display(), out_dir.join(rows::CSV).display());
        out!("report: spomp experiment report {}", out_dir.display());
    }
    Ok(if was_interrupted {
        ExitCode::from(EXIT_INTERRUPTED)
    } else if failures.is_empty() {
        ExitCode::SUCCESS
    } else {
        ExitCode::from(1)
    })
}

fn push(list: &Mutex<Vec<String>>, message: String) {
    if let Ok(mut l) = list.lock() {
        l.push(message);
    }
}

/// Holds each configuration with trials to run against the memory `budget`, as `spomp sim`
/// does before it starts: a configuration's trials run up to `jobs` side by side (and trials of
/// other configurations may share the machine with them, so the figure is a floor). The first
/// configuration that cannot fit is an error naming it.
fn check_memory(
    configurations: &[ResolvedConfiguration],
    pending: &[Trial],
    jobs: usize,
    budget: &crate::memory_stage::Budget,
) -> Result<(), String> {
    let side_by_side = jobs.min(pending.len()).max(1);
    for (index, configuration) in configurations.iter().enumerate() {
        if !pending.iter().any(|t| t.configuration == index) {
            continue;
        }
        let loaded = &configuration.loaded;
        let Some(mission) = loaded.mission.as_ref() else { continue };
        // A world that does not load fails the trial with its own message.
        let Ok(sizes) = crate::memory_stage::sizes_of(mission, &loaded.base_dir()) else { continue };
        crate::memory_stage::judge(&sizes, side_by_side, budget)
            .map_err(|message| format!("configuration `{}`: {message}", configuration.name))?;
    }
    Ok(())
}

/// What a trial of `configuration` is expected to cost, in UGV-seconds: its UGVs do nearly all
/// of a run's work (panoramas, terrain, localization, planning), and a run lasts up to its time
/// limit. Only the order of these figures matters.
fn expected_cost(configuration: &ResolvedConfiguration) -> f64 {
    configuration.loaded.mission.as_ref().map_or(0.0, |mission| {
        let ugvs = mission.team.iter().filter(|r| r.kind == spomp_core::RobotKind::Ugv).count();
        ugvs.max(1) as f64 * mission.time_limit_s
    })
}

/// The `pending` trials in the order they are started: the costliest configurations' first
/// (`costs` by configuration index), experiment order among equals. Short trials last keep the
/// end of a run from waiting on one long trial while the other workers are idle.
fn longest_first(pending: &[Trial], costs: &[f64]) -> Vec<Trial> {
    let cost = |t: &Trial| costs.get(t.configuration).copied().unwrap_or(0.0);
    let mut order = pending.to_vec();
    order.sort_by(|a, b| cost(b).total_cmp(&cost(a)).then(a.index.cmp(&b.index)));
    order
}

/// Runs one trial; `None` when a signal cut it short.
fn run_trial(
    trial: &Trial,
    configuration: &ResolvedConfiguration,
    hash: &str,
    registry: &NodeRegistry<RobotRuntime>,
    parallel_robots: bool,
    interrupted: &AtomicBool,
) -> Result<Option<TrialRow>> {
    let loaded = &configuration.loaded;
    let Some(mission) = loaded.mission.as_ref() else { bail!("the mission did not load") };
    let world = spomp_world::world_for_mission(mission, &loaded.base_dir(), trial.seed)
        .with_context(|| format!("building the world of `{}`", mission.mission))?;
    let options = SimOptions { seed: trial.seed, parallel_robots, ..SimOptions::default() };
    let sim = Simulation::new(loaded, registry, Arc::new(world), options)
        .with_context(|| format!("setting up `{}`", mission.mission))?;
    let result = sim.run_until(&mut rows::TrialObserver, &mut || interrupted.load(Ordering::Relaxed));
    if result.summary.outcome == Outcome::Interrupted {
        return Ok(None);
    }
    let bytes = ByteCounter::of_robots(&result.team_traffic);
    Ok(Some(rows::row_of(trial.index, &configuration.name, hash, &result.summary, &bytes)))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn trial(index: usize, configuration: usize) -> Trial {
        Trial { index, configuration, seed: index as u64 + 1, deployed: None }
    }

    #[test]
    fn trials_start_costliest_configuration_first_in_experiment_order_among_equals() {
        // Configuration 0 is cheap, 1 dear, 2 as dear as 1, 3 has no estimate.
        let costs = [1800.0, 9000.0, 9000.0];
        let pending = [trial(0, 0), trial(1, 0), trial(2, 1), trial(3, 1), trial(4, 2), trial(5, 3)];
        let order: Vec<usize> = longest_first(&pending, &costs).iter().map(|t| t.index).collect();
        assert_eq!(order, vec![2, 3, 4, 0, 1, 5]);
    }

    #[test]
    fn ordering_keeps_every_trial_once() {
        let costs = [5.0, 1.0, 3.0];
        let pending: Vec<Trial> = (0..30).map(|i| trial(i, i % 3)).collect();
        let mut indices: Vec<usize> = longest_first(&pending, &costs).iter().map(|t| t.index).collect();
        indices.sort_unstable();
        assert_eq!(indices, (0..30).collect::<Vec<_>>());
    }
}
