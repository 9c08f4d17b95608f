//! The memory stage of `spomp validate`: a team estimated not to fit is refused with the figures,
//! at the mission's `team`; `--memory-budget-mb` checks against a given budget and
//! `--ignore-memory` skips the stage; the shipped missions fit.

#![allow(clippy::unwrap_used, clippy::expect_used)] // tests fail loudly by design

use std::path::{Path, PathBuf};

use assert_cmd::Command;

/// A mission with `ugvs` UGVs (and a basestation) on a generated city of `size_m`.
fn team_mission(dir: &Path, ugvs: usize, size_m: [u32; 2]) -> PathBuf {
    let mut text = String::from(
        "mission: big-team\nteam:\n  - { id: base, kind: basestation, role: base, start: { x_m: 0, y_m: 0 } }\n",
    );
    for i in 1..=ugvs {
        text.push_str(&format!(
            "  - {{ id: u{i}, kind: ugv, role: visitor, priority: {i}, start: {{ x_m: {}, y_m: {} }} }}\n",
            i % 100,
            i / 100
        ));
    }
    text.push_str(&format!(
        "goals:\n  manual:\n    - {{ x_m: 50, y_m: 20 }}\nroles:\n  visitor:\n    tree:\n      sequence:\n        \
         - claim_goal: {{ goal: \"{{goal}}\", goal_position: \"{{goal_position}}\" }}\n        \
         - navigate_to: {{ target: \"{{goal_position}}\" }}\n        \
         - mark_visited: {{ goal: \"{{goal}}\" }}\n  base:\n    tree:\n      wait: {{ duration_s: 10 }}\n\
         time_limit_s: 1800\nsim:\n  world: {{ generate: {{ size_m: [{}, {}], vehicle_clusters: 3, roadblocks: 0 }} }}\n",
        size_m[0], size_m[1]
    ));
    let path = dir.join("big-team.yaml");
    std::fs::write(&path, text).unwrap();
    path
}

fn validate(args: &[&str]) -> (i32, String) {
    let out = Command::cargo_bin("spomp").unwrap().arg("validate").args(args).output().unwrap();
    (out.status.code().unwrap_or(-1), String::from_utf8_lossy(&out.stdout).into_owned())
}

/// The first "about N MB" figure of a message, megabytes.
fn needed_mb(message: &str) -> f64 {
    let rest = message.split("needs about ").nth(1).expect("the message names what the run needs");
    rest.split(" MB").next().unwrap().parse().unwrap()
}

#[test]
fn an_absurd_team_is_refused_with_the_figures_at_the_team() {
    let dir = tempfile::tempdir().unwrap();
    let mission = team_mission(dir.path(), 999, [400, 300]);
    let file = mission.to_str().unwrap();
    let (code, stdout) = validate(&[file, "--json", "--memory-budget-mb", "8000"]);
    assert_eq!(code, 1, "{stdout}");
    let diagnostics: serde_json::Value = serde_json::from_str(&stdout).unwrap();
    let diagnostics = diagnostics.as_array().unwrap();
    assert_eq!(diagnostics.len(), 1, "{diagnostics:#?}");
    let d = &diagnostics[0];
    assert_eq!(d["stage"], "memory");
    assert_eq!(d["severity"], "error");
    assert_eq!(d["node_path"], "team");
    assert_eq!((d["line"].as_u64(), d["column"].as_u64()), (Some(3), Some(3)), "at the team's first robot");
    let message = d["message"].as_str().unwrap();
    for part in ["999 UGV(s) × ", "1 basestation(s)", "the budget given is 8000 MB", "cannot fit", "--ignore-memory"] {
        assert!(message.contains(part), "`{part}` missing from: {message}");
    }
    assert!(needed_mb(message) > 8000.0, "{message}");

    // The human form names the file and line too.
    let (code, stdout) = validate(&[file, "--memory-budget-mb", "8000"]);
    assert_eq!(code, 1);
    assert!(stdout.contains(&format!("{file}:3:3: [memory] at team:")), "{stdout}");

    // Skipping the stage: valid.
    let (code, stdout) = validate(&[file, "--ignore-memory"]);
    assert_eq!(code, 0, "{stdout}");
}

#[test]
fn a_team_that_cannot_fit_this_machine_is_refused_with_its_figures() {
    // 999 UGVs over a 5 km square city need hundreds of GB: more than any machine running the
    // tests has available.
    let dir = tempfile::tempdir().unwrap();
    let mission = team_mission(dir.path(), 999, [5000, 5000]);
    let (code, stdout) = validate(&[mission.to_str().unwrap()]);
    assert_eq!(code, 1, "{stdout}");
    assert!(stdout.contains("[memory]") && stdout.contains("this machine has"), "{stdout}");
    assert!(needed_mb(&stdout) > 100_000.0, "{stdout}");
}

#[test]
fn the_shipped_mission_fits_a_small_machine_and_a_tight_budget_warns() {
    let mission = Path::new(env!("CARGO_MANIFEST_DIR")).join("missions/visit-all-vehicle-clusters.yaml");
    let file = mission.to_str().unwrap();
    let (code, stdout) = validate(&[file, "--memory-budget-mb", "10"]);
    assert_eq!(code, 1, "{stdout}");
    let need = needed_mb(&stdout);
    assert!((60.0..400.0).contains(&need), "a few hundred MB at most for 1 UAV + 3 UGVs: {stdout}");
    let (code, stdout) = validate(&[file, "--memory-budget-mb", "1000"]);
    assert_eq!(code, 0, "{stdout}");
    assert!(!stdout.contains("[memory]"), "{stdout}");
    // A budget it nearly fills: a warning, still valid.
    let tight = format!("{}", (need / 0.9).ceil());
    let (code, stdout) = validate(&[file, "--memory-budget-mb", &tight]);
    assert_eq!(code, 0, "{stdout}");
    assert!(stdout.contains("[memory]") && stdout.contains("close to what is available"), "{stdout}");
}

#[test]
fn spomp_sim_refuses_a_team_that_cannot_fit_before_it_starts() {
    let dir = tempfile::tempdir().unwrap();
    let mission = team_mission(dir.path(), 999, [5000, 5000]);
    let out = Command::cargo_bin("spomp")
        .unwrap()
        .args(["sim", mission.to_str().unwrap(), "--no-mcap", "--out"])
        .arg(dir.path().join("runs"))
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{stderr}");
    assert!(stderr.contains("cannot fit") && stderr.contains("give --force"), "{stderr}");
    assert!(needed_mb(&stderr) > 100_000.0, "{stderr}");
    assert!(!dir.path().join("runs").exists(), "nothing is written before the check");
}

#[test]
fn spomp_experiment_refuses_a_configuration_that_cannot_fit_before_it_starts() {
    let dir = tempfile::tempdir().unwrap();
    team_mission(dir.path(), 999, [5000, 5000]);
    let experiment = dir.path().join("huge.yaml");
    std::fs::write(
        &experiment,
        "experiment: huge\nmission: big-team.yaml\nseeds: [1, 2]\ntime_limit_s: 60\n\
         configurations:\n  - name: small\n    ugvs: 1\n    \
         world: { generate: { size_m: [100, 100], vehicle_clusters: 3, roadblocks: 0 } }\n  - name: everyone\n",
    )
    .unwrap();
    let out_dir = dir.path().join("runs");
    let out = Command::cargo_bin("spomp")
        .unwrap()
        .args(["experiment", experiment.to_str().unwrap(), "--json", "--out"])
        .arg(&out_dir)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{stderr}");
    // The small configuration fits; the check goes on to the one that does not, and names it.
    assert!(stderr.contains("configuration `everyone`: "), "the configuration is named: {stderr}");
    assert!(stderr.contains("999 UGV(s) × "), "{stderr}");
    assert!(stderr.contains("cannot fit") && stderr.contains("give --force"), "{stderr}");
    assert!(needed_mb(&stderr) > 100_000.0, "{stderr}");
    assert!(!out_dir.exists(), "nothing is written before the check");
}
