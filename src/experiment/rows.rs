//! Trial rows: what one trial measured, and the crash-safe files they are kept in
//! (`trials.jsonl`, the record; `trials.csv`, the same rows for spreadsheets).

use std::collections::BTreeMap;
use std::fs::File;
use std::io::Write;
use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use serde::{Deserialize, Serialize};
use spomp_behaviors::mission::limits::{SourceError, read_regular};
use spomp_behaviors::mission::output;
use spomp_core::RobotId;
use spomp_robot::{RobotObserver, TeamTraffic};
use spomp_sim::run::{RunSummary, SimObserver};
use spomp_teamstate::{SyncMessage, TierSet};

use super::spec::{Metric, TeamChannel};

/// The record of the trials, one JSON object a line.
pub const JSONL: &str = "trials.jsonl";
/// The same rows as CSV.
pub const CSV: &str = "trials.csv";

/// One robot's figures in a trial.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RobotRow {
    /// Robot id.
    pub id: String,
    /// `ugv`, `uav` or `basestation`.
    pub kind: String,
    /// Distance driven or flown, metres.
    pub distance_m: f64,
    /// Goals it visited.
    pub goals_visited: u32,
    /// Times of its visits, seconds, in order.
    pub visit_times_s: Vec<f64>,
    /// Fraction of the time it was heading to a goal.
    pub heading_to_goal_fraction: f64,
    /// Collisions.
    pub collisions: u64,
    /// Median localization error, metres (UGVs with a localizer).
    pub localization_error_m: Option<f64>,
    /// Team-state bytes it sent.
    pub bytes_sent: u64,
    /// Seconds from its first motion to its last (a robot sent on one trip: the trip).
    #[serde(default)]
    pub travel_time_s: Option<f64>,
    /// Its tree's status at the end (`success`, `failure`, `running`, …): whether a robot
    /// whose tree ends — a `navigate_to` — got there.
    #[serde(default)]
    pub tree_status: String,
    /// Times the simulator refused every commanded motion of this UGV for its stuck timeout
    /// (rows written before the field existed read 0).
    #[serde(default)]
    pub stuck_events: u64,
    /// Longest time this UGV stood still while its tree was driving it, seconds.
    #[serde(default)]
    pub longest_motionless_driving_s: f64,
}

/// One trial's row.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TrialRow {
    /// Index of the trial in the experiment.
    pub trial: usize,
    /// Configuration name.
    pub configuration: String,
    /// Seed.
    pub seed: u64,
    /// Hash of the resolved configuration and seed (16 hex digits).
    pub config_hash: String,
    /// Mission name.
    pub mission: String,
    /// How it ended (`completed`, `time_limit`, …).
    pub outcome: String,
    /// Simulated seconds at the end.
    pub end_s: f64,
    /// The trial's time limit, seconds.
    pub time_limit_s: f64,
    /// UGVs in the team.
    pub ugvs: usize,
    /// Goals known at the end.
    pub goals_total: usize,
    /// Goals visited.
    pub goals_visited: usize,
    /// Vehicle clusters in the world (generated worlds).
    pub clusters_total: Option<usize>,
    /// Vehicle clusters visited (generated worlds).
    pub clusters_visited: Option<usize>,
    /// Times of the goal visits, seconds, sorted.
    pub visit_times_s: Vec<f64>,
    /// Distance driven, metres, mean over UGVs.
    pub distance_m: f64,
    /// Fraction of time heading to a goal, mean over UGVs.
    pub heading_to_goal_fraction: f64,
    /// Collisions, sum over UGVs.
    pub collisions: u64,
    /// Localization error, metres: mean over UGVs of each one's median.
    pub localization_error_m: Option<f64>,
    /// Team-state bytes sent by all robots.
    pub bytes_sent: u64,
    /// Of those, over links that carried every tier (within the data range).
    pub bytes_sent_full_links: u64,
    /// Of those, over links that carried coordination only (position range).
    pub bytes_sent_small_links: u64,
    /// Of those, the coordination tier's (goals, claims, poses; with every message's header).
    #[serde(default)]
    pub bytes_sent_coordination: u64,
    /// Of those, the scan tier's (shared reachability scans).
    #[serde(default)]
    pub bytes_sent_scans: u64,
    /// Of those, the map tier's (aerial-map versions).
    #[serde(default)]
    pub bytes_sent_maps: u64,
    /// Wall-clock seconds of the trial (the only field that differs between equal runs).
    pub wall_s: f64,
    /// Each robot, in team order.
    pub robots: Vec<RobotRow>,
    /// A deployed trial's team channel (the lockstep farm and one `spomp run` process per
    /// robot); absent for a trial run in-process.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub deployed: Option<TeamChannel>,
    /// A deployed trial's process problems: a robot process that did not report in time, was
    /// dropped from the lockstep (died or hung), failed, or had to be killed at the end.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub process_problems: Vec<String>,
}

impl TrialRow {
    /// The row without its wall-clock time, for comparing runs.
    pub fn deterministic_part(&self) -> TrialRow {
        TrialRow { wall_s: 0.0, ..self.clone() }
    }

    /// Vehicle clusters visited (generated worlds), else goals visited.
    pub fn clusters_or_goals_visited(&self) -> f64 {
        self.clusters_visited.unwrap_or(self.goals_visited) as f64
    }

    /// The UGVs' rows.
    fn ugv_rows(&self) -> impl Iterator<Item = &RobotRow> {
        self.robots.iter().filter(|r| r.kind == "ugv")
    }

    /// Distance flown by the team's UAVs, metres (their sum).
    pub fn uav_distance_m(&self) -> f64 {
        self.robots.iter().filter(|r| r.kind == "uav").map(|r| r.distance_m).sum()
    }

    /// The visited share of the world's clusters (generated worlds), else of the goals.
    pub fn visited_fraction(&self) -> f64 {
        match (self.clusters_total, self.clusters_visited) {
            (Some(t), Some(v)) if t > 0 => v as f64 / t as f64,
            _ if self.goals_total > 0 => self.goals_visited as f64 / self.goals_total as f64,
            _ => 0.0,
        }
    }

    /// The value of `metric` (for `time_to_goal_s`, of the `k`-th visit; for a robot's own
    /// value, `robot`). `None` when the robot is not in the trial or the metric has no value.
    pub fn metric(&self, metric: Metric, k: u32, robot: Option<&str>) -> Option<f64> {
        let kth = |times: &[f64]| {
            let k = (k.max(1) - 1) as usize;
            Some(times.get(k).copied().unwrap_or(self.time_limit_s))
        };
        if let Some(id) = robot {
            let r = self.robots.iter().find(|r| r.id == id)?;
            return match metric {
                Metric::DistanceM => Some(r.distance_m),
                Metric::HeadingToGoalFraction => Some(r.heading_to_goal_fraction),
                Metric::Collisions => Some(r.collisions as f64),
                Metric::GoalsVisited => Some(f64::from(r.goals_visited)),
                Metric::TimeToGoalS => kth(&r.visit_times_s),
                Metric::BytesSent => Some(r.bytes_sent as f64),
                Metric::TravelTimeS => r.travel_time_s,
                Metric::StuckEvents => Some(r.stuck_events as f64),
                Metric::LongestMotionlessDrivingS => Some(r.longest_motionless_driving_s),
                _ => None,
            };
        }
        match metric {
            Metric::GoalsVisited => Some(self.goals_visited as f64),
            Metric::VisitedFraction => Some(self.visited_fraction()),
            Metric::TimeToGoalS => kth(&self.visit_times_s),
            Metric::EndS => Some(self.end_s),
            Metric::DistanceM => Some(self.distance_m),
            Metric::HeadingToGoalFraction => Some(self.heading_to_goal_fraction),
            Metric::Collisions => Some(self.collisions as f64),
            Metric::LocalizationErrorM => self.localization_error_m,
            Metric::BytesSent => Some(self.bytes_sent as f64),
            Metric::BytesSentScans => Some(self.bytes_sent_scans as f64),
            Metric::TravelTimeS => mean(self.robots.iter().filter(|r| r.kind == "ugv").filter_map(|r| r.travel_time_s)),
            Metric::StuckEvents => Some(self.ugv_rows().map(|r| r.stuck_events).sum::<u64>() as f64),
            Metric::LongestMotionlessDrivingS => {
                Some(self.ugv_rows().map(|r| r.longest_motionless_driving_s).fold(0.0, f64::max))
            }
            Metric::WallS => Some(self.wall_s),
        }
    }
}

/// Counts the team-state bytes each robot sends, by the kind of link.
#[derive(Debug, Default)]
pub struct ByteCounter {
    /// Bytes per sender over links that carry every tier.
    pub full: BTreeMap<String, u64>,
    /// Bytes per sender over coordination-only links.
    pub small: BTreeMap<String, u64>,
    /// Bytes of all senders by sync tier (coordination, scans, maps).
    pub by_tier: [u64; 3],
}

impl ByteCounter {
    /// Counts a message `robot` sent over a link allowing `tiers`.
    pub fn count(&mut self, robot: &RobotId, tiers: TierSet, bytes: &[u8]) {
        let map = if tiers == TierSet::ALL { &mut self.full } else { &mut self.small };
        *map.entry(robot.to_string()).or_default() += bytes.len() as u64;
        // The robot encoded this message itself: it decodes. Were it ever not to, its bytes
        // still count, as coordination.
        let split = SyncMessage::decode(bytes).map_or([bytes.len() as u64, 0, 0], |m| m.bytes_by_tier(bytes.len()));
        for (total, b) in self.by_tier.iter_mut().zip(split) {
            *total += b;
        }
    }

    /// Adds `other`'s counts to these.
    pub fn add(&mut self, other: &ByteCounter) {
        for (mine, theirs) in [(&mut self.full, &other.full), (&mut self.small, &other.small)] {
            for (robot, b) in theirs {
                *mine.entry(robot.clone()).or_default() += b;
            }
        }
        for (total, b) in self.by_tier.iter_mut().zip(other.by_tier) {
            *total += b;
        }
    }
}

impl ByteCounter {
    /// The counts the robots kept of what they sent (`spomp_robot::TeamTraffic`): no seam
    /// recording needed, so an experiment's robots do not copy every call they answer.
    pub fn of_robots<'a>(traffic: impl IntoIterator<Item = &'a (RobotId, TeamTraffic)>) -> Self {
        let mut bytes = ByteCounter::default();
        for (robot, t) in traffic {
            if t.sent_messages == 0 {
                continue;
            }
            let robot = robot.to_string();
            if t.sent_bytes_all_tiers > 0 {
                *bytes.full.entry(robot.clone()).or_default() += t.sent_bytes_all_tiers;
            }
            if t.sent_bytes_fewer_tiers > 0 {
                *bytes.small.entry(robot).or_default() += t.sent_bytes_fewer_tiers;
            }
            for (total, b) in bytes.by_tier.iter_mut().zip(t.sent_bytes_by_tier) {
                *total += b;
            }
        }
        bytes
    }
}

/// What an experiment's trial observes of its run: nothing but the result (the rows come from
/// the summary and the robots' own traffic counts), with the robots' states as rarely as the
/// simulator allows.
pub struct TrialObserver;

impl RobotObserver for TrialObserver {}

impl SimObserver for TrialObserver {
    fn record_period_s(&self) -> f64 {
        1.0
    }
}

fn mean(values: impl Iterator<Item = f64>) -> Option<f64> {
    let (sum, n) = values.fold((0.0, 0usize), |(s, n), v| (s + v, n + 1));
    (n > 0).then(|| sum / n as f64)
}

/// The row of a finished trial.
pub fn row_of(
    trial: usize,
    configuration: &str,
    config_hash: &str,
    summary: &RunSummary,
    bytes: &ByteCounter,
) -> TrialRow {
    let mut visit_times_s: Vec<f64> = summary.goals.iter().filter_map(|g| g.visited_s).collect();
    visit_times_s.sort_by(f64::total_cmp);
    let robots: Vec<RobotRow> = summary
        .robots
        .iter()
        .map(|r| {
            let mut times: Vec<f64> = summary
                .goals
                .iter()
                .filter(|g| g.visited_by.as_deref() == Some(r.id.as_str()))
                .filter_map(|g| g.visited_s)
                .collect();
            times.sort_by(f64::total_cmp);
            RobotRow {
                id: r.id.clone(),
                kind: r.kind.clone(),
                distance_m: r.distance_m,
                goals_visited: r.goals_visited,
                visit_times_s: times,
                heading_to_goal_fraction: r.heading_to_goal_fraction,
                collisions: r.collisions,
                localization_error_m: r.localization_error_m.map(|e| e.median),
                bytes_sent: bytes.full.get(&r.id).copied().unwrap_or(0) + bytes.small.get(&r.id).copied().unwrap_or(0),
                tree_status: r.tree_status.clone(),
                travel_time_s: r.travel_time_s,
                stuck_events: r.stuck_events,
                longest_motionless_driving_s: r.longest_motionless_driving_s,
            }
        })
        .collect();
    let ugvs: Vec<&RobotRow> = robots.iter().filter(|r| r.kind == "ugv").collect();
    let full: u64 = bytes.full.values().sum();
    let small: u64 = bytes.small.values().sum();
    TrialRow {
        trial,
        configuration: configuration.to_string(),
        seed: summary.seed,
        config_hash: config_hash.to_string(),
        mission: summary.mission.clone(),
        outcome: serde_json::to_value(summary.outcome)
            .ok()
            .and_then(|v| v.as_str().map(str::to_string))
            .unwrap_or_else(|| format!("{:?}", summary.outcome)),
        end_s: summary.end_s,
        time_limit_s: summary.time_limit_s,
        ugvs: ugvs.len(),
        goals_total: summary.goals.len(),
        goals_visited: summary.goals_visited,
        clusters_total: summary.clusters.map(|c| c.total),
        clusters_visited: summary.clusters.map(|c| c.visited),
        visit_times_s,
        distance_m: mean(ugvs.iter().map(|r| r.distance_m)).unwrap_or(0.0),
        heading_to_goal_fraction: mean(ugvs.iter().map(|r| r.heading_to_goal_fraction)).unwrap_or(0.0),
        collisions: ugvs.iter().map(|r| r.collisions).sum(),
        localization_error_m: mean(ugvs.iter().filter_map(|r| r.localization_error_m)),
        bytes_sent: full + small,
        bytes_sent_full_links: full,
        bytes_sent_small_links: small,
        bytes_sent_coordination: bytes.by_tier[0],
        bytes_sent_scans: bytes.by_tier[1],
        bytes_sent_maps: bytes.by_tier[2],
        wall_s: summary.wall_s,
        robots,
        deployed: None,
        process_problems: Vec::new(),
    }
}

/// The CSV header: every scalar of a row (visit times joined with `;`; robots only in the
/// JSONL).
pub const CSV_HEADER: &str = "trial,configuration,seed,config_hash,mission,outcome,end_s,time_limit_s,ugvs,\
goals_total,goals_visited,clusters_total,clusters_visited,visit_times_s,distance_m,heading_to_goal_fraction,\
collisions,localization_error_m,bytes_sent,bytes_sent_full_links,bytes_sent_small_links,bytes_sent_coordination,\
bytes_sent_scans,bytes_sent_maps,wall_s,deployed";

/// A row as a CSV line (with its newline). Configuration and mission names are plain
/// identifiers, so no field needs quoting; `deployed` is the team channel of a deployed trial,
/// empty for an in-process one.
pub fn csv_line(r: &TrialRow) -> String {
    let opt = |v: Option<usize>| v.map_or_else(String::new, |v| v.to_string());
    let times: Vec<String> = r.visit_times_s.iter().map(|t| format!("{t:.1}")).collect();
    format!(
        "{},{},{},{},{},{},{:.1},{:.1},{},{},{},{},{},{},{:.1},{:.4},{},{},{},{},{},{},{},{},{:.2},{}\n",
        r.trial,
        r.configuration,
        r.seed,
        r.config_hash,
        r.mission,
        r.outcome,
        r.end_s,
        r.time_limit_s,
        r.ugvs,
        r.goals_total,
        r.goals_visited,
        opt(r.clusters_total),
        opt(r.clusters_visited),
        times.join(";"),
        r.distance_m,
        r.heading_to_goal_fraction,
        r.collisions,
        r.localization_error_m.map_or_else(String::new, |e| format!("{e:.3}")),
        r.bytes_sent,
        r.bytes_sent_full_links,
        r.bytes_sent_small_links,
        r.bytes_sent_coordination,
        r.bytes_sent_scans,
        r.bytes_sent_maps,
        r.wall_s,
        r.deployed.map_or("", TeamChannel::as_str)
    )
}

/// The largest `trials.jsonl` read, bytes (64 MiB: tens of thousands of rows).
pub const MAX_ROWS_BYTES: u64 = 64 << 20;

/// The bytes of a `trials.jsonl`, `None` when there is none: a regular file of at most
/// [`MAX_ROWS_BYTES`] (a FIFO or `/dev/zero` in its place is an error, not a hang).
fn read_jsonl(path: &Path) -> Result<Option<Vec<u8>>> {
    match read_regular(path, MAX_ROWS_BYTES) {
        Ok(bytes) => Ok(Some(bytes)),
        Err(SourceError::Io { kind: std::io::ErrorKind::NotFound, .. }) => Ok(None),
        Err(e) => Err(anyhow::anyhow!("{e}")),
    }
}

/// Reads the rows of `dir/trials.jsonl`. A last line without its newline (a crash while it was
/// written) is ignored; any other line that does not parse is an error naming it.
pub fn read_rows(dir: &Path) -> Result<Vec<TrialRow>> {
    let path = dir.join(JSONL);
    let Some(bytes) = read_jsonl(&path)? else { return Ok(Vec::new()) };
    let text = String::from_utf8(bytes).map_err(|_| anyhow::anyhow!("{}: not UTF-8 text", path.display()))?;
    let complete = match text.rfind('\n') {
        Some(end) => &text[..=end],
        None => "",
    };
    let mut rows = Vec::new();
    for (i, line) in complete.lines().enumerate() {
        if line.trim().is_empty() {
            continue;
        }
        let row: TrialRow =
            serde_json::from_str(line).with_context(|| format!("{}:{}: not a trial row", path.display(), i + 1))?;
        rows.push(row);
    }
    Ok(rows)
}

/// Appends rows to a folder's `trials.jsonl` and `trials.csv`, each row flushed and synced to
/// disk before the next, so a crash or Ctrl-C loses no finished trial.
pub struct RowSink {
    jsonl: File,
    csv: File,
    paths: (PathBuf, PathBuf),
}

impl RowSink {
    /// Opens `dir`'s row files for appending, holding `existing` (the rows read from it):
    /// a partial last line of `trials.jsonl` is cut off, and `trials.csv` is rewritten from
    /// the JSONL rows (the CSV is a view of the record, never the record).
    pub fn open(dir: &Path, existing: &[TrialRow]) -> Result<RowSink> {
        let jsonl_path = dir.join(JSONL);
        let csv_path = dir.join(CSV);
        if let Some(text) = read_jsonl(&jsonl_path)? {
            let keep = text.iter().rposition(|b| *b == b'\n').map_or(0, |i| i + 1);
            if keep < text.len() {
                let f = output::open_existing_file(&jsonl_path)
                    .with_context(|| format!("opening {}", jsonl_path.display()))?;
                f.set_len(keep as u64)
                    .with_context(|| format!("cutting the partial row of {}", jsonl_path.display()))?;
                f.sync_all().with_context(|| format!("syncing {}", jsonl_path.display()))?;
            }
        }
        let mut csv_text = format!("{CSV_HEADER}\n");
        for r in existing {
            csv_text.push_str(&csv_line(r));
        }
        write_synced(&csv_path, csv_text.as_bytes())?;
        let open = |p: &Path| output::append_file(p).with_context(|| format!("opening {}", p.display()));
        Ok(RowSink { jsonl: open(&jsonl_path)?, csv: open(&csv_path)?, paths: (jsonl_path, csv_path) })
    }

    /// Appends one row to both files and syncs them.
    pub fn append(&mut self, row: &TrialRow) -> Result<()> {
        let mut line = serde_json::to_string(row).context("serialising a trial row")?;
        line.push('\n');
        // The record first: a row in the JSONL is complete; the CSV is rebuilt from it on resume.
        self.jsonl
            .write_all(line.as_bytes())
            .and_then(|()| self.jsonl.flush())
            .and_then(|()| self.jsonl.sync_data())
            .with_context(|| format!("writing {}", self.paths.0.display()))?;
        self.csv
            .write_all(csv_line(row).as_bytes())
            .and_then(|()| self.csv.flush())
            .and_then(|()| self.csv.sync_data())
            .with_context(|| format!("writing {}", self.paths.1.display()))?;
        Ok(())
    }
}

/// Writes a whole file through a temporary one (an unpredictable name in the same folder),
/// synced, renamed over it; a link planted at `path` is refused.
pub fn write_synced(path: &Path, bytes: &[u8]) -> Result<()> {
    crate::output::write(path, bytes)
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;

    fn row(trial: usize) -> TrialRow {
        TrialRow {
            trial,
            configuration: "ugv3".into(),
            seed: 7,
            config_hash: "0123456789abcdef".into(),
            mission: "m".into(),
            outcome: "completed".into(),
            end_s: 100.0,
            time_limit_s: 600.0,
            ugvs: 3,
            goals_total: 4,
            goals_visited: 2,
            clusters_total: Some(5),
            clusters_visited: Some(2),
            visit_times_s: vec![10.0, 50.0],
            distance_m: 80.0,
            heading_to_goal_fraction: 0.5,
            collisions: 1,
            localization_error_m: Some(0.4),
            bytes_sent: 30,
            bytes_sent_full_links: 20,
            bytes_sent_small_links: 10,
            bytes_sent_coordination: 24,
            bytes_sent_scans: 6,
            bytes_sent_maps: 0,
            wall_s: 1.5,
            robots: vec![RobotRow {
                id: "ugv1".into(),
                kind: "ugv".into(),
                distance_m: 80.0,
                goals_visited: 2,
                visit_times_s: vec![10.0, 50.0],
                heading_to_goal_fraction: 0.5,
                collisions: 1,
                localization_error_m: Some(0.4),
                bytes_sent: 30,
                tree_status: "running".into(),
                travel_time_s: Some(90.0),
                stuck_events: 1,
                longest_motionless_driving_s: 12.0,
            }],
            deployed: None,
            process_problems: Vec::new(),
        }
    }

    #[test]
    fn metrics_read_the_row_and_censor_missing_visits_at_the_time_limit() {
        let r = row(0);
        assert_eq!(r.metric(Metric::TimeToGoalS, 2, None), Some(50.0));
        assert_eq!(r.metric(Metric::TimeToGoalS, 3, None), Some(600.0));
        assert_eq!(r.metric(Metric::VisitedFraction, 1, None), Some(0.4));
        assert_eq!(r.metric(Metric::DistanceM, 1, Some("ugv1")), Some(80.0));
        assert_eq!(r.metric(Metric::DistanceM, 1, Some("ugv9")), None);
        assert_eq!(r.metric(Metric::LocalizationErrorM, 1, Some("ugv1")), None);
        assert_eq!(r.metric(Metric::TravelTimeS, 1, Some("ugv1")), Some(90.0));
        assert_eq!(r.metric(Metric::TravelTimeS, 1, None), Some(90.0), "the mean over the one UGV");
        assert_eq!(r.metric(Metric::BytesSentScans, 1, None), Some(6.0));
    }

    /// Rows written before the per-tier byte counts and trip times existed still read (a study
    /// resumed across the upgrade), with those figures at zero / absent.
    #[test]
    fn rows_without_the_newer_fields_still_read() {
        let mut old = serde_json::to_value(row(0)).unwrap();
        let o = old.as_object_mut().unwrap();
        for k in ["bytes_sent_coordination", "bytes_sent_scans", "bytes_sent_maps"] {
            o.remove(k);
        }
        o["robots"][0].as_object_mut().unwrap().remove("travel_time_s");
        let back: TrialRow = serde_json::from_value(old).unwrap();
        assert_eq!((back.bytes_sent_scans, back.robots[0].travel_time_s), (0, None));
    }

    #[test]
    fn a_partial_last_line_is_ignored_then_cut_before_appending() {
        let dir = tempfile::tempdir().unwrap();
        let mut sink = RowSink::open(dir.path(), &[]).unwrap();
        sink.append(&row(0)).unwrap();
        drop(sink);
        // A crash in the middle of the second row.
        let mut f = std::fs::OpenOptions::new().append(true).open(dir.path().join(JSONL)).unwrap();
        f.write_all(b"{\"trial\":1,\"configu").unwrap();
        drop(f);
        let rows = read_rows(dir.path()).unwrap();
        assert_eq!(rows, vec![row(0)]);
        let mut sink = RowSink::open(dir.path(), &rows).unwrap();
        sink.append(&row(1)).unwrap();
        drop(sink);
        assert_eq!(read_rows(dir.path()).unwrap(), vec![row(0), row(1)]);
        let csv = std::fs::read_to_string(dir.path().join(CSV)).unwrap();
        assert_eq!(csv.lines().count(), 3);
        assert!(csv.starts_with("trial,configuration,seed,"));
        assert_eq!(csv.lines().nth(2).unwrap().split(',').count(), CSV_HEADER.split(',').count());
    }

    /// Regression: serde_json's default float parser may be one ulp off, so a study's merged
    /// report differed in the last bit of distances and fractions from the rows its trials
    /// wrote (80 of the paper study's 120 rows). Rows must read back as written.
    #[test]
    fn floats_read_back_bit_for_bit() {
        let mut written = row(0);
        written.distance_m = 12488.037106661619;
        written.heading_to_goal_fraction = 0.9235598022332241;
        written.localization_error_m = Some(0.21496572595232258);
        written.robots[0].distance_m = 2465.7009001515007;
        let mut state = 0x2545_f491_4f6c_dd1du64;
        written.visit_times_s = (0..2000)
            .map(|_| {
                state ^= state << 13;
                state ^= state >> 7;
                state ^= state << 17;
                (state >> 11) as f64 / (1u64 << 53) as f64 * 1800.0
            })
            .collect();
        let dir = tempfile::tempdir().unwrap();
        RowSink::open(dir.path(), &[]).unwrap().append(&written).unwrap();
        let back = read_rows(dir.path()).unwrap();
        let bits = |r: &TrialRow| {
            let mut b =
                vec![r.distance_m.to_bits(), r.heading_to_goal_fraction.to_bits(), r.robots[0].distance_m.to_bits()];
            b.extend(r.localization_error_m.map(f64::to_bits));
            b.extend(r.visit_times_s.iter().map(|t| t.to_bits()));
            b
        };
        let (got, want) = (bits(&back[0]), bits(&written));
        let differing = got.iter().zip(&want).filter(|(a, b)| a != b).count();
        assert_eq!((got.len(), differing), (want.len(), 0), "values that read back differently");
    }

    #[test]
    fn a_broken_complete_line_is_an_error_that_names_it() {
        let dir = tempfile::tempdir().unwrap();
        std::fs::write(dir.path().join(JSONL), "not json\n").unwrap();
        let e = read_rows(dir.path()).unwrap_err();
        assert!(format!("{e:#}").contains("trials.jsonl:1"), "{e:#}");
    }
}
