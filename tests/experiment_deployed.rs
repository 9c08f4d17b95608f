//! `spomp experiment` on the deployed path: a trial run as robots run it — the lockstep robot
//! farm in the experiment's process and one `spomp run` process per robot (basestation, UAV,
//! two UGVs) over loopback — beside the same trial in-process. Over the farm's radio model the
//! row is the in-process row, field for field but wall time; over the signed Zenoh link the
//! row is marked and the trial runs to its end. Two deployed trials run side by side
//! (`--jobs 2`), each on its own DDS domain and ports.

#![allow(clippy::unwrap_used, clippy::expect_used)] // tests fail loudly by design

use std::path::Path;

use assert_cmd::Command;
use spomp::experiment::rows::{TrialRow, read_rows};
use spomp::experiment::spec::TeamChannel;

/// The experiment, named as a user in its folder names it: without a folder (regression: the
/// robots' processes were then given an empty `--allow-dir` and every one refused to start).
const EXPERIMENT: &str = "deployed.yaml";
const EXPERIMENT_DIR: &str = "tests/experiments";

fn spomp() -> Command {
    let mut c = Command::cargo_bin("spomp").unwrap();
    c.current_dir(env!("CARGO_MANIFEST_DIR"));
    c.env("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST");
    c.env_remove("ROS_DOMAIN_ID");
    c
}

fn run(out: &Path, extra: &[&str]) -> serde_json::Value {
    let o = spomp()
        .current_dir(Path::new(env!("CARGO_MANIFEST_DIR")).join(EXPERIMENT_DIR))
        .args(["experiment", EXPERIMENT, "--json", "--jobs", "2", "--out"])
        .arg(out)
        .args(extra)
        .output()
        .unwrap();
    assert_eq!(
        o.status.code(),
        Some(0),
        "{}\n{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    );
    serde_json::from_slice(&o.stdout).unwrap()
}

/// A row without what only says how it was run (its index, wall time and deployment marks).
fn bare(row: &TrialRow) -> TrialRow {
    TrialRow { trial: 0, deployed: None, process_problems: Vec::new(), ..row.deterministic_part() }
}

#[test]
fn a_deployed_trial_over_the_radio_model_is_the_in_process_trial_and_one_over_zenoh_runs_to_its_end() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("out");
    let summary = run(&out, &[]);
    assert_eq!(summary["trials_run"], 3, "{summary:#}");
    let rows = read_rows(&out).unwrap();
    let find = |d: Option<TeamChannel>| rows.iter().find(|r| r.deployed == d).cloned().unwrap();
    let (inside, radio, zenoh) = (find(None), find(Some(TeamChannel::Radio)), find(Some(TeamChannel::Zenoh)));
    // Trial indices: the deployed ones after every in-process one, radio then zenoh.
    assert_eq!((inside.trial, radio.trial, zenoh.trial), (0, 1, 2));
    assert!(inside.goals_visited >= 2, "the in-process trial does something: {inside:#?}");

    assert!(radio.process_problems.is_empty(), "{:#?}", radio.process_problems);
    assert_eq!(bare(&radio), bare(&inside), "over the radio model the deployed row is the in-process row");

    assert!(zenoh.process_problems.is_empty(), "{:#?}", zenoh.process_problems);
    assert_eq!(zenoh.config_hash, inside.config_hash);
    assert!(zenoh.end_s > 0.0 && zenoh.robots.len() == 4, "{zenoh:#?}");
    assert!(zenoh.bytes_sent > 0, "the processes' links report what they sent: {zenoh:#?}");
    assert!(zenoh.goals_visited >= 1, "the UGVs visit goals over the link too: {zenoh:#?}");
    // A trial without problems leaves no working folder behind.
    assert!(!out.join("deployed").join("team-seed2-zenoh").exists());
    let csv = std::fs::read_to_string(out.join("trials.csv")).unwrap();
    assert!(csv.lines().any(|l| l.ends_with(",zenoh")) && csv.lines().any(|l| l.ends_with(",radio")), "{csv}");

    // The report sets them beside the in-process row; the study (claims, tables) is in-process.
    let o = spomp().args(["experiment", "report", "--json"]).arg(&out).output().unwrap();
    assert_eq!(o.status.code(), Some(0), "{}", String::from_utf8_lossy(&o.stderr));
    let report: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(report["trials"], 1, "{report:#}");
    let deployed = report["deployed"].as_array().unwrap();
    assert_eq!(deployed.len(), 2, "{report:#}");
    assert_eq!(deployed[0]["channel"], "radio");
    assert_eq!(deployed[0]["pairs"][0]["identical"], true, "{report:#}");
    assert_eq!(deployed[0]["clusters_ratio"], 1.0, "{report:#}");
    assert_eq!(deployed[1]["channel"], "zenoh");
    let md = std::fs::read_to_string(out.join("report.md")).unwrap();
    assert!(md.contains("## Deployed beside in-process") && md.contains("| team | zenoh | 2 |"), "{md}");

    // Resumed: every row (in-process and deployed) is there already.
    assert_eq!(run(&out, &["--resume"])["trials_run"], 0);
}
