//! Experiment files: the typed file, its checks, and its resolution into trials — one patched
//! mission per configuration, validated by the mission language itself, so a bad override is a
//! located error like any mission error.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};
use spomp_behaviors::NodeRegistry;
use spomp_behaviors::mission::limits;
use spomp_behaviors::mission::schema::{FaultSpec, LocalizationSpec, RobotSpec, SimSpec, StartPose, WorldSpec};
use spomp_behaviors::mission::yaml::{Loc, Node, PathSeg, parse};
use spomp_behaviors::mission::{Diagnostic, LoadOptions, LoadedMission, MissionFile, Stage, load_mission_str};
use spomp_core::RobotKind;
use spomp_robot::RobotRuntime;

/// Most trials one experiment file may declare (configurations × seeds).
pub const MAX_TRIALS: usize = 100_000;

/// Version of the trial rows and of what a configuration hash covers; bumped when either
/// changes meaning, so rows of an older spomp are not taken as complete.
pub const ROW_FORMAT: u32 = 1;

/// An experiment: a base mission, configurations that patch it, seeds, and the claims the
/// report checks.
#[derive(Debug, Clone, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct ExperimentFile {
    /// Experiment name (the default output folder is `runs/experiments/<name>`).
    pub experiment: String,
    /// What the experiment is for.
    #[serde(default)]
    pub description: Option<String>,
    /// Base mission, relative to this file; a configuration may name its own.
    #[serde(default)]
    pub mission: Option<String>,
    /// Seeds every configuration runs with: a list (`[1, 2, 3]`) or an inclusive range
    /// (`{ from: 1, to: 10 }`).
    pub seeds: Seeds,
    /// Time limit of every trial, seconds (a configuration's own wins; default: the mission's).
    #[serde(default)]
    pub time_limit_s: Option<f64>,
    /// The variations, each run over every seed. Names are unique.
    pub configurations: Vec<Configuration>,
    /// Directional claims the report checks over the configurations' means.
    #[serde(default)]
    pub claims: Vec<Claim>,
}

/// Seeds: a list or an inclusive range.
#[derive(Debug, Clone, Serialize, Deserialize, JsonSchema)]
#[serde(untagged)]
pub enum Seeds {
    /// These seeds, in this order.
    List(Vec<u64>),
    /// `from` to `to`, both included.
    Range(SeedRange),
}

/// An inclusive seed range.
#[derive(Debug, Clone, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct SeedRange {
    /// First seed.
    pub from: u64,
    /// Last seed (included).
    pub to: u64,
}

impl Seeds {
    /// The seeds in order (a range too large to list yields its first `MAX_TRIALS + 1`, which
    /// the checks refuse).
    pub fn values(&self) -> Vec<u64> {
        match self {
            Seeds::List(v) => v.clone(),
            Seeds::Range(r) => (r.from..=r.to).take(MAX_TRIALS + 1).collect(),
        }
    }
}

/// One configuration: overrides applied to the base mission, each a typed patch of the mission
/// structure; the patched mission then goes through the mission language's validation.
#[derive(Debug, Clone, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Configuration {
    /// Unique name (letters, digits, `_`, `-`, `.`), used in rows, tables and claims.
    pub name: String,
    /// What the configuration varies.
    #[serde(default)]
    pub description: Option<String>,
    /// Base mission of this configuration, relative to the experiment file (default: the
    /// experiment's `mission`).
    #[serde(default)]
    pub mission: Option<String>,
    /// Team size: this many UGVs. The base mission's first ones are kept in team order; more
    /// are copies of the UGV template with ids `ugv<N>`, the next free priorities and start
    /// poses from `starts` or on a grid beside the template (3 m along its heading, 5 m
    /// across).
    #[serde(default)]
    pub ugvs: Option<u32>,
    /// Id of the UGV the added UGVs copy (default: the base mission's first UGV).
    #[serde(default)]
    pub ugv_template: Option<String>,
    /// Start poses of the added UGVs, in order (the grid is used past the list's end).
    #[serde(default)]
    pub starts: Vec<StartPose>,
    /// `navigation:` settings merged, key by key, into every UGV's own `navigation:` (the
    /// mission language's section: `global_planner: { learning: off, graph_updates: off,
    /// sharing: none }`, `terrain`, `control`, …).
    #[serde(default)]
    pub navigation: Option<serde_json::Value>,
    /// Per role: `navigation:` merged into the role's section.
    #[serde(default)]
    pub roles: BTreeMap<String, RoleOverride>,
    /// Per robot id: settings of that robot (applied after the team-wide ones).
    #[serde(default)]
    pub robots: BTreeMap<String, RobotOverride>,
    /// Localization of every UGV (replaces the base mission's).
    #[serde(default)]
    pub localization: Option<LocalizationSpec>,
    /// Radio settings (each given field replaces the mission's).
    #[serde(default)]
    pub comms: Option<CommsOverride>,
    /// Faults added to the mission's `sim.faults`.
    #[serde(default)]
    pub faults: Vec<FaultSpec>,
    /// The world (replaces the mission's `sim.world`): `{ generate: {...} }` or `{ dir: PATH }`
    /// with PATH relative to the experiment file.
    #[serde(default)]
    pub world: Option<WorldSpec>,
    /// Every robot starts with the whole aerial map (the mission's `sim.prior_map`).
    #[serde(default)]
    pub prior_map: Option<bool>,
    /// Time limit of this configuration's trials, seconds.
    #[serde(default)]
    pub time_limit_s: Option<f64>,
    /// Also run each of this configuration's trials deployed, once per team channel listed
    /// (`radio`: the farm's radio model; `zenoh`: the signed Zenoh link): the simulator as a
    /// lockstep robot farm and one `spomp run` process per robot, as robots run the mission.
    /// The rows say which; `spomp experiment report` sets them beside the in-process rows.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub deployed: Vec<TeamChannel>,
}

/// How the robot processes of a deployed trial exchange their team state.
#[derive(
    Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize, JsonSchema, clap::ValueEnum,
)]
#[serde(rename_all = "snake_case")]
pub enum TeamChannel {
    /// Over the farm's radio model, as in the simulator (a lockstep run is then the in-process
    /// run, bit for bit).
    Radio,
    /// Over the signed Zenoh link between the processes (keys generated per trial), in real
    /// time: what robots do.
    Zenoh,
}

impl TeamChannel {
    /// Every channel, in the order of trial indices.
    pub const ALL: [TeamChannel; 2] = [TeamChannel::Radio, TeamChannel::Zenoh];

    /// The channel's name in rows and reports.
    pub fn as_str(self) -> &'static str {
        match self {
            TeamChannel::Radio => "radio",
            TeamChannel::Zenoh => "zenoh",
        }
    }
}

impl std::fmt::Display for TeamChannel {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.as_str())
    }
}

/// Overrides of one role.
#[derive(Debug, Clone, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct RoleOverride {
    /// Merged, key by key, into the role's `navigation:`.
    #[serde(default)]
    pub navigation: Option<serde_json::Value>,
}

/// Overrides of one robot.
#[derive(Debug, Clone, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct RobotOverride {
    /// Merged, key by key, into the robot's `navigation:`.
    #[serde(default)]
    pub navigation: Option<serde_json::Value>,
    /// The robot's localization (replaces its own).
    #[serde(default)]
    pub localization: Option<LocalizationSpec>,
}

/// Radio settings to replace; absent fields keep the mission's.
#[derive(Debug, Clone, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct CommsOverride {
    /// Within this range robots exchange positions and claims, metres.
    #[serde(default)]
    pub position_range_m: Option<f64>,
    /// Within this range robots exchange everything, metres.
    #[serde(default)]
    pub data_range_m: Option<f64>,
    /// Bytes per second per link.
    #[serde(default)]
    pub bandwidth_bytes_per_s: Option<f64>,
    /// Direct UGV-to-UGV links.
    #[serde(default)]
    pub ugv_to_ugv: Option<bool>,
}

/// A claim over configurations: the means of `metric` over seeds, in the order of `over`, are
/// expected to rise, fall or stay alike; or each configuration's mean (or, with `each_trial`,
/// every trial's value) is expected at least or at most a bound (an acceptance threshold); or
/// the first of two configurations' means is expected at least a multiple of the second's.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Claim {
    /// What the claim says, in words.
    pub name: String,
    /// The metric compared.
    pub metric: Metric,
    /// With `time_to_goal_s`: which goal (the k-th visited, from 1; default 1).
    #[serde(default)]
    pub k: Option<u32>,
    /// Take the metric of this robot instead of the team's (`distance_m`,
    /// `heading_to_goal_fraction`, `collisions`, `goals_visited`, `time_to_goal_s`,
    /// `bytes_sent`).
    #[serde(default)]
    pub robot: Option<String>,
    /// How the means relate along `over`.
    pub expect: Expect,
    /// Configuration names in the order the expectation reads them: at least two, one is
    /// enough for `at_least` and `at_most`, exactly two for `ratio_at_least`.
    pub over: Vec<String>,
    /// With `similar`: largest relative difference from the first mean (default 0.1).
    #[serde(default)]
    pub tolerance: Option<f64>,
    /// With `at_least` / `at_most` (required there): the bound, in the metric's unit. With
    /// `ratio_at_least` (required there): the least ratio of the first mean to the second, a
    /// positive number.
    #[serde(default)]
    pub value: Option<f64>,
    /// With `at_least` / `at_most`: hold the bound on every trial's value instead of each
    /// configuration's mean (default false).
    #[serde(default)]
    pub each_trial: bool,
}

/// How a claim's means relate.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum Expect {
    /// Each mean is larger than the one before.
    Increasing,
    /// Each mean is smaller than the one before.
    Decreasing,
    /// Every mean is within `tolerance` (relative) of the first.
    Similar,
    /// Every mean (with `each_trial`, every trial's value) is at least `value`.
    AtLeast,
    /// Every mean (with `each_trial`, every trial's value) is at most `value`.
    AtMost,
    /// The first configuration's mean is at least `value` times the second's (exactly two
    /// configurations; the second's mean positive): e.g. how many times longer the trip takes
    /// without an ablated feature than with it.
    RatioAtLeast,
}

/// A per-trial metric.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum Metric {
    /// Goals visited.
    GoalsVisited,
    /// Visited share of the world's vehicle clusters (generated worlds), else of the goals.
    VisitedFraction,
    /// Time of the k-th goal visit, seconds (a trial that never got there counts its time
    /// limit).
    TimeToGoalS,
    /// Simulated time at the end, seconds.
    EndS,
    /// Distance driven, metres (mean over UGVs; a robot's own with `robot`).
    DistanceM,
    /// Fraction of time heading to a goal (mean over UGVs).
    HeadingToGoalFraction,
    /// Collisions (sum over UGVs).
    Collisions,
    /// Localization error, metres (mean over UGVs of each one's median).
    LocalizationErrorM,
    /// Team-state bytes sent (sum over robots).
    BytesSent,
    /// Of those, the scan tier's: shared reachability scans (sum over robots).
    BytesSentScans,
    /// Seconds from a robot's first motion to its last: for a robot sent on one trip, the trip
    /// (mean over UGVs; a robot's own with `robot`).
    TravelTimeS,
    /// Stuck events: times the simulator refused every commanded motion of a UGV for its stuck
    /// timeout (sum over UGVs; a robot's own with `robot`).
    StuckEvents,
    /// Longest time a UGV stood still while its tree was driving it, seconds (the largest over
    /// UGVs; a robot's own with `robot`).
    LongestMotionlessDrivingS,
    /// Wall-clock seconds of the trial.
    WallS,
}

impl Metric {
    /// Every metric, in report order.
    pub const ALL: [Metric; 14] = [
        Metric::GoalsVisited,
        Metric::VisitedFraction,
        Metric::TimeToGoalS,
        Metric::EndS,
        Metric::DistanceM,
        Metric::HeadingToGoalFraction,
        Metric::Collisions,
        Metric::LocalizationErrorM,
        Metric::BytesSent,
        Metric::BytesSentScans,
        Metric::TravelTimeS,
        Metric::StuckEvents,
        Metric::LongestMotionlessDrivingS,
        Metric::WallS,
    ];

    /// The name written in files.
    pub fn as_str(self) -> &'static str {
        match self {
            Metric::GoalsVisited => "goals_visited",
            Metric::VisitedFraction => "visited_fraction",
            Metric::TimeToGoalS => "time_to_goal_s",
            Metric::EndS => "end_s",
            Metric::DistanceM => "distance_m",
            Metric::HeadingToGoalFraction => "heading_to_goal_fraction",
            Metric::Collisions => "collisions",
            Metric::LocalizationErrorM => "localization_error_m",
            Metric::BytesSent => "bytes_sent",
            Metric::BytesSentScans => "bytes_sent_scans",
            Metric::TravelTimeS => "travel_time_s",
            Metric::StuckEvents => "stuck_events",
            Metric::LongestMotionlessDrivingS => "longest_motionless_driving_s",
            Metric::WallS => "wall_s",
        }
    }

    /// Whether a robot's own value exists.
    pub fn per_robot(self) -> bool {
        matches!(
            self,
            Metric::DistanceM
                | Metric::HeadingToGoalFraction
                | Metric::Collisions
                | Metric::GoalsVisited
                | Metric::TimeToGoalS
                | Metric::BytesSent
                | Metric::TravelTimeS
                | Metric::StuckEvents
                | Metric::LongestMotionlessDrivingS
        )
    }
}

/// A configuration resolved: its patched, validated mission and what identifies its trials.
#[derive(Debug)]
pub struct ResolvedConfiguration {
    /// The configuration's name.
    pub name: String,
    /// The patched mission, loaded and valid.
    pub loaded: LoadedMission,
    /// The patched mission's text (JSON), whose relative paths resolve in the base mission's
    /// folder: what a deployed trial's robot processes load.
    pub patched: String,
    /// Hash of what its trials depend on besides the seed (see [`trial_hash`]).
    pub hash_input: String,
}

/// One trial: a configuration and a seed, run in-process or deployed.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Trial {
    /// Index in the experiment: configuration index × number of seeds + seed index for an
    /// in-process trial; a deployed one's is its in-process trial's plus the number of
    /// in-process trials times 1 (radio) or 2 (zenoh) (see [`deployed_trial`]).
    pub index: usize,
    /// Index of its configuration.
    pub configuration: usize,
    /// Seed.
    pub seed: u64,
    /// Run deployed over this team channel; `None`: in-process.
    pub deployed: Option<TeamChannel>,
}

/// The deployed trial of in-process trial `trial` over `channel`, in an experiment of
/// `in_process` in-process trials: its index follows every in-process one, so indices (and
/// shards) do not depend on which channels a run selects.
pub fn deployed_trial(trial: &Trial, channel: TeamChannel, in_process: usize) -> Trial {
    let k = TeamChannel::ALL.iter().position(|c| *c == channel).unwrap_or(0) + 1;
    Trial { index: trial.index + in_process * k, deployed: Some(channel), ..trial.clone() }
}

/// An experiment file loaded: the typed file, its resolved configurations and its trials, or
/// every problem found.
#[derive(Debug, Default)]
pub struct LoadedExperiment {
    /// The typed file, if it parsed.
    pub file: Option<ExperimentFile>,
    /// Configurations in file order (all of them when the experiment is valid).
    pub configurations: Vec<ResolvedConfiguration>,
    /// Every trial in index order.
    pub trials: Vec<Trial>,
    /// Problems, with their place.
    pub diagnostics: Vec<Diagnostic>,
    /// Source text of each file diagnostics may point into.
    pub sources: BTreeMap<PathBuf, String>,
}

impl LoadedExperiment {
    /// Whether the experiment can run.
    pub fn is_valid(&self) -> bool {
        self.diagnostics.is_empty() && self.file.is_some()
    }

    /// The seeds, in order.
    pub fn seeds(&self) -> Vec<u64> {
        self.file.as_ref().map(|f| f.seeds.values()).unwrap_or_default()
    }
}

/// The location of the node at `path` in `root`, or of the deepest node on the way.
fn loc_at(root: &Node, path: &[PathSeg]) -> Loc {
    let mut node = root;
    for seg in path {
        let next = match seg {
            PathSeg::Key(k) => node.get(k),
            PathSeg::Index(i) => node.as_seq().and_then(|s| s.get(*i)),
        };
        match next {
            Some(n) => node = n,
            None => break,
        }
    }
    node.loc
}

fn key(k: &str) -> PathSeg {
    PathSeg::Key(k.to_string())
}

/// Collects located problems of one experiment file.
struct Problems<'a> {
    file: &'a Path,
    root: &'a Node,
    list: Vec<Diagnostic>,
}

impl Problems<'_> {
    fn at(&mut self, path: &[PathSeg], stage: Stage, message: impl Into<String>) {
        let loc = loc_at(self.root, path);
        let shown = spomp_behaviors::mission::yaml::render_path(path);
        self.list.push(Diagnostic::new(self.file, loc, shown, stage, message));
    }
}

/// Loads an experiment file and resolves every configuration against the node registry.
pub fn load_experiment(
    path: &Path,
    registry: &NodeRegistry<RobotRuntime>,
    allowed_dirs: &[PathBuf],
) -> LoadedExperiment {
    let mut out = LoadedExperiment::default();
    let text = match limits::read_text(path, limits::MAX_SOURCE_BYTES) {
        Ok(t) => t,
        Err(e) => {
            let (line, column) = e.position().unwrap_or((1, 1));
            let loc = Loc { line, column, offset: None, len: 0 };
            out.diagnostics.push(Diagnostic::new(
                path,
                loc,
                "",
                Stage::Parse,
                format!("cannot read the experiment: {e}"),
            ));
            out.sources.insert(path.to_path_buf(), String::new());
            return out;
        }
    };
    out.sources.insert(path.to_path_buf(), text.clone());
    let root = match parse(&text) {
        Ok(n) => n,
        Err(e) => {
            out.diagnostics.push(Diagnostic::new(path, e.loc, "", Stage::Parse, e.message));
            return out;
        }
    };
    let file: ExperimentFile = match root.deserialize() {
        Ok(f) => f,
        Err(e) => {
            let loc = e.loc.unwrap_or_else(|| loc_at(&root, &e.path));
            let message = if matches!(e.path.last(), Some(PathSeg::Key(k)) if k == "seeds") {
                "seeds are a list (`[1, 2, 3]`) or an inclusive range (`{ from: 1, to: 10 }`)".to_string()
            } else {
                e.message.clone()
            };
            out.diagnostics.push(Diagnostic::new(path, loc, e.path_string(), Stage::Schema, message));
            return out;
        }
    };
    let mut problems = Problems { file: path, root: &root, list: Vec::new() };
    check_file(&file, &mut problems);
    if problems.list.is_empty() {
        let dir = path.parent().map(Path::to_path_buf).unwrap_or_default();
        let mut options = LoadOptions { allowed_dirs: vec![dir.clone()] };
        options.allowed_dirs.extend(allowed_dirs.iter().cloned());
        for (i, c) in file.configurations.iter().enumerate() {
            if let Some(r) = resolve(&file, i, c, &dir, &options, registry, &mut problems, &mut out.sources) {
                out.configurations.push(r);
            }
        }
        if problems.list.is_empty() {
            check_claim_robots(&file, &out.configurations, &mut problems);
        }
    }
    out.diagnostics = problems.list;
    out.diagnostics.sort_by(|a, b| (&a.file, a.line, a.column).cmp(&(&b.file, b.line, b.column)));
    if out.diagnostics.is_empty() {
        let seeds = file.seeds.values();
        for c in 0..file.configurations.len() {
            for (s, &seed) in seeds.iter().enumerate() {
                out.trials.push(Trial { index: c * seeds.len() + s, configuration: c, seed, deployed: None });
            }
        }
        let in_process = out.trials.len();
        for (c, configuration) in file.configurations.iter().enumerate() {
            for channel in TeamChannel::ALL.iter().filter(|ch| configuration.deployed.contains(ch)) {
                let deployed: Vec<Trial> = out.trials[..in_process]
                    .iter()
                    .filter(|t| t.configuration == c)
                    .map(|t| deployed_trial(t, *channel, in_process))
                    .collect();
                out.trials.extend(deployed);
            }
        }
        out.trials.sort_by_key(|t| t.index);
    }
    out.file = Some(file);
    out
}

/// Whether a configuration name is plain (it lands in CSV rows, Markdown tables and claims).
fn plain_name(name: &str) -> bool {
    !name.is_empty()
        && name.len() <= limits::MAX_IDENTIFIER_LEN
        && name.chars().all(|c| c.is_ascii_alphanumeric() || matches!(c, '_' | '-' | '.'))
}

/// The checks that need no mission: names, seeds, claims.
fn check_file(file: &ExperimentFile, p: &mut Problems<'_>) {
    if let Err(e) = limits::check_identifier("the experiment name", &file.experiment) {
        p.at(&[key("experiment")], Stage::Schema, e);
    }
    let seeds = file.seeds.values();
    if seeds.is_empty() {
        p.at(&[key("seeds")], Stage::Schema, "expected at least one seed (a range needs from ≤ to)");
    }
    let mut seen_seeds = BTreeSet::new();
    for (i, s) in seeds.iter().enumerate() {
        if !seen_seeds.insert(*s) {
            p.at(&[key("seeds"), PathSeg::Index(i)], Stage::Schema, format!("seed {s} is listed twice"));
        }
    }
    if let Some(t) = file.time_limit_s
        && let Err(e) = limits::check_time_limit(t)
    {
        p.at(&[key("time_limit_s")], Stage::Schema, e);
    }
    if file.configurations.is_empty() {
        p.at(&[key("configurations")], Stage::Schema, "expected at least one configuration");
    }
    if seeds.len().saturating_mul(file.configurations.len()) > MAX_TRIALS {
        p.at(
            &[key("seeds")],
            Stage::Schema,
            format!(
                "{} configurations × {} seeds is more than the {MAX_TRIALS} trials an experiment may have",
                file.configurations.len(),
                seeds.len()
            ),
        );
    }
    let mut names = BTreeSet::new();
    for (i, c) in file.configurations.iter().enumerate() {
        let at = |k: &str| vec![key("configurations"), PathSeg::Index(i), key(k)];
        if !plain_name(&c.name) {
            p.at(
                &at("name"),
                Stage::Schema,
                format!(
                    "`{}` is not a configuration name: use 1 to {} letters, digits, `_`, `-` or `.`",
                    c.name,
                    limits::MAX_IDENTIFIER_LEN
                ),
            );
        } else if !names.insert(c.name.as_str()) {
            p.at(&at("name"), Stage::Schema, format!("configuration `{}` is defined twice", c.name));
        }
        if c.mission.is_none() && file.mission.is_none() {
            p.at(
                &[key("configurations"), PathSeg::Index(i)],
                Stage::Schema,
                "no base mission: give the experiment's `mission` or this configuration's",
            );
        }
        if let Some(n) = c.ugvs
            && (n == 0 || n as usize > limits::MAX_ROBOTS)
        {
            p.at(&at("ugvs"), Stage::Schema, format!("expected 1 to {} UGVs, found {n}", limits::MAX_ROBOTS));
        }
        if let Some(t) = c.time_limit_s
            && let Err(e) = limits::check_time_limit(t)
        {
            p.at(&at("time_limit_s"), Stage::Schema, e);
        }
        if !c.starts.is_empty() && c.ugvs.is_none() {
            p.at(&at("starts"), Stage::Schema, "`starts` places added UGVs: give `ugvs` too");
        }
        for (k, v) in [("navigation", &c.navigation)] {
            if let Some(v) = v
                && !v.is_object()
            {
                p.at(&at(k), Stage::Schema, "expected a mapping of navigation settings");
            }
        }
    }
    for (i, claim) in file.claims.iter().enumerate() {
        let at = |k: &str| vec![key("claims"), PathSeg::Index(i), key(k)];
        let bound = matches!(claim.expect, Expect::AtLeast | Expect::AtMost);
        let ratio = claim.expect == Expect::RatioAtLeast;
        if ratio && claim.over.len() != 2 {
            p.at(&at("over"), Stage::Schema, "`ratio_at_least` compares exactly two configurations (first / second)");
        } else if claim.over.len() < 2 && !bound {
            p.at(&at("over"), Stage::Schema, "a claim compares at least two configurations");
        }
        if claim.over.is_empty() && bound {
            p.at(&at("over"), Stage::Schema, "a claim names at least one configuration");
        }
        match (bound || ratio, claim.value) {
            (true, None) if ratio => {
                p.at(&at("value"), Stage::Schema, "`ratio_at_least` needs the least ratio `value`")
            }
            (true, None) => p.at(&at("value"), Stage::Schema, "`at_least` and `at_most` need the bound `value`"),
            (true, Some(v)) if !v.is_finite() => p.at(&at("value"), Stage::Schema, "expected a finite number"),
            (true, Some(v)) if ratio && v <= 0.0 => {
                p.at(&at("value"), Stage::Schema, "expected a positive ratio");
            }
            (false, Some(_)) => {
                p.at(&at("value"), Stage::Schema, "`value` goes with `expect: at_least`, `at_most` or `ratio_at_least`")
            }
            _ => {}
        }
        if claim.each_trial && !bound {
            p.at(&at("each_trial"), Stage::Schema, "`each_trial` goes with `expect: at_least` or `at_most`");
        }
        for (j, name) in claim.over.iter().enumerate() {
            if !file.configurations.iter().any(|c| &c.name == name) {
                let known: Vec<&str> = file.configurations.iter().map(|c| c.name.as_str()).collect();
                p.at(
                    &[key("claims"), PathSeg::Index(i), key("over"), PathSeg::Index(j)],
                    Stage::Schema,
                    format!("no configuration `{name}`; configurations are: {}", known.join(", ")),
                );
            }
        }
        if claim.k.is_some() && claim.metric != Metric::TimeToGoalS {
            p.at(&at("k"), Stage::Schema, "`k` goes with the metric `time_to_goal_s`");
        }
        if claim.k == Some(0) {
            p.at(&at("k"), Stage::Schema, "goals count from 1");
        }
        if claim.robot.is_some() && !claim.metric.per_robot() {
            p.at(&at("robot"), Stage::Schema, format!("`{}` has no per-robot value", claim.metric.as_str()));
        }
        match (claim.expect, claim.tolerance) {
            (Expect::Similar, Some(t)) if !(t.is_finite() && t >= 0.0) => {
                p.at(&at("tolerance"), Stage::Schema, "expected a non-negative relative tolerance (0.1 = 10 %)");
            }
            (
                Expect::Increasing | Expect::Decreasing | Expect::AtLeast | Expect::AtMost | Expect::RatioAtLeast,
                Some(_),
            ) => {
                p.at(&at("tolerance"), Stage::Schema, "`tolerance` goes with `expect: similar`");
            }
            _ => {}
        }
    }
}

/// A claim naming a robot needs that robot in every configuration it compares.
fn check_claim_robots(file: &ExperimentFile, resolved: &[ResolvedConfiguration], p: &mut Problems<'_>) {
    for (i, claim) in file.claims.iter().enumerate() {
        let Some(robot) = &claim.robot else { continue };
        for name in &claim.over {
            let Some(r) = resolved.iter().find(|r| &r.name == name) else { continue };
            let has = r.loaded.mission.as_ref().is_some_and(|m| m.team.iter().any(|t| &t.id == robot));
            if !has {
                p.at(
                    &[key("claims"), PathSeg::Index(i), key("robot")],
                    Stage::Team,
                    format!("configuration `{name}` has no robot `{robot}`"),
                );
            }
        }
    }
}

fn merged(base: &Option<serde_json::Value>, patch: &serde_json::Value) -> Option<serde_json::Value> {
    let mut v = base.clone().unwrap_or_else(|| serde_json::Value::Object(Default::default()));
    spomp_robot::settings::merge(&mut v, patch);
    Some(v)
}

/// Where each override landed in the mission (a dotted path prefix) and where it is written in
/// the experiment file, so a mission problem in patched content points at its override.
struct Provenance {
    entries: Vec<(String, Vec<PathSeg>)>,
}

impl Provenance {
    fn note(&mut self, mission_prefix: impl Into<String>, at: Vec<PathSeg>) {
        self.entries.push((mission_prefix.into(), at));
    }

    /// The override a mission node path falls under (the longest prefix), if any.
    fn find(&self, node_path: &str) -> Option<&[PathSeg]> {
        let path = dotted(node_path);
        self.entries
            .iter()
            .filter(|(prefix, _)| path == *prefix || path.starts_with(&format!("{prefix}.")))
            .max_by_key(|(prefix, _)| prefix.len())
            .map(|(_, at)| at.as_slice())
    }
}

/// `team[2].x` and `team.2.x` alike: indices as dotted segments.
fn dotted(path: &str) -> String {
    path.replace('[', ".").replace(']', "").trim_start_matches('.').to_string()
}

/// The grid position `k` beside `template` (3 m along its heading, 5 m across), k from 0.
fn grid_start(template: &StartPose, k: usize) -> StartPose {
    let along = [0.0, -3.0, 3.0, -6.0, 6.0, -9.0, 9.0, -12.0, 12.0];
    let (row, col) = (k / along.len(), k % along.len());
    let across = 5.0 * row as f64;
    let yaw = template.yaw_deg.to_radians();
    let (s, c) = yaw.sin_cos();
    let a = along[col];
    StartPose {
        x_m: template.x_m + a * c - across * s,
        y_m: template.y_m + a * s + across * c,
        yaw_deg: template.yaw_deg,
    }
}

/// The team with `n` UGVs: the first `n` of the base's, then copies of the template.
fn resize_team(
    team: &mut Vec<RobotSpec>,
    n: usize,
    template_id: Option<&str>,
    starts: &[StartPose],
) -> Result<(), (String, &'static str)> {
    let template = match template_id {
        Some(id) => team
            .iter()
            .find(|r| r.id == id && r.kind == RobotKind::Ugv)
            .cloned()
            .ok_or_else(|| (format!("the base mission has no UGV `{id}` to copy"), "ugv_template"))?,
        None => team
            .iter()
            .find(|r| r.kind == RobotKind::Ugv)
            .cloned()
            .ok_or_else(|| ("the base mission has no UGV to copy".to_string(), "ugvs"))?,
    };
    let mut kept = 0usize;
    team.retain(|r| {
        if r.kind != RobotKind::Ugv {
            return true;
        }
        kept += 1;
        kept <= n
    });
    let mut next_id = 1usize;
    let mut next_priority = team.iter().filter_map(|r| r.priority).max().unwrap_or(0) + 1;
    let mut grid = 0usize;
    let mut added = 0usize;
    while team.iter().filter(|r| r.kind == RobotKind::Ugv).count() < n {
        while team.iter().any(|r| r.id == format!("ugv{next_id}")) {
            next_id += 1;
        }
        let start = match starts.get(added) {
            Some(s) => *s,
            None => loop {
                let candidate = grid_start(&template.start, grid);
                grid += 1;
                let free = team.iter().all(|r| (r.start.x_m - candidate.x_m).hypot(r.start.y_m - candidate.y_m) >= 2.0);
                if free {
                    break candidate;
                }
            },
        };
        let mut robot = template.clone();
        robot.id = format!("ugv{next_id}");
        robot.priority = Some(next_priority);
        robot.start = start;
        robot.ros2 = None;
        next_priority += 1;
        added += 1;
        team.push(robot);
    }
    if added < starts.len() {
        return Err((format!("{} start poses for {added} added UGVs", starts.len()), "starts"));
    }
    Ok(())
}

/// Applies a configuration to its base mission, loads the result with the mission language and
/// reports its problems at the overrides that caused them.
#[allow(clippy::too_many_arguments)]
fn resolve(
    file: &ExperimentFile,
    index: usize,
    c: &Configuration,
    dir: &Path,
    options: &LoadOptions,
    registry: &NodeRegistry<RobotRuntime>,
    p: &mut Problems<'_>,
    sources: &mut BTreeMap<PathBuf, String>,
) -> Option<ResolvedConfiguration> {
    let here = |k: &str| vec![key("configurations"), PathSeg::Index(index), key(k)];
    let (mission_rel, mission_at) = match (&c.mission, &file.mission) {
        (Some(m), _) => (m.clone(), here("mission")),
        (None, Some(m)) => (m.clone(), vec![key("mission")]),
        (None, None) => return None, // reported by check_file
    };
    // A base mission may be in the experiment's folder, the folder above it (the project:
    // `experiments/` beside `missions/`) or an allowed folder.
    let mut roots: Vec<PathBuf> =
        vec![dir.to_path_buf(), absolute(dir).parent().map(Path::to_path_buf).unwrap_or_default()];
    roots.extend(options.allowed_dirs.iter().cloned());
    let base_path = match limits::resolve_inside(&roots, dir, &mission_rel) {
        Ok(p) => p,
        Err(e) => {
            p.at(&mission_at, Stage::Parse, format!("the base mission {e}"));
            return None;
        }
    };
    let base_text = match limits::read_text(&base_path, limits::MAX_SOURCE_BYTES) {
        Ok(t) => t,
        Err(e) => {
            p.at(&mission_at, Stage::Parse, format!("cannot read the base mission {}: {e}", base_path.display()));
            return None;
        }
    };
    let base = load_mission_str(&base_text, &base_path, registry, options);
    if !base.is_valid() {
        for (f, s) in base.files.iter().zip(&base.sources) {
            sources.insert(f.clone(), s.clone());
        }
        p.at(
            &mission_at,
            Stage::Schema,
            format!("the base mission {} is invalid ({} problems below)", base_path.display(), base.diagnostics.len()),
        );
        p.list.extend(base.diagnostics.iter().cloned());
        return None;
    }
    let mut mission: MissionFile = base.mission.clone()?;
    let mut prov = Provenance { entries: Vec::new() };
    // Team size first: the settings below then reach the added UGVs too.
    if let Some(n) = c.ugvs {
        if let Err((message, field)) = resize_team(&mut mission.team, n as usize, c.ugv_template.as_deref(), &c.starts)
        {
            p.at(&here(field), Stage::Team, message);
            return None;
        }
        prov.note("team", here("ugvs"));
    }
    for (i, robot) in mission.team.iter_mut().enumerate() {
        if robot.kind != RobotKind::Ugv {
            continue;
        }
        if let Some(nav) = &c.navigation {
            robot.navigation = merged(&robot.navigation, nav);
            prov.note(format!("team.{i}.navigation"), here("navigation"));
        }
        if let Some(l) = &c.localization {
            robot.localization = Some(l.clone());
            prov.note(format!("team.{i}.localization"), here("localization"));
        }
    }
    for (id, o) in &c.robots {
        let at = vec![key("configurations"), PathSeg::Index(index), key("robots"), key(id)];
        let Some((i, robot)) = mission.team.iter_mut().enumerate().find(|(_, r)| &r.id == id) else {
            let ids: Vec<&str> = mission.team.iter().map(|r| r.id.as_str()).collect();
            p.at(&at, Stage::Team, format!("the mission has no robot `{id}`; robots are: {}", ids.join(", ")));
            continue;
        };
        if let Some(nav) = &o.navigation {
            robot.navigation = merged(&robot.navigation, nav);
            let mut nav_at = at.clone();
            nav_at.push(key("navigation"));
            prov.note(format!("team.{i}.navigation"), nav_at);
        }
        if let Some(l) = &o.localization {
            robot.localization = Some(l.clone());
            let mut l_at = at.clone();
            l_at.push(key("localization"));
            prov.note(format!("team.{i}.localization"), l_at);
        }
    }
    for (name, o) in &c.roles {
        let at = vec![key("configurations"), PathSeg::Index(index), key("roles"), key(name)];
        let Some(role) = mission.roles.get_mut(name) else {
            let names: Vec<&str> = mission.roles.keys().map(String::as_str).collect();
            p.at(&at, Stage::Team, format!("the mission has no role `{name}`; roles are: {}", names.join(", ")));
            continue;
        };
        if let Some(nav) = &o.navigation {
            role.navigation = merged(&role.navigation, nav);
            prov.note(format!("roles.{name}.navigation"), at);
        }
    }
    if let Some(comms) = &c.comms {
        let m = &mut mission.comms;
        m.position_range_m = comms.position_range_m.unwrap_or(m.position_range_m);
        m.data_range_m = comms.data_range_m.unwrap_or(m.data_range_m);
        m.bandwidth_bytes_per_s = comms.bandwidth_bytes_per_s.unwrap_or(m.bandwidth_bytes_per_s);
        m.ugv_to_ugv = comms.ugv_to_ugv.or(m.ugv_to_ugv);
        prov.note("comms", here("comms"));
    }
    if !c.faults.is_empty() || c.world.is_some() || c.prior_map.is_some() {
        let sim = mission.sim.get_or_insert_with(|| SimSpec {
            world: None,
            trials: None,
            seed: None,
            faults: Vec::new(),
            prior_map: false,
            operator: Vec::new(),
        });
        if !c.faults.is_empty() {
            let first = sim.faults.len();
            sim.faults.extend(c.faults.iter().cloned());
            for k in 0..c.faults.len() {
                let mut at = here("faults");
                at.push(PathSeg::Index(k));
                prov.note(format!("sim.faults.{}", first + k), at);
            }
        }
        if let Some(world) = &c.world {
            // A world folder is written relative to the experiment file.
            sim.world = Some(match world {
                WorldSpec::Dir(d) => WorldSpec::Dir(absolute(&dir.join(d)).to_string_lossy().into_owned()),
                other => other.clone(),
            });
            prov.note("sim.world", here("world"));
        }
        if let Some(prior) = c.prior_map {
            sim.prior_map = prior;
            prov.note("sim.prior_map", here("prior_map"));
        }
    }
    match (c.time_limit_s, file.time_limit_s) {
        (Some(t), _) => {
            mission.time_limit_s = t;
            prov.note("time_limit_s", here("time_limit_s"));
        }
        (None, Some(t)) => {
            mission.time_limit_s = t;
            prov.note("time_limit_s", vec![key("time_limit_s")]);
        }
        (None, None) => {}
    }
    let patched = match serde_json::to_string_pretty(&mission) {
        Ok(t) => t,
        Err(e) => {
            p.at(&[key("configurations"), PathSeg::Index(index)], Stage::Schema, format!("patching the mission: {e}"));
            return None;
        }
    };
    let loaded = load_mission_str(&patched, &base_path, registry, options);
    if !loaded.is_valid() {
        let fallback = vec![key("configurations"), PathSeg::Index(index), key("name")];
        for d in &loaded.diagnostics {
            let at = prov.find(&d.node_path).unwrap_or(&fallback).to_vec();
            let shown = if d.node_path.is_empty() { String::new() } else { format!(" at `{}`", d.node_path) };
            p.at(&at, d.stage, format!("configuration `{}` makes the mission invalid{shown}: {}", c.name, d.message));
        }
        return None;
    }
    // What the trials depend on besides the seed: the base mission's text as written, this
    // configuration's overrides as parsed (its description aside: words change no result), and
    // the experiment-wide time limit.
    // Nor where the trials run: a deployed trial is the same trial run another way.
    let overrides = Configuration { description: None, deployed: Vec::new(), ..c.clone() };
    let hash_input = serde_json::json!({
        "row_format": ROW_FORMAT,
        "base_mission": base_text,
        "configuration": overrides,
        "time_limit_s": file.time_limit_s,
    })
    .to_string();
    Some(ResolvedConfiguration { name: c.name.clone(), loaded, patched, hash_input })
}

/// `p` made absolute against the working folder (no file system access).
fn absolute(p: &Path) -> PathBuf {
    if p.is_absolute() {
        p.to_path_buf()
    } else {
        std::env::current_dir().map(|d| d.join(p)).unwrap_or_else(|_| p.to_path_buf())
    }
}

/// FNV-1a, 64 bits: a hash that stays the same across builds and machines (the standard
/// library's does not promise that), so rows written anywhere can be matched.
pub fn fnv1a64(bytes: &[u8]) -> u64 {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for b in bytes {
        h ^= u64::from(*b);
        h = h.wrapping_mul(0x0000_0100_0000_01b3);
    }
    h
}

/// The hash that identifies a trial's resolved configuration and seed, as 16 hex digits.
pub fn trial_hash(configuration: &ResolvedConfiguration, seed: u64) -> String {
    let text = format!("{}\u{0}seed={seed}", configuration.hash_input);
    format!("{:016x}", fnv1a64(text.as_bytes()))
}

/// The trials of shard `index` (from 1) of `count`: those whose trial index mod `count` is
/// `index - 1`, so shards interleave configurations and seeds and take similar work.
pub fn shard_of(trials: &[Trial], index: usize, count: usize) -> Vec<Trial> {
    if count == 0 || index == 0 || index > count {
        return Vec::new();
    }
    trials.iter().filter(|t| t.index % count == index - 1).cloned().collect()
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;

    #[test]
    fn fnv_matches_reference_values() {
        // Published FNV-1a 64 test vectors.
        assert_eq!(fnv1a64(b""), 0xcbf2_9ce4_8422_2325);
        assert_eq!(fnv1a64(b"a"), 0xaf63_dc4c_8601_ec8c);
        assert_eq!(fnv1a64(b"foobar"), 0x8594_4171_f739_67e8);
    }

    #[test]
    fn deployed_trials_follow_every_in_process_trial_whatever_the_channels_selected() {
        let t = Trial { index: 3, configuration: 1, seed: 2, deployed: None };
        let radio = deployed_trial(&t, TeamChannel::Radio, 10);
        let zenoh = deployed_trial(&t, TeamChannel::Zenoh, 10);
        assert_eq!((radio.index, radio.deployed, radio.seed), (13, Some(TeamChannel::Radio), 2));
        assert_eq!((zenoh.index, zenoh.configuration), (23, 1));
    }

    #[test]
    fn merge_is_key_by_key() {
        let mut base =
            serde_json::json!({ "profile": "simulation", "global_planner": { "learning": "on", "sharing": "all" } });
        spomp_robot::settings::merge(&mut base, &serde_json::json!({ "global_planner": { "sharing": "none" } }));
        assert_eq!(
            base,
            serde_json::json!({ "profile": "simulation", "global_planner": { "learning": "on", "sharing": "none" } })
        );
    }

    #[test]
    fn grid_starts_step_along_and_across_the_heading() {
        let t = StartPose { x_m: 16.0, y_m: 2.5, yaw_deg: 0.0 };
        let a = grid_start(&t, 1);
        assert!((a.x_m - 13.0).abs() < 1e-9 && (a.y_m - 2.5).abs() < 1e-9);
        let b = grid_start(&t, 9);
        assert!((b.x_m - 16.0).abs() < 1e-9 && (b.y_m - 7.5).abs() < 1e-9);
        let north = StartPose { yaw_deg: 90.0, ..t };
        let c = grid_start(&north, 2);
        assert!((c.x_m - 16.0).abs() < 1e-9 && (c.y_m - 5.5).abs() < 1e-9);
    }

    #[test]
    fn provenance_takes_the_longest_prefix_on_segment_boundaries() {
        let mut p = Provenance { entries: Vec::new() };
        p.note("team", vec![key("ugvs")]);
        p.note("team.1.navigation", vec![key("navigation")]);
        assert_eq!(p.find("team[1].navigation.terrain.inflation_m"), Some(&[key("navigation")][..]));
        assert_eq!(p.find("team.1.priority"), Some(&[key("ugvs")][..]));
        assert_eq!(p.find("team.10.navigation"), Some(&[key("ugvs")][..]));
        assert_eq!(p.find("comms"), None);
    }
}

#[cfg(test)]
mod shard_properties {
    use proptest::prelude::*;

    use super::*;

    fn trials(configurations: usize, seeds: usize) -> Vec<Trial> {
        (0..configurations * seeds)
            .map(|i| Trial { index: i, configuration: i / seeds, seed: (i % seeds) as u64 + 1, deployed: None })
            .collect()
    }

    proptest! {
        /// The shards of any experiment hold every trial exactly once, and none is more than
        /// one trial larger than another.
        #[test]
        fn shards_partition_the_trials(configurations in 1usize..12, seeds in 1usize..15, count in 1usize..20) {
            let all = trials(configurations, seeds);
            let mut seen = vec![0u32; all.len()];
            let mut sizes = Vec::new();
            for i in 1..=count {
                let shard = shard_of(&all, i, count);
                sizes.push(shard.len());
                for t in shard {
                    seen[t.index] += 1;
                }
            }
            prop_assert!(seen.iter().all(|&n| n == 1), "{seen:?}");
            let (lo, hi) = (sizes.iter().min().copied().unwrap_or(0), sizes.iter().max().copied().unwrap_or(0));
            prop_assert!(hi - lo <= 1, "{sizes:?}");
            prop_assert!(shard_of(&all, 0, count).is_empty() && shard_of(&all, count + 1, count).is_empty());
        }
    }
}
