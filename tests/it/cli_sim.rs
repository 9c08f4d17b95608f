//! `spomp sim` and `spomp validate --dry-run` as a user runs them: outputs on disk, JSON
//! summaries, exit codes, fault flags and bad input.

#![allow(clippy::unwrap_used, clippy::expect_used)] // tests fail loudly by design

use crate::{root, spomp};

#[test]
fn sim_writes_summaries_log_and_plots_for_every_trial() {
    let out_dir = tempfile::tempdir().unwrap();
    let out = spomp()
        .current_dir(root())
        .args(["sim", "missions/patrol-return-home.yaml", "--time-limit-s", "20", "--trials", "2", "--seed", "4"])
        .args(["--json", "--out"])
        .arg(out_dir.path())
        .output()
        .unwrap();
    // Twenty seconds do not finish the patrol: the mission did not complete, exit 1.
    assert_eq!(out.status.code(), Some(1), "{}", String::from_utf8_lossy(&out.stderr));
    let combined: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(combined["trials"], 2);
    let runs = combined["runs"].as_array().unwrap();
    assert_eq!(runs.iter().map(|r| r["seed"].as_u64().unwrap()).collect::<Vec<_>>(), vec![4, 5]);
    for run in runs {
        assert_eq!(run["outcome"], "time_limit");
        assert!((run["end_s"].as_f64().unwrap() - 20.0).abs() < 1.0);
        let ugv1 = run["robots"].as_array().unwrap().iter().find(|r| r["id"] == "ugv1").unwrap();
        assert!(ugv1["distance_m"].as_f64().unwrap() > 5.0, "the patroller drove: {ugv1}");
        assert_eq!(ugv1["localization"], "ground_truth");
    }
    assert!(out_dir.path().join("summary.json").is_file());
    for seed in [4, 5] {
        let trial = out_dir.path().join(format!("trial-{seed}"));
        for f in ["summary.json", "run.mcap", "plots/map.png", "plots/goal_visits.png", "plots/localization_error.png"]
        {
            let p = trial.join(f);
            assert!(p.metadata().map(|m| m.len() > 0).unwrap_or(false), "{} missing or empty", p.display());
        }
        // The error over time of every UGV, at most once a second (20 s of the patroller's).
        let csv = std::fs::read_to_string(trial.join("localization_error.csv")).unwrap();
        let mut lines = csv.lines();
        assert_eq!(lines.next(), Some("robot,time_s,error_m"));
        let rows: Vec<(f64, f64)> = lines
            .filter(|l| l.starts_with("ugv1,"))
            .map(|l| {
                let f: Vec<&str> = l.split(',').collect();
                (f[1].parse().unwrap(), f[2].parse().unwrap())
            })
            .collect();
        assert!((15..=21).contains(&rows.len()), "{csv}");
        assert!(rows.windows(2).all(|w| w[1].0 - w[0].0 >= 0.99), "at most 1 Hz: {csv}");
        // ugv1 takes ground truth with 0.3 m noise; ugv2 (the guard) localizes cross-view.
        assert!(rows.iter().all(|&(_, e)| (0.0..2.0).contains(&e)), "ground truth with noise: {csv}");
        assert!(csv.lines().any(|l| l.starts_with("ugv2,")), "every UGV has a series: {csv}");
        let mcap = std::fs::read(trial.join("run.mcap")).unwrap();
        assert!(mcap.starts_with(b"\x89MCAP0\r\n"), "an MCAP file");
    }
}

#[test]
fn sim_refuses_invalid_missions_and_bad_flags() {
    let out = spomp().current_dir(root()).args(["sim", "tests/missions/invalid-unknown-port.yaml"]).output().unwrap();
    assert_eq!(out.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&out.stdout).contains("invalid-unknown-port.yaml:"));
    spomp().current_dir(root()).args(["sim", "missions/manual-goals.yaml", "--kill", "ugv1"]).assert().code(2);
    spomp().current_dir(root()).args(["sim", "missions/manual-goals.yaml", "--blackout", "9..3"]).assert().code(2);
}

#[test]
fn killed_robot_stops_where_the_flag_says() {
    let out_dir = tempfile::tempdir().unwrap();
    let out = spomp()
        .current_dir(root())
        .args(["sim", "missions/patrol-return-home.yaml", "--time-limit-s", "15", "--no-mcap", "--json"])
        .args(["--kill", "ugv1@5", "--out"])
        .arg(out_dir.path())
        .output()
        .unwrap();
    let combined: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let robots = combined["runs"][0]["robots"].as_array().unwrap().clone();
    let ugv1 = robots.iter().find(|r| r["id"] == "ugv1").unwrap();
    assert!((ugv1["killed_s"].as_f64().unwrap() - 5.0).abs() < 0.2, "{ugv1}");
    // At most 1.5 m/s for 5 s.
    assert!(ugv1["distance_m"].as_f64().unwrap() <= 7.6, "{ugv1}");
    assert!(!out_dir.path().join("trial-1/run.mcap").exists());
}

#[test]
fn dry_run_reports_outcome_and_unticked_nodes() {
    let dir = tempfile::tempdir().unwrap();
    let mission = dir.path().join("short.yaml");
    std::fs::write(
        &mission,
        r#"
mission: short
team:
  - { id: ugv1, kind: ugv, role: r, priority: 1, start: { x_m: 12, y_m: 2.5 }, localization: { mode: ground_truth } }
roles:
  r:
    tree:
      fallback:
        - wait: { duration_s: 2 }
        - fail:
complete_when: all_trees_done
time_limit_s: 30
sim: { world: { generate: { size_m: [120, 100], vehicle_clusters: 1, roadblocks: 0 } } }
"#,
    )
    .unwrap();
    let out = spomp().args(["validate", "--dry-run", "--json"]).arg(&mission).output().unwrap();
    assert_eq!(out.status.code(), Some(0), "{}", String::from_utf8_lossy(&out.stdout));
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let run = &v["dry_runs"][0]["dry_run"];
    assert_eq!(run["outcome"], "complete");
    assert!(run["end_s"].as_f64().unwrap() < 5.0);
    let never: Vec<String> =
        run["never_ticked"].as_array().unwrap().iter().map(|s| s.as_str().unwrap().to_string()).collect();
    assert_eq!(never, vec!["ugv1: r/fallback[1]/fail".to_string()]);
}

/// The paper's ablation switches and a robot's own terrain threshold, set in the mission
/// (`navigation:` per role, overridden per robot), are the settings the robots run with.
#[test]
fn navigation_settings_in_the_mission_are_in_force_per_robot() {
    let dir = tempfile::tempdir().unwrap();
    let mission = dir.path().join("ablation.yaml");
    std::fs::write(
        &mission,
        r#"
mission: ablation
team:
  - { id: ugv1, kind: ugv, role: r, priority: 1, start: { x_m: 12, y_m: 2.5 }, localization: { mode: ground_truth } }
  - id: ugv2
    kind: ugv
    role: r
    priority: 2
    start: { x_m: 12, y_m: 6 }
    localization: { mode: ground_truth }
    navigation:
      terrain: { inflation_m: 0.9 }
      global_planner: { learning: off, graph_updates: off }
roles:
  r:
    navigation: { profile: simulation, watchdog: { stuck_timeout_s: 45 } }
    tree:
      navigate_to: { target: { x: 60, y: 4 } }
complete_when: all_trees_done
time_limit_s: 10
sim: { world: { generate: { size_m: [120, 100], vehicle_clusters: 1, roadblocks: 0 } } }
"#,
    )
    .unwrap();
    let out_dir = dir.path().join("out");
    let out = spomp().args(["sim", "--json", "--no-mcap", "--out"]).arg(&out_dir).arg(&mission).output().unwrap();
    assert!(out.status.code().is_some_and(|c| c <= 1), "{}", String::from_utf8_lossy(&out.stderr));
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let robots = v["runs"][0]["robots"].as_array().unwrap();
    let nav = |id: &str| robots.iter().find(|r| r["id"] == id).unwrap()["navigation"].clone();
    let (u1, u2) = (nav("ugv1"), nav("ugv2"));
    assert_eq!((u1["learning"].as_bool(), u1["graph_updates"].as_bool()), (Some(true), Some(true)), "{u1}");
    assert_eq!(u1["inflation_m"], 0.75, "the simulation profile: {u1}");
    assert_eq!(u1["stuck_timeout_s"], 45.0, "the role's watchdog: {u1}");
    assert_eq!((u2["learning"].as_bool(), u2["graph_updates"].as_bool()), (Some(false), Some(false)), "{u2}");
    assert_eq!(u2["inflation_m"], 0.9, "the robot's own override: {u2}");
    assert_eq!(u2["slope_threshold"], 0.25, "the rest from its role's profile: {u2}");
}

/// Issue 33: a UGV wedged at the tip of a dead-end pocket (a flat gravel wedge between a
/// building and 1 m vegetation, tests/worlds/wedge), facing the tip with the only goal beyond
/// it, must get itself out with the shipped recovery subtree (`drive_with_recovery`: no
/// progress detected, the edge it stands on marked failed, backed out or turned about, driven
/// again) and visit the goal by the south road. At the tip its terrain analysis finds no safe
/// ground and its scans cannot judge the edge it is on, so the forward-only controller commands
/// nothing while the planner's path leads on through the tip: with the recovery subtree
/// replaced by a plain `navigate_to`, or with failed-edge learning off (`graph_updates: off`),
/// the UGV stays at the tip until the time limit (checked when this test was written).
#[test]
fn a_ugv_wedged_in_a_dead_end_pocket_gets_itself_out_and_visits_the_goal() {
    let out_dir = tempfile::tempdir().unwrap();
    let out = spomp()
        .current_dir(root())
        .args(["sim", "tests/worlds/wedge/wedge-mission.yaml", "--allow-dir", "missions/subtrees", "--seed", "1"])
        .args(["--no-mcap", "--pano-every-s", "0", "--json", "--out"])
        .arg(out_dir.path())
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert_eq!(out.status.code(), Some(0), "{stdout}\n{}", String::from_utf8_lossy(&out.stderr));
    let combined: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let run = &combined["runs"][0];
    assert_eq!(run["outcome"], "complete", "{run}");
    assert_eq!(run["goals_visited"], 1, "{run}");
    let ugv1 = run["robots"].as_array().unwrap().iter().find(|r| r["id"] == "ugv1").unwrap();
    assert_eq!(ugv1["goals_visited"], 1, "{ugv1}");
    assert_eq!(ugv1["tree_status"], "success", "{ugv1}");
    // It was wedged: the first drive reported no progress, and the recovery took over.
    let problems = run["problems"].as_array().unwrap();
    let said =
        |what: &str| problems.iter().any(|p| p["robot"] == "ugv1" && p["message"].as_str().unwrap().contains(what));
    assert!(said("no progress"), "the UGV was never wedged: {problems:?}");
    // Out of the pocket and round by the south road (the tip is 25 m from the goal as the crow
    // flies; the road is about 90 m).
    let driven = ugv1["distance_m"].as_f64().unwrap();
    assert!(driven > 60.0, "drove {driven} m: {ugv1}");
    let still = ugv1["longest_motionless_driving_s"].as_f64().unwrap();
    assert!(still <= 120.0, "motionless for {still} s while driven (issue 33 bound: 120 s): {ugv1}");
    // A refusal the simulator counted is reported too, never silent.
    let stuck = ugv1["stuck_events"].as_u64().unwrap();
    assert_eq!(stuck > 0, said("stuck at"), "stuck events {stuck} against problems {problems:?}");
}

/// Regression (the paper study's sharing-all trial, seed 5): the three UGVs came east along a
/// road to a roadblock labelled road (so the aerial map does not show it) and stood against it
/// from 300 s to the time limit, visiting nothing. Two defects: a robot's own scan in which any
/// bin ended at a teammate removed no edge at all, so robots queued behind one another kept the
/// road through the block; and a robot standing at the block lay in the region of the graph node
/// beyond it, so every plan began with a straight leg through the block that no scan or failed
/// drive could remove.
#[test]
fn three_ugvs_meeting_a_roadblock_the_aerial_map_does_not_show_all_get_past_it() {
    let out_dir = tempfile::tempdir().unwrap();
    let out = spomp()
        .current_dir(root())
        .args(["experiment", "tests/experiments/hidden-roadblock.yaml", "--allow-dir", "missions"])
        .args(["--jobs", "1", "--json", "--out"])
        .arg(out_dir.path())
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(0), "{}", String::from_utf8_lossy(&out.stderr));
    let rows = std::fs::read_to_string(out_dir.path().join("trials.jsonl")).unwrap();
    let row: serde_json::Value = serde_json::from_str(rows.lines().next().unwrap()).unwrap();
    let visited = row["clusters_visited"].as_u64().unwrap();
    let total = row["clusters_total"].as_u64().unwrap();
    assert!(visited * 4 >= total * 3, "{visited} of {total} clusters visited: {row}");
    for ugv in row["robots"].as_array().unwrap().iter().filter(|r| r["kind"] == "ugv") {
        assert!(ugv["goals_visited"].as_u64().unwrap() >= 1, "a UGV stayed at the block: {ugv}");
        assert!(ugv["distance_m"].as_f64().unwrap() > 500.0, "{ugv}");
    }
}
