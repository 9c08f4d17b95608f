//! `spomp experiment` as a user runs it on `experiments/smoke.yaml`: a one-shot run, the same
//! study as two shards merged by `report`, a run resumed after losing half its rows and a row
//! cut in half by a crash, and a run stopped by Ctrl-C then resumed all give the same trial rows; an edited experiment is refused on
//! resume; bad input and bad usage have their exit codes.

#![allow(clippy::unwrap_used, clippy::expect_used)] // tests fail loudly by design

use std::io::Write;
use std::path::Path;

use crate::{root, spomp};
use spomp::experiment::rows::{TrialRow, read_rows};

const SMOKE: &str = "experiments/smoke.yaml";

/// Runs `spomp experiment SMOKE --out DIR EXTRA...` and returns its JSON summary.
fn run(out: &Path, extra: &[&str]) -> serde_json::Value {
    let o = spomp()
        .current_dir(root())
        .args(["experiment", SMOKE, "--json", "--jobs", "2", "--out"])
        .arg(out)
        .args(extra)
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(0), "{}", String::from_utf8_lossy(&o.stderr));
    serde_json::from_slice(&o.stdout).unwrap()
}

/// Rows without wall-clock time, in trial order.
fn deterministic(mut rows: Vec<TrialRow>) -> Vec<TrialRow> {
    rows.sort_by_key(|r| r.trial);
    rows.iter().map(TrialRow::deterministic_part).collect()
}

#[test]
fn shards_merged_and_a_resumed_run_equal_one_run() {
    let tmp = tempfile::tempdir().unwrap();
    let one = tmp.path().join("one");
    let summary = run(&one, &[]);
    assert_eq!(summary["trials_run"], 4);
    let reference = deterministic(read_rows(&one).unwrap());
    assert_eq!(reference.len(), 4);
    let keys: Vec<(usize, &str, u64)> = reference.iter().map(|r| (r.trial, r.configuration.as_str(), r.seed)).collect();
    assert_eq!(keys, [(0, "ugv1", 1), (1, "ugv1", 2), (2, "ugv2-class-ranks", 1), (3, "ugv2-class-ranks", 2)]);
    assert_eq!(reference[0].ugvs, 1);
    assert_eq!(reference[2].ugvs, 2);
    assert!(reference.iter().all(|r| r.end_s > 29.0 && r.distance_m > 1.0), "{reference:#?}");
    let csv = std::fs::read_to_string(one.join("trials.csv")).unwrap();
    assert_eq!(csv.lines().count(), 5, "{csv}");

    // Two shards: interleaved trials (index mod 2), merged by `report`.
    let (a, b) = (tmp.path().join("shard1"), tmp.path().join("shard2"));
    assert_eq!(run(&a, &["--shard", "1/2"])["trials_run"], 2);
    assert_eq!(run(&b, &["--shard", "2/2"])["trials_run"], 2);
    let shard1: Vec<usize> = read_rows(&a).unwrap().iter().map(|r| r.trial).collect();
    assert!(shard1.iter().all(|t| t % 2 == 0), "{shard1:?}");
    let merged = tmp.path().join("merged");
    let o = spomp()
        .args(["experiment", "report", "--json", "--out"])
        .arg(&merged)
        .arg(&a)
        .arg(&b)
        .arg(&one) // the same trials a third time: equal duplicates count once
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(0), "{}", String::from_utf8_lossy(&o.stderr));
    let report: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(report["trials"], 4);
    assert_eq!(report["claims"].as_array().unwrap().len(), 1);
    let text = std::fs::read_to_string(merged.join("merged-trials.jsonl")).unwrap();
    let merged_rows: Vec<TrialRow> = text.lines().map(|l| serde_json::from_str(l).unwrap()).collect();
    assert_eq!(deterministic(merged_rows), reference);
    let md = std::fs::read_to_string(merged.join("report.md")).unwrap();
    assert!(md.contains("| ugv1 | 2 |") && md.contains("## Claims"), "{md}");
    for plot in ["goals_over_time.png", "metrics.png"] {
        assert!(std::fs::metadata(merged.join("plots").join(plot)).unwrap().len() > 1000, "{plot}");
    }

    // Resume: a folder with one shard's rows and a row a crash cut in half.
    let resumed = tmp.path().join("resumed");
    run(&resumed, &["--shard", "2/2"]);
    let mut f = std::fs::OpenOptions::new().append(true).open(resumed.join("trials.jsonl")).unwrap();
    f.write_all(b"{\"trial\":0,\"configuration\":\"ugv1\",\"se").unwrap();
    drop(f);
    // Without --resume the folder is refused (usage).
    spomp().current_dir(root()).args(["experiment", SMOKE, "--out"]).arg(&resumed).assert().code(2);
    let summary = run(&resumed, &["--resume"]);
    assert_eq!((summary["trials_run"].as_u64(), summary["trials_skipped"].as_u64()), (Some(2), Some(2)));
    assert_eq!(deterministic(read_rows(&resumed).unwrap()), reference);
    let csv = std::fs::read_to_string(resumed.join("trials.csv")).unwrap();
    assert_eq!(csv.lines().count(), 5, "the CSV is rebuilt from the record: {csv}");
    // Nothing left to do.
    assert_eq!(run(&resumed, &["--resume"])["trials_run"], 0);

    // Ctrl-C after the first row: the finished rows stay, the rest resumes to the same rows.
    #[cfg(unix)]
    {
        let interrupted = tmp.path().join("interrupted");
        let mut child = std::process::Command::new(assert_cmd::cargo::cargo_bin("spomp"))
            .current_dir(root())
            .args(["experiment", SMOKE, "--json", "--jobs", "1", "--out"])
            .arg(&interrupted)
            .stdout(std::process::Stdio::null())
            .spawn()
            .unwrap();
        let deadline = std::time::Instant::now() + std::time::Duration::from_secs(120);
        while read_rows(&interrupted).map_or(0, |r| r.len()) == 0 {
            assert!(std::time::Instant::now() < deadline, "no row within 120 s");
            std::thread::sleep(std::time::Duration::from_millis(20));
        }
        let sent = std::process::Command::new("kill").args(["-INT", &child.id().to_string()]).status().unwrap();
        assert!(sent.success());
        let status = child.wait().unwrap();
        let kept = read_rows(&interrupted).unwrap().len();
        // 130 unless every trial had finished by the time the signal arrived.
        assert!(status.code() == Some(130) || (status.code() == Some(0) && kept == 4), "{status:?}, {kept} rows");
        assert!(kept >= 1);
        run(&interrupted, &["--resume"]);
        assert_eq!(deterministic(read_rows(&interrupted).unwrap()), reference);
    }

    // A conflicting duplicate (the same trial with other results) is an error in `report`.
    let forged = tmp.path().join("forged");
    std::fs::create_dir_all(&forged).unwrap();
    std::fs::copy(one.join("experiment.json"), forged.join("experiment.json")).unwrap();
    let mut row = read_rows(&one).unwrap().remove(0);
    row.goals_visited += 1;
    std::fs::write(forged.join("trials.jsonl"), format!("{}\n", serde_json::to_string(&row).unwrap())).unwrap();
    let o = spomp().args(["experiment", "report"]).arg(&one).arg(&forged).output().unwrap();
    assert_eq!(o.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&o.stderr).contains("differ"), "{}", String::from_utf8_lossy(&o.stderr));

    // An edited experiment (another time limit) is refused on resume.
    let edited = tmp.path().join("edited.yaml");
    let smoke = std::fs::read_to_string(root().join(SMOKE)).unwrap();
    let missions = root().join("missions");
    let text = smoke.replace("time_limit_s: 30", "time_limit_s: 20").replace(
        "mission: ../missions/manual-goals.yaml",
        &format!("mission: {}", missions.join("manual-goals.yaml").display()),
    );
    std::fs::write(&edited, text).unwrap();
    let o = spomp()
        .args(["experiment", "--resume", "--allow-dir"])
        .arg(&missions)
        .arg(&edited)
        .arg("--out")
        .arg(&one)
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(1), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(String::from_utf8_lossy(&o.stderr).contains("another version"), "{}", String::from_utf8_lossy(&o.stderr));
}

#[test]
fn bad_files_and_bad_usage_have_their_exit_codes() {
    let tmp = tempfile::tempdir().unwrap();
    let o = spomp()
        .current_dir(root())
        .args(["experiment", "tests/experiments/invalid-navigation-override.yaml", "--out"])
        .arg(tmp.path())
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(1));
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(stdout.contains("invalid-navigation-override.yaml:9:17"), "{stdout}");
    for bad in ["0/2", "3/2", "1", "a/b"] {
        spomp().current_dir(root()).args(["experiment", SMOKE, "--shard", bad]).assert().code(2);
    }
    spomp().args(["experiment", "report"]).assert().code(2);
    // A folder that holds no experiment.
    spomp().args(["experiment", "report"]).arg(tmp.path()).assert().code(1);
    spomp().args(["experiment", "validate", "experiments/smoke.yaml"]).current_dir(root()).assert().code(0);
    let schema = spomp().args(["experiment", "schema"]).output().unwrap();
    let v: serde_json::Value = serde_json::from_slice(&schema.stdout).unwrap();
    assert!(v["properties"]["configurations"].is_object(), "{v}");
}
