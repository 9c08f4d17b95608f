//! `spomp experiment report`: merges the rows of one or more output folders (shards), and writes
//! `report.md` (per configuration the mean and spread of each metric over seeds, time to the
//! k-th goal, a verdict per claim) with PNG plots (goals visited over time, a band per
//! configuration; each metric's mean and spread). Deployed rows (`--deployed`) are set beside
//! the in-process rows of the same configuration and seeds; the tables, plots and claims are
//! the in-process rows'.

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::process::ExitCode;

use anyhow::{Context, Result, anyhow, bail};
use plotters::prelude::*;
use serde::Serialize;
use spomp_behaviors::mission::limits::{MAX_SOURCE_BYTES, read_text};

use super::rows::{self, TrialRow};
use super::spec::{Claim, Expect, Metric, TeamChannel};
use super::{ExperimentMeta, META};

/// The largest magnitude a plot's axis may reach. Past it (a corrupted or hand-edited row: a
/// distance of 1e200 m) the plotting library's axis code does not end, so such values are left
/// out of the plots and named in the report instead.
pub const PLOT_LIMIT: f64 = 1e12;

/// Whether `v` can be drawn: finite and at most [`PLOT_LIMIT`] in magnitude.
fn plottable(v: f64) -> bool {
    v.is_finite() && v.abs() <= PLOT_LIMIT
}

/// Mean and spread of a metric over a configuration's trials.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Stats {
    /// Trials with a value.
    pub n: usize,
    /// Mean.
    pub mean: f64,
    /// Sample standard deviation (0 for one trial).
    pub sd: f64,
    /// Smallest value.
    pub min: f64,
    /// Largest value.
    pub max: f64,
}

impl Stats {
    /// The statistics of `values`; `None` when empty.
    pub fn of(values: &[f64]) -> Option<Stats> {
        if values.is_empty() {
            return None;
        }
        let n = values.len();
        let mean = values.iter().sum::<f64>() / n as f64;
        let var = if n > 1 { values.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1) as f64 } else { 0.0 };
        let min = values.iter().copied().fold(f64::INFINITY, f64::min);
        let max = values.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        Some(Stats { n, mean, sd: var.sqrt(), min, max })
    }

    /// Standard error of the mean.
    pub fn se(&self) -> f64 {
        self.sd / (self.n.max(1) as f64).sqrt()
    }
}

/// A claim's result.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ClaimResult {
    /// The claim.
    pub claim: Claim,
    /// The compared means, in the claim's order (`None`: no trial of that configuration).
    pub stats: Vec<Option<Stats>>,
    /// `holds`, `fails` or `no data`.
    pub verdict: &'static str,
    /// The smallest step between neighbours in units of their combined standard error
    /// (increasing/decreasing claims with at least two trials each): below 2 the order could be
    /// noise.
    pub weakest_step_se: Option<f64>,
}

/// The ratio of the first of two means to the second (`ratio_at_least`): `None` unless there
/// are two and the second is positive.
pub fn ratio_of(means: &[f64]) -> Option<f64> {
    match means {
        [a, b] if *b > 0.0 && a.is_finite() && b.is_finite() => Some(a / b),
        _ => None,
    }
}

/// Checks one claim against the merged rows.
pub fn check_claim(claim: &Claim, rows: &[TrialRow]) -> ClaimResult {
    let k = claim.k.unwrap_or(1);
    let stats: Vec<Option<Stats>> = claim
        .over
        .iter()
        .map(|name| {
            let values: Vec<f64> = rows
                .iter()
                .filter(|r| &r.configuration == name)
                .filter_map(|r| r.metric(claim.metric, k, claim.robot.as_deref()))
                .collect();
            Stats::of(&values)
        })
        .collect();
    let Some(means) = stats.iter().map(|s| s.map(|s| s.mean)).collect::<Option<Vec<f64>>>() else {
        return ClaimResult { claim: claim.clone(), stats, verdict: "no data", weakest_step_se: None };
    };
    let bound = claim.value.unwrap_or(f64::NAN);
    // The values a bound is held on: each configuration's mean, or with `each_trial` the
    // extreme trial of each (the smallest for `at_least`, the largest for `at_most`).
    let bounded = |low: bool| -> Vec<f64> {
        if !claim.each_trial {
            return means.clone();
        }
        stats.iter().flatten().map(|s| if low { s.min } else { s.max }).collect()
    };
    let holds = match claim.expect {
        Expect::Increasing => means.windows(2).all(|w| w[1] > w[0]),
        Expect::Decreasing => means.windows(2).all(|w| w[1] < w[0]),
        Expect::Similar => {
            let tol = claim.tolerance.unwrap_or(0.1);
            let first = means[0];
            means.iter().all(|m| (m - first).abs() <= tol * first.abs().max(f64::EPSILON))
        }
        Expect::AtLeast => bounded(true).iter().all(|v| *v >= bound),
        Expect::AtMost => bounded(false).iter().all(|v| *v <= bound),
        Expect::RatioAtLeast => ratio_of(&means).is_some_and(|r| r >= bound),
    };
    let weakest_step_se = match claim.expect {
        Expect::Similar | Expect::AtLeast | Expect::AtMost | Expect::RatioAtLeast => None,
        _ => stats
            .windows(2)
            .filter_map(|w| match (w[0], w[1]) {
                (Some(a), Some(b)) if a.n > 1 && b.n > 1 => {
                    let se = (a.se().powi(2) + b.se().powi(2)).sqrt();
                    (se > 0.0).then(|| (b.mean - a.mean).abs() / se)
                }
                _ => None,
            })
            .reduce(f64::min),
    };
    ClaimResult { claim: claim.clone(), stats, verdict: if holds { "holds" } else { "fails" }, weakest_step_se }
}

/// Reads and merges the rows of `dirs`: one row per (configuration, seed, in-process or
/// deployed channel); equal duplicates (the same trial in two folders) count once, differing
/// ones are an error.
pub fn merge(dirs: &[PathBuf]) -> Result<(ExperimentMeta, Vec<TrialRow>)> {
    let mut meta: Option<(ExperimentMeta, &Path)> = None;
    let mut merged: BTreeMap<(String, u64, Option<TeamChannel>), (TrialRow, PathBuf)> = BTreeMap::new();
    for dir in dirs {
        let path = dir.join(META);
        let text = read_text(&path, MAX_SOURCE_BYTES).map_err(|e| {
            anyhow!("reading {}: {e} (is {} an experiment output folder?)", path.display(), dir.display())
        })?;
        let m: ExperimentMeta = serde_json::from_str(&text).with_context(|| format!("parsing {}", path.display()))?;
        match &meta {
            None => meta = Some((m, dir)),
            Some((first, first_dir)) if *first != m => bail!(
                "{} and {} hold different experiments (`{}` and `{}`, or their configurations, seeds or claims differ)",
                first_dir.display(),
                dir.display(),
                first.experiment,
                m.experiment
            ),
            Some(_) => {}
        }
        for row in rows::read_rows(dir)? {
            let key = (row.configuration.clone(), row.seed, row.deployed);
            match merged.get(&key) {
                Some((other, from)) if other.deterministic_part() != row.deterministic_part() => bail!(
                    "configuration `{}` seed {}{}: the rows in {} and {} differ (hash {} and {}); \
                     they are not the same trial",
                    row.configuration,
                    row.seed,
                    row.deployed.map_or_else(String::new, |c| format!(" (deployed, {c})")),
                    from.display(),
                    dir.display(),
                    other.config_hash,
                    row.config_hash
                ),
                Some(_) => {}
                None => {
                    merged.insert(key, (row, dir.clone()));
                }
            }
        }
    }
    let Some((meta, _)) = meta else { bail!("no output folder given") };
    let mut rows: Vec<TrialRow> = merged.into_values().map(|(r, _)| r).collect();
    rows.sort_by_key(|r| r.trial);
    Ok((meta, rows))
}

/// One seed of a configuration, in-process and deployed over one channel.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct DeployedPair {
    /// Seed.
    pub seed: u64,
    /// Vehicle clusters visited (goals, in a world without clusters): in-process, deployed.
    pub clusters_visited: (f64, f64),
    /// Distance the UAVs flew, metres: in-process, deployed.
    pub uav_distance_m: (f64, f64),
    /// Goals visited: in-process, deployed.
    pub goals_visited: (usize, usize),
    /// Whether the deployed row equals the in-process one field for field but wall time, with no
    /// process problems (a trial whose processes failed was simulated by the farm, not deployed).
    pub identical: bool,
    /// The deployed trial's process problems.
    pub process_problems: Vec<String>,
}

/// A configuration's deployed trials over one team channel beside its in-process trials of
/// the same seeds.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct DeployedComparison {
    /// Configuration.
    pub configuration: String,
    /// Team channel of the deployed trials.
    pub channel: TeamChannel,
    /// Per seed with both rows, in seed order.
    pub pairs: Vec<DeployedPair>,
    /// Seeds with a deployed row but no in-process one (not compared).
    pub unpaired_seeds: Vec<u64>,
    /// Mean clusters visited: in-process, deployed.
    pub clusters_visited: (f64, f64),
    /// Deployed mean over in-process mean of clusters visited.
    pub clusters_ratio: Option<f64>,
    /// Mean UAV distance, metres: in-process, deployed.
    pub uav_distance_m: (f64, f64),
    /// Deployed mean over in-process mean of UAV distance.
    pub uav_distance_ratio: Option<f64>,
}

/// The deployed rows of `rows` beside the in-process rows of the same configuration and seed,
/// per configuration (in `configurations` order) and channel.
pub fn deployed_comparisons(configurations: &[String], rows: &[TrialRow]) -> Vec<DeployedComparison> {
    let mut out = Vec::new();
    for c in configurations {
        for channel in TeamChannel::ALL {
            let deployed: Vec<&TrialRow> =
                rows.iter().filter(|r| &r.configuration == c && r.deployed == Some(channel)).collect();
            if deployed.is_empty() {
                continue;
            }
            let mut pairs = Vec::new();
            let mut unpaired_seeds = Vec::new();
            for d in deployed {
                let Some(i) = rows.iter().find(|r| &r.configuration == c && r.seed == d.seed && r.deployed.is_none())
                else {
                    unpaired_seeds.push(d.seed);
                    continue;
                };
                let bare = |r: &TrialRow| TrialRow {
                    trial: 0,
                    deployed: None,
                    process_problems: Vec::new(),
                    ..r.deterministic_part()
                };
                pairs.push(DeployedPair {
                    seed: d.seed,
                    clusters_visited: (i.clusters_or_goals_visited(), d.clusters_or_goals_visited()),
                    uav_distance_m: (i.uav_distance_m(), d.uav_distance_m()),
                    goals_visited: (i.goals_visited, d.goals_visited),
                    identical: d.process_problems.is_empty() && bare(i) == bare(d),
                    process_problems: d.process_problems.clone(),
                });
            }
            pairs.sort_by_key(|p| p.seed);
            unpaired_seeds.sort_unstable();
            let mean = |f: &dyn Fn(&DeployedPair) -> f64| {
                if pairs.is_empty() { f64::NAN } else { pairs.iter().map(f).sum::<f64>() / pairs.len() as f64 }
            };
            let ratio = |(a, b): (f64, f64)| (a.is_finite() && b.is_finite() && a != 0.0).then(|| b / a);
            let clusters_visited = (mean(&|p| p.clusters_visited.0), mean(&|p| p.clusters_visited.1));
            let uav_distance_m = (mean(&|p| p.uav_distance_m.0), mean(&|p| p.uav_distance_m.1));
            out.push(DeployedComparison {
                configuration: c.clone(),
                channel,
                pairs,
                unpaired_seeds,
                clusters_ratio: ratio(clusters_visited),
                clusters_visited,
                uav_distance_ratio: ratio(uav_distance_m),
                uav_distance_m,
            });
        }
    }
    out
}

/// The report's section on deployed trials (empty without any).
fn deployed_markdown(comparisons: &[DeployedComparison]) -> String {
    let mut md = String::new();
    if comparisons.is_empty() {
        return md;
    }
    let _ = writeln!(
        md,
        "## Deployed beside in-process

Trials run as robots run them (`--deployed`): the simulator as a lockstep \
         robot farm, one `spomp run` process per robot, the team state over the farm's radio model (`radio`) or the \
         signed Zenoh link (`zenoh`). Each is set beside the in-process trial of the same configuration and seed; \
         means are over the seeds with both. Over the radio model a deployed row is the in-process row, field for \
         field but wall time (`identical`). The claims, tables and plots above use the in-process rows only.\n"
    );
    let _ = writeln!(
        md,
        "| configuration | channel | seeds | clusters visited: in-process | deployed | ratio | UAV distance (m): \
         in-process | deployed | ratio | identical | with process problems |"
    );
    let _ = writeln!(md, "|---|---|---|---|---|---|---|---|---|---|---|");
    for c in comparisons {
        let _ = writeln!(
            md,
            "| {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} |",
            c.configuration,
            c.channel,
            c.pairs.len(),
            fmt_num(c.clusters_visited.0),
            fmt_num(c.clusters_visited.1),
            fmt_ratio(c.clusters_ratio),
            fmt_num(c.uav_distance_m.0),
            fmt_num(c.uav_distance_m.1),
            fmt_ratio(c.uav_distance_ratio),
            c.pairs.iter().filter(|p| p.identical).count(),
            c.pairs.iter().filter(|p| !p.process_problems.is_empty()).count()
        );
    }
    let _ = writeln!(
        md,
        "
### Per seed
"
    );
    let _ = writeln!(
        md,
        "| configuration | channel | seed | clusters visited: in-process | deployed | UAV distance (m): in-process | \
         deployed | goals visited: in-process | deployed | identical | process problems |"
    );
    let _ = writeln!(md, "|---|---|---|---|---|---|---|---|---|---|---|");
    for c in comparisons {
        for p in &c.pairs {
            let problems =
                if p.process_problems.is_empty() { "—".to_string() } else { p.process_problems.join("; ") };
            let _ = writeln!(
                md,
                "| {} | {} | {} | {} | {} | {:.0} | {:.0} | {} | {} | {} | {} |",
                c.configuration,
                c.channel,
                p.seed,
                p.clusters_visited.0,
                p.clusters_visited.1,
                p.uav_distance_m.0,
                p.uav_distance_m.1,
                p.goals_visited.0,
                p.goals_visited.1,
                if p.identical { "yes" } else { "no" },
                problems.replace('|', "\\|")
            );
        }
    }
    let unpaired: Vec<String> = comparisons
        .iter()
        .flat_map(|c| c.unpaired_seeds.iter().map(move |s| format!("{}/{s} ({})", c.configuration, c.channel)))
        .collect();
    if !unpaired.is_empty() {
        let _ = writeln!(
            md,
            "
Deployed rows without an in-process row of their seed (not compared): {}.",
            unpaired.join(", ")
        );
    }
    let _ = writeln!(md);
    md
}

/// `spomp experiment report DIR... [--out DIR]`.
pub fn report(dirs: &[PathBuf], out: Option<&Path>, json: bool) -> Result<ExitCode> {
    let (meta, all_rows) = merge(dirs)?;
    // The study is the in-process rows'; deployed rows get their own section.
    let comparisons = deployed_comparisons(&meta.configurations, &all_rows);
    let rows: Vec<TrialRow> = all_rows.iter().filter(|r| r.deployed.is_none()).cloned().collect();
    let out_dir = out.map(Path::to_path_buf).or_else(|| dirs.first().cloned()).ok_or_else(|| anyhow!("no folder"))?;
    let plots = out_dir.join("plots");
    crate::output::create_dir(&plots)?;
    let mut jsonl = String::new();
    let mut csv = format!("{}\n", rows::CSV_HEADER);
    for r in &all_rows {
        jsonl.push_str(&serde_json::to_string(r)?);
        jsonl.push('\n');
        csv.push_str(&rows::csv_line(r));
    }
    rows::write_synced(&out_dir.join("merged-trials.jsonl"), jsonl.as_bytes())?;
    rows::write_synced(&out_dir.join("merged-trials.csv"), csv.as_bytes())?;
    let table = stats_table(&meta, &rows);
    let claims: Vec<ClaimResult> = meta.claims.iter().map(|c| check_claim(c, &rows)).collect();
    let everything = format!("{}: goals visited over time (mean ± sd over seeds)", meta.experiment);
    let (plotted_rows, mut left_out) = rows_to_plot(&rows);
    goals_over_time_plot(&everything, &meta.configurations, &plotted_rows, &plots.join("goals_over_time.png"))?;
    let groups = claim_groups(&meta, &plotted_rows);
    for (i, group) in groups.iter().enumerate() {
        let title = format!("goals visited over time: {}", group.join(" / "));
        goals_over_time_plot(&title, group, &plotted_rows, &plots.join(group_plot_name(i)))?;
    }
    left_out.extend(metrics_plot(&meta, &table, &plots.join("metrics.png"))?);
    let mut md = markdown(&meta, &rows, &table, &claims);
    md.push_str(&deployed_markdown(&comparisons));
    if !left_out.is_empty() {
        let _ = writeln!(
            md,
            "## Left out of the plots\n\nValues that are not finite or exceed {PLOT_LIMIT:e} in magnitude cannot be \
             drawn; the tables above keep them.\n"
        );
        for note in &left_out {
            let _ = writeln!(md, "- {note}");
        }
        let _ = writeln!(md);
    }
    if !groups.is_empty() {
        let _ = writeln!(
            md,
            "## Goals visited over time, per compared set
"
        );
        for (i, group) in groups.iter().enumerate() {
            let _ = writeln!(
                md,
                "![{}](plots/{})
",
                group.join(" / "),
                group_plot_name(i)
            );
        }
    }
    rows::write_synced(&out_dir.join("report.md"), md.as_bytes())?;
    let expected = meta.configurations.len() * meta.seeds.len();
    if json {
        let configurations: Vec<_> = meta
            .configurations
            .iter()
            .map(|c| {
                let metrics: BTreeMap<&str, Option<Stats>> =
                    Metric::ALL.iter().map(|m| (m.as_str(), table.get(&(c.clone(), *m)).copied())).collect();
                serde_json::json!({ "name": c, "trials": rows.iter().filter(|r| &r.configuration == c).count(), "metrics": metrics })
            })
            .collect();
        let v = serde_json::json!({
            "experiment": meta.experiment,
            "trials": rows.len(),
            "trials_expected": expected,
            "configurations": configurations,
            "claims": claims,
            "deployed": comparisons,
            "left_out_of_plots": left_out,
            "report": out_dir.join("report.md"),
        });
        out!("{}", serde_json::to_string_pretty(&v)?);
    } else {
        out!(
            "experiment `{}`: {} of {expected} trials merged from {} folder(s)",
            meta.experiment,
            rows.len(),
            dirs.len()
        );
        for c in &claims {
            out!("  {:<8} {}", c.verdict, c.claim.name);
        }
        for c in &comparisons {
            out!(
                "  deployed ({}) {}: {} seeds; clusters visited {} vs {} in-process (×{}), UAV distance ×{}",
                c.channel,
                c.configuration,
                c.pairs.len(),
                fmt_num(c.clusters_visited.1),
                fmt_num(c.clusters_visited.0),
                fmt_ratio(c.clusters_ratio),
                fmt_ratio(c.uav_distance_ratio)
            );
        }
        if !left_out.is_empty() {
            out!(
                "  {} value(s) left out of the plots (not finite or beyond {PLOT_LIMIT:e}; see the report)",
                left_out.len()
            );
        }
        out!("report: {}", out_dir.join("report.md").display());
    }
    Ok(ExitCode::SUCCESS)
}

type Table = BTreeMap<(String, Metric), Stats>;

fn stats_table(meta: &ExperimentMeta, rows: &[TrialRow]) -> Table {
    let mut t = Table::new();
    for c in &meta.configurations {
        for m in Metric::ALL {
            let values: Vec<f64> =
                rows.iter().filter(|r| &r.configuration == c).filter_map(|r| r.metric(m, 1, None)).collect();
            if let Some(s) = Stats::of(&values) {
                t.insert((c.clone(), m), s);
            }
        }
    }
    t
}

/// A deployed/in-process ratio to three decimals, `—` when there is none.
fn fmt_ratio(r: Option<f64>) -> String {
    r.map_or_else(|| "—".to_string(), |r| format!("{r:.3}"))
}

fn fmt_num(v: f64) -> String {
    if v.abs() >= 1e6 {
        format!("{:.3e}", v)
    } else if v.abs() >= 100.0 {
        format!("{v:.0}")
    } else if v.abs() >= 1.0 {
        format!("{v:.2}")
    } else {
        format!("{v:.3}")
    }
}

fn markdown(meta: &ExperimentMeta, rows: &[TrialRow], table: &Table, claims: &[ClaimResult]) -> String {
    let mut md = String::new();
    let expected = meta.configurations.len() * meta.seeds.len();
    let _ = writeln!(md, "# Experiment `{}`\n", meta.experiment);
    let _ = writeln!(
        md,
        "{} of {expected} trials ({} configurations × {} seeds). Each cell: mean ± standard deviation over seeds \
         [min – max]. `time_to_goal_s` is the first visit; a trial that never visited counts its time limit.\n",
        rows.len(),
        meta.configurations.len(),
        meta.seeds.len()
    );
    let _ = writeln!(md, "## Claims\n");
    if claims.is_empty() {
        let _ = writeln!(md, "The experiment declares no claims.\n");
    } else {
        let _ = writeln!(md, "| claim | metric | expect | configurations: mean ± se (n) | verdict | weakest step |");
        let _ = writeln!(md, "|---|---|---|---|---|---|");
        for c in claims {
            let metric = match (&c.claim.robot, c.claim.metric, c.claim.k) {
                (r, Metric::TimeToGoalS, k) => format!(
                    "time_to_goal_s (goal {}){}",
                    k.unwrap_or(1),
                    r.as_ref().map_or_else(String::new, |r| format!(", {r}"))
                ),
                (Some(r), m, _) => format!("{} ({r})", m.as_str()),
                (None, m, _) => m.as_str().to_string(),
            };
            let expect = match c.claim.expect {
                Expect::Increasing => "increasing".to_string(),
                Expect::Decreasing => "decreasing".to_string(),
                Expect::Similar => format!("similar (±{:.0} %)", c.claim.tolerance.unwrap_or(0.1) * 100.0),
                Expect::AtLeast | Expect::AtMost => format!(
                    "{} {}{}",
                    if c.claim.expect == Expect::AtLeast { "≥" } else { "≤" },
                    fmt_num(c.claim.value.unwrap_or(f64::NAN)),
                    if c.claim.each_trial { " (every trial)" } else { "" }
                ),
                Expect::RatioAtLeast => {
                    let means: Option<Vec<f64>> = c.stats.iter().map(|s| s.map(|s| s.mean)).collect();
                    format!(
                        "first / second ≥ {} (measured {})",
                        fmt_num(c.claim.value.unwrap_or(f64::NAN)),
                        means.as_deref().and_then(ratio_of).map_or_else(|| "—".to_string(), |r| format!("{r:.2}"))
                    )
                }
            };
            let values: Vec<String> = c
                .claim
                .over
                .iter()
                .zip(&c.stats)
                .map(|(name, s)| match s {
                    Some(s) => format!("{name}: {} ± {} ({})", fmt_num(s.mean), fmt_num(s.se()), s.n),
                    None => format!("{name}: —"),
                })
                .collect();
            let step = c.weakest_step_se.map_or_else(|| "—".to_string(), |s| format!("{s:.1} se"));
            let _ = writeln!(
                md,
                "| {} | {metric} | {expect} | {} | **{}** | {step} |",
                c.claim.name,
                values.join("; "),
                c.verdict
            );
        }
        let _ = writeln!(
            md,
            "\nA verdict compares means (a bound marked \"every trial\": each trial's value); the weakest step (the smallest difference between neighbours in units \
             of their combined standard error) below 2 says the order could be noise.\n"
        );
    }
    let _ = writeln!(md, "## Metrics per configuration\n");
    let _ = write!(md, "| configuration | trials |");
    for m in Metric::ALL {
        let _ = write!(md, " {} |", m.as_str());
    }
    let _ = writeln!(md);
    let _ = writeln!(md, "|---|---|{}", "---|".repeat(Metric::ALL.len()));
    for c in &meta.configurations {
        let n = rows.iter().filter(|r| &r.configuration == c).count();
        let _ = write!(md, "| {c} | {n} |");
        for m in Metric::ALL {
            match table.get(&(c.clone(), m)) {
                Some(s) => {
                    let _ = write!(
                        md,
                        " {} ± {} [{} – {}] |",
                        fmt_num(s.mean),
                        fmt_num(s.sd),
                        fmt_num(s.min),
                        fmt_num(s.max)
                    );
                }
                None => md.push_str(" — |"),
            }
        }
        let _ = writeln!(md);
    }
    // Time to the k-th goal, for every k some trial reached.
    let max_k = rows.iter().map(|r| r.visit_times_s.len()).max().unwrap_or(0).min(20);
    if max_k > 0 {
        let _ = writeln!(
            md,
            "\n## Time to the k-th goal (s)\n\nMean over seeds; a trial that did not reach goal k counts its time limit \
             (the number of trials that did is in brackets).\n"
        );
        let _ = write!(md, "| configuration |");
        for k in 1..=max_k {
            let _ = write!(md, " {k} |");
        }
        let _ = writeln!(md);
        let _ = writeln!(md, "|---|{}", "---|".repeat(max_k));
        for c in &meta.configurations {
            let runs: Vec<&TrialRow> = rows.iter().filter(|r| &r.configuration == c).collect();
            let _ = write!(md, "| {c} |");
            for k in 1..=max_k {
                let values: Vec<f64> =
                    runs.iter().filter_map(|r| r.metric(Metric::TimeToGoalS, k as u32, None)).collect();
                let reached = runs.iter().filter(|r| r.visit_times_s.len() >= k).count();
                match Stats::of(&values) {
                    Some(s) => {
                        let _ = write!(md, " {:.0} ({reached}) |", s.mean);
                    }
                    None => md.push_str(" — |"),
                }
            }
            let _ = writeln!(md);
        }
    }
    let _ = writeln!(md, "\n## Plots\n");
    let _ = writeln!(md, "![goals visited over time](plots/goals_over_time.png)\n");
    let _ = writeln!(md, "![metrics](plots/metrics.png)\n");
    let missing: Vec<String> = meta
        .configurations
        .iter()
        .flat_map(|c| meta.seeds.iter().map(move |s| (c, *s)))
        .filter(|(c, s)| !rows.iter().any(|r| &&r.configuration == c && r.seed == *s))
        .map(|(c, s)| format!("{c}/{s}"))
        .collect();
    if !missing.is_empty() {
        let shown: Vec<&str> = missing.iter().take(30).map(String::as_str).collect();
        let _ = writeln!(md, "## Trials without a row\n\n{} (of {}).\n", shown.join(", "), missing.len());
    }
    md
}

/// Plot colours per configuration.
const COLOURS: [RGBColor; 8] = [
    RGBColor(0, 114, 178),
    RGBColor(213, 94, 0),
    RGBColor(0, 158, 115),
    RGBColor(204, 121, 167),
    RGBColor(230, 159, 0),
    RGBColor(86, 180, 233),
    RGBColor(120, 120, 120),
    RGBColor(0, 0, 0),
];

/// The sets of configurations the claims compare, one plot each (the paper's one figure per
/// ablation): consecutive claims that share a configuration are one set (a study writes the
/// claims of one ablation together), and a set in whose trials no goal was visited is left out
/// (its plot would be empty).
fn claim_groups(meta: &ExperimentMeta, rows: &[TrialRow]) -> Vec<Vec<String>> {
    let mut groups: Vec<Vec<String>> = Vec::new();
    for c in &meta.claims {
        match groups.last_mut() {
            Some(last) if c.over.iter().any(|name| last.contains(name)) => {
                for name in &c.over {
                    if !last.contains(name) {
                        last.push(name.clone());
                    }
                }
            }
            _ => groups.push(c.over.clone()),
        }
    }
    groups.retain(|g| rows.iter().any(|r| g.contains(&r.configuration) && !r.visit_times_s.is_empty()));
    groups
}

fn group_plot_name(index: usize) -> String {
    format!("goals_over_time_{}.png", index + 1)
}

/// The rows the goals-over-time plots can draw (times and counts within [`PLOT_LIMIT`]) and a
/// note for each row left out.
fn rows_to_plot(rows: &[TrialRow]) -> (Vec<TrialRow>, Vec<String>) {
    let mut kept = Vec::with_capacity(rows.len());
    let mut notes = Vec::new();
    for r in rows {
        let bad = [("end_s", r.end_s), ("time_limit_s", r.time_limit_s), ("goals_visited", r.goals_visited as f64)]
            .into_iter()
            .chain(r.visit_times_s.iter().map(|&t| ("visit_times_s", t)))
            .find(|(_, v)| !plottable(*v));
        match bad {
            Some((field, v)) => notes.push(format!(
                "configuration `{}` seed {}: {field} = {v:e}; the trial is left out of the goals-over-time plots",
                r.configuration, r.seed
            )),
            None => kept.push(r.clone()),
        }
    }
    (kept, notes)
}

/// Goals visited over time for `configurations`: per configuration the mean over seeds with a
/// band of ± one standard deviation (the paper's figure style).
fn goals_over_time_plot(title: &str, configurations: &[String], rows: &[TrialRow], path: &Path) -> Result<()> {
    crate::sim_plots::ensure_font()?;
    let rows: Vec<&TrialRow> = rows.iter().filter(|r| configurations.contains(&r.configuration)).collect();
    let t_max = rows.iter().map(|r| r.end_s.max(r.time_limit_s.min(r.end_s))).fold(1.0, f64::max);
    let y_max = rows.iter().map(|r| r.goals_visited).max().unwrap_or(1).max(1) as f64 * 1.1;
    const STEPS: usize = 200;
    crate::output::plot_png(path, (900, 500), |root| {
        root.fill(&WHITE)?;
        let mut chart = ChartBuilder::on(root)
            .caption(title, ("sans-serif", 18))
            .margin(15)
            .x_label_area_size(35)
            .y_label_area_size(45)
            .build_cartesian_2d(0.0..t_max, 0.0..y_max)?;
        chart.configure_mesh().x_desc("time (s)").y_desc("goals visited").draw()?;
        for (i, c) in configurations.iter().enumerate() {
            let runs: Vec<&&TrialRow> = rows.iter().filter(|r| &r.configuration == c).collect();
            if runs.is_empty() {
                continue;
            }
            let colour = COLOURS[i % COLOURS.len()];
            let mut mean = Vec::with_capacity(STEPS + 1);
            let mut upper = Vec::with_capacity(STEPS + 1);
            let mut lower = Vec::with_capacity(STEPS + 1);
            for s in 0..=STEPS {
                let t = t_max * s as f64 / STEPS as f64;
                let counts: Vec<f64> =
                    runs.iter().map(|r| r.visit_times_s.iter().filter(|v| **v <= t).count() as f64).collect();
                if let Some(st) = Stats::of(&counts) {
                    mean.push((t, st.mean));
                    upper.push((t, st.mean + st.sd));
                    lower.push((t, (st.mean - st.sd).max(0.0)));
                }
            }
            let mut band = upper;
            band.extend(lower.into_iter().rev());
            chart.draw_series(std::iter::once(Polygon::new(band, colour.mix(0.2).filled())))?;
            chart
                .draw_series(LineSeries::new(mean, colour.stroke_width(2)))?
                .label(format!("{c} ({} seeds)", runs.len()))
                .legend(move |(x, y)| PathElement::new([(x, y), (x + 15, y)], colour.stroke_width(2)));
        }
        chart
            .configure_series_labels()
            .position(SeriesLabelPosition::UpperLeft)
            .background_style(WHITE.mix(0.8))
            .border_style(BLACK)
            .draw()?;
        Ok(())
    })
}

/// Each metric's mean per configuration, with a bar of ± one standard deviation. Returns a note
/// for each value left out (not within [`PLOT_LIMIT`]).
fn metrics_plot(meta: &ExperimentMeta, table: &Table, path: &Path) -> Result<Vec<String>> {
    crate::sim_plots::ensure_font()?;
    let shown = [
        Metric::GoalsVisited,
        Metric::TimeToGoalS,
        Metric::DistanceM,
        Metric::HeadingToGoalFraction,
        Metric::Collisions,
        Metric::LocalizationErrorM,
        Metric::BytesSent,
        Metric::WallS,
    ];
    let n = meta.configurations.len().max(1);
    let mut notes = Vec::new();
    for metric in shown {
        for c in &meta.configurations {
            if let Some(s) = table.get(&(c.clone(), metric))
                && !(plottable(s.mean - s.sd) && plottable(s.mean + s.sd))
            {
                notes.push(format!(
                    "configuration `{c}`: {} mean {:e} ± {:e}; left out of the metrics plot",
                    metric.as_str(),
                    s.mean,
                    s.sd
                ));
            }
        }
    }
    crate::output::plot_png(path, (1200, 700), |root| {
        root.fill(&WHITE)?;
        let areas = root.split_evenly((2, 4));
        for (area, metric) in areas.iter().zip(shown) {
            let values: Vec<(usize, Stats)> = meta
                .configurations
                .iter()
                .enumerate()
                .filter_map(|(i, c)| table.get(&(c.clone(), metric)).map(|s| (i, *s)))
                .filter(|(_, s)| plottable(s.mean - s.sd) && plottable(s.mean + s.sd))
                .collect();
            let highest = values.iter().map(|(_, s)| s.mean + s.sd).fold(0.0, f64::max);
            // An all-zero metric still gets a readable axis.
            let top = if highest > 0.0 { highest * 1.15 } else { 1.0 };
            let bottom = values.iter().map(|(_, s)| s.mean - s.sd).fold(0.0, f64::min);
            let mut chart = ChartBuilder::on(area)
                .caption(metric.as_str(), ("sans-serif", 15))
                .margin(8)
                .x_label_area_size(20)
                .y_label_area_size(50)
                .build_cartesian_2d(-0.5..(n as f64 - 0.5), bottom..top)?;
            chart
                .configure_mesh()
                .disable_x_mesh()
                .x_labels(n)
                .x_label_formatter(&|x| {
                    let i = x.round();
                    if (x - i).abs() < 1e-6 && i >= 0.0 {
                        meta.configurations.get(i as usize).cloned().unwrap_or_default()
                    } else {
                        String::new()
                    }
                })
                .draw()?;
            for (i, s) in values {
                let colour = COLOURS[i % COLOURS.len()];
                let x = i as f64;
                chart.draw_series(std::iter::once(Rectangle::new(
                    [(x - 0.3, 0.0), (x + 0.3, s.mean)],
                    colour.mix(0.6).filled(),
                )))?;
                chart.draw_series(std::iter::once(PathElement::new(
                    [(x, s.mean - s.sd), (x, s.mean + s.sd)],
                    BLACK.stroke_width(2),
                )))?;
            }
        }
        Ok(())
    })?;
    Ok(notes)
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;

    fn row(configuration: &str, seed: u64, goals: usize) -> TrialRow {
        TrialRow {
            trial: 0,
            configuration: configuration.into(),
            seed,
            config_hash: "h".into(),
            mission: "m".into(),
            outcome: "time_limit".into(),
            end_s: 100.0,
            time_limit_s: 100.0,
            ugvs: 1,
            goals_total: 10,
            goals_visited: goals,
            clusters_total: None,
            clusters_visited: None,
            visit_times_s: (0..goals).map(|k| 10.0 * (k + 1) as f64).collect(),
            distance_m: 10.0,
            heading_to_goal_fraction: 0.5,
            collisions: 0,
            localization_error_m: None,
            bytes_sent: 100 * goals as u64,
            bytes_sent_full_links: 0,
            bytes_sent_small_links: 0,
            bytes_sent_coordination: 0,
            bytes_sent_scans: 0,
            bytes_sent_maps: 0,
            wall_s: 1.0,
            robots: Vec::new(),
            deployed: None,
            process_problems: Vec::new(),
        }
    }

    fn claim(expect: Expect, metric: Metric, over: &[&str]) -> Claim {
        Claim {
            name: "c".into(),
            metric,
            k: None,
            robot: None,
            expect,
            over: over.iter().map(|s| s.to_string()).collect(),
            tolerance: None,
            value: None,
            each_trial: false,
        }
    }

    #[test]
    fn stats_are_the_sample_ones() {
        let s = Stats::of(&[1.0, 2.0, 3.0, 4.0]).unwrap();
        assert_eq!((s.n, s.mean, s.min, s.max), (4, 2.5, 1.0, 4.0));
        assert!((s.sd - 1.290_994_448_7).abs() < 1e-9);
        assert!(Stats::of(&[]).is_none());
    }

    #[test]
    fn claims_of_one_ablation_share_a_plot_and_sets_without_visits_get_none() {
        let meta = ExperimentMeta {
            claims: vec![
                claim(Expect::Increasing, Metric::GoalsVisited, &["a1", "a3"]),
                claim(Expect::Decreasing, Metric::TimeToGoalS, &["a1", "a3", "a5"]),
                claim(Expect::Increasing, Metric::GoalsVisited, &["off", "on"]),
                claim(Expect::Decreasing, Metric::EndS, &["relay-none", "relay-all"]),
            ],
            experiment: "e".into(),
            configurations: ["a1", "a3", "a5", "off", "on", "relay-none", "relay-all"].map(String::from).to_vec(),
            seeds: vec![1],
        };
        let mut rows: Vec<TrialRow> = ["a1", "a3", "a5", "off", "on"].iter().map(|c| row(c, 1, 2)).collect();
        rows.extend(["relay-none", "relay-all"].iter().map(|c| row(c, 1, 0)));
        assert_eq!(claim_groups(&meta, &rows), vec![vec!["a1", "a3", "a5"], vec!["off", "on"]]);
    }

    fn uav(distance_m: f64) -> rows::RobotRow {
        rows::RobotRow {
            id: "uav1".into(),
            kind: "uav".into(),
            distance_m,
            goals_visited: 0,
            visit_times_s: Vec::new(),
            heading_to_goal_fraction: 0.0,
            collisions: 0,
            localization_error_m: None,
            bytes_sent: 0,
            travel_time_s: None,
            tree_status: "running".into(),
            stuck_events: 0,
            longest_motionless_driving_s: 0.0,
        }
    }

    #[test]
    fn deployed_rows_are_set_beside_the_in_process_rows_of_their_seeds() {
        let inside = |seed, clusters, uav_m| {
            let mut r = row("c", seed, clusters);
            r.clusters_visited = Some(clusters);
            r.robots = vec![uav(uav_m)];
            r
        };
        let (a, b) = (inside(1, 4, 1000.0), inside(2, 6, 3000.0));
        let deployed = |r: &TrialRow, clusters, uav_m| {
            let mut d = inside(r.seed, clusters, uav_m);
            d.deployed = Some(TeamChannel::Zenoh);
            d.wall_s = 99.0;
            d
        };
        // Seed 1 did worse deployed; seed 2 the same (wall time aside); seed 3 has no partner.
        let (da, db) = (deployed(&a, 3, 600.0), deployed(&b, 6, 3000.0));
        let mut dc = deployed(&a, 1, 1.0);
        dc.seed = 3;
        dc.process_problems = vec!["ugv2 dropped at 5.0 s".into()];
        let c = deployed_comparisons(&["c".into()], &[a, b.clone(), da, db.clone(), dc]);
        assert_eq!(c.len(), 1);
        let c = &c[0];
        assert_eq!((c.channel, c.pairs.len(), c.unpaired_seeds.clone()), (TeamChannel::Zenoh, 2, vec![3]));
        assert_eq!(c.clusters_visited, (5.0, 4.5));
        assert_eq!(c.clusters_ratio, Some(0.9));
        assert_eq!(c.uav_distance_m, (2000.0, 1800.0));
        assert_eq!(c.uav_distance_ratio, Some(0.9));
        assert_eq!(c.pairs.iter().map(|p| p.identical).collect::<Vec<_>>(), [false, true]);
        // Regression: processes that never ran leave the farm simulating the robots, a row equal
        // to the in-process one; that is no evidence of identity.
        let mut failed = db.clone();
        failed.process_problems = vec!["ugv1's process exited with exit status: 2".into()];
        let f = deployed_comparisons(&["c".into()], &[b.clone(), failed]);
        assert_eq!(f[0].pairs.iter().map(|p| p.identical).collect::<Vec<_>>(), [false]);
        let md = deployed_markdown(std::slice::from_ref(c));
        assert!(md.contains("| c | zenoh | 2 | 5.00 | 4.50 | 0.900 |"), "{md}");
        assert!(md.contains("c/3 (zenoh)"), "{md}");
        // No deployed rows: no section.
        assert!(deployed_markdown(&deployed_comparisons(&["c".into()], &[row("c", 1, 2)])).is_empty());
    }

    #[test]
    fn claims_get_their_verdicts() {
        let rows = vec![row("a", 1, 2), row("a", 2, 4), row("b", 1, 5), row("b", 2, 7), row("c", 1, 7)];
        assert_eq!(check_claim(&claim(Expect::Increasing, Metric::GoalsVisited, &["a", "b"]), &rows).verdict, "holds");
        assert_eq!(check_claim(&claim(Expect::Decreasing, Metric::GoalsVisited, &["a", "b"]), &rows).verdict, "fails");
        // b: mean 6, c: 7 → within 20 % but not 10 %.
        let mut similar = claim(Expect::Similar, Metric::GoalsVisited, &["b", "c"]);
        assert_eq!(check_claim(&similar, &rows).verdict, "fails");
        similar.tolerance = Some(0.2);
        assert_eq!(check_claim(&similar, &rows).verdict, "holds");
        assert_eq!(
            check_claim(&claim(Expect::Increasing, Metric::GoalsVisited, &["a", "zz"]), &rows).verdict,
            "no data"
        );
        // Time to the first goal is the same (10 s) everywhere: neither increasing nor decreasing.
        assert_eq!(check_claim(&claim(Expect::Decreasing, Metric::TimeToGoalS, &["a", "b"]), &rows).verdict, "fails");
        let step = check_claim(&claim(Expect::Increasing, Metric::GoalsVisited, &["a", "b"]), &rows).weakest_step_se;
        // Means 3 and 6, sds √2 each, n 2 each: se of the difference is √2, the step 3/√2.
        assert!((step.unwrap() - 3.0 / 2f64.sqrt()).abs() < 1e-9);
    }

    #[test]
    fn bounds_hold_on_the_means_or_on_every_trial() {
        // a: goals 2 and 4 (mean 3); b: 5 and 7 (mean 6).
        let rows = vec![row("a", 1, 2), row("a", 2, 4), row("b", 1, 5), row("b", 2, 7)];
        let bound = |expect, value, each_trial, over: &[&str]| {
            let mut c = claim(expect, Metric::GoalsVisited, over);
            c.value = Some(value);
            c.each_trial = each_trial;
            check_claim(&c, &rows)
        };
        assert_eq!(bound(Expect::AtLeast, 3.0, false, &["a", "b"]).verdict, "holds");
        assert_eq!(bound(Expect::AtLeast, 3.0, true, &["a", "b"]).verdict, "fails", "a's seed 1 visited 2");
        assert_eq!(bound(Expect::AtLeast, 5.0, true, &["b"]).verdict, "holds");
        assert_eq!(bound(Expect::AtMost, 6.0, false, &["a", "b"]).verdict, "holds");
        assert_eq!(bound(Expect::AtMost, 6.0, true, &["b"]).verdict, "fails", "b's seed 2 visited 7");
        assert_eq!(bound(Expect::AtMost, 6.0, true, &["zz"]).verdict, "no data");
        assert_eq!(bound(Expect::AtMost, 6.0, false, &["b"]).weakest_step_se, None);
    }

    #[test]
    fn a_ratio_claim_holds_when_the_first_mean_is_that_multiple_of_the_second() {
        // a: goals 2 and 4 (mean 3); b: 5 and 7 (mean 6); z: 0 (mean 0).
        let rows = vec![row("a", 1, 2), row("a", 2, 4), row("b", 1, 5), row("b", 2, 7), row("z", 1, 0)];
        let ratio = |value, over: &[&str]| {
            let mut c = claim(Expect::RatioAtLeast, Metric::GoalsVisited, over);
            c.value = Some(value);
            check_claim(&c, &rows)
        };
        assert_eq!(ratio(2.0, &["b", "a"]).verdict, "holds", "6 / 3 = 2");
        assert_eq!(ratio(2.01, &["b", "a"]).verdict, "fails");
        assert_eq!(ratio(1.0, &["a", "b"]).verdict, "fails", "3 / 6 = 0.5");
        assert_eq!(ratio(0.1, &["a", "z"]).verdict, "fails", "no ratio to a mean of 0");
        assert_eq!(ratio(2.0, &["b", "zz"]).verdict, "no data");
        assert_eq!(ratio(2.0, &["b", "a"]).weakest_step_se, None);
        assert_eq!(ratio_of(&[6.0, 3.0]), Some(2.0));
        assert_eq!(ratio_of(&[6.0]), None);
    }
}
