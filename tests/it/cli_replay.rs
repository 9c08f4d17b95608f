//! `spomp replay` on logs of `spomp sim --replayable`: every robot replays identically, a
//! setting changed on replay diverges where the same change diverges in the simulator, a log
//! cut short replays to its end and says so.

#![allow(clippy::unwrap_used, clippy::expect_used)] // tests fail loudly by design

use std::path::{Path, PathBuf};

use crate::{root, spomp};
use spomp_mcap::{SeamCallMsg, decode_cdr, read_replay_log};

/// Runs `mission` for `seconds` with `--replayable`; the trial's log.
fn record(mission: &Path, seconds: &str, seed: &str, out: &Path) -> PathBuf {
    record_with(mission, seconds, seed, out, &[])
}

fn record_with(mission: &Path, seconds: &str, seed: &str, out: &Path, extra: &[&str]) -> PathBuf {
    let o = spomp()
        .current_dir(root())
        .args(["sim", "--replayable", "--json", "--time-limit-s", seconds, "--seed", seed, "--out"])
        .arg(out)
        .arg(mission)
        .args(extra)
        .output()
        .unwrap();
    assert!(matches!(o.status.code(), Some(0 | 1)), "{}", String::from_utf8_lossy(&o.stderr));
    out.join(format!("trial-{seed}")).join("run.mcap")
}

fn replay(log: &Path, robot: &str, extra: &[&str]) -> (Option<i32>, serde_json::Value) {
    let o = spomp().args(["replay", "--json", "--robot", robot]).arg(log).args(extra).output().unwrap();
    let report = serde_json::from_slice(&o.stdout).unwrap_or_else(|e| {
        panic!("{e}: {}\n{}", String::from_utf8_lossy(&o.stdout), String::from_utf8_lossy(&o.stderr))
    });
    (o.status.code(), report)
}

#[test]
fn every_robot_of_a_simulated_mission_replays_identically() {
    let out = tempfile::tempdir().unwrap();
    // Basestation, UAV and three UGVs: external poses, camera tiles, panoramas, team messages.
    let log = record(Path::new("missions/visit-all-vehicle-clusters.yaml"), "30", "3", out.path());
    for robot in ["base", "uav1", "ugv1", "ugv2", "ugv3"] {
        let (code, r) = replay(&log, robot, &[]);
        assert_eq!(code, Some(0), "{robot}: {r}");
        assert_eq!(r["identical"], true, "{r}");
        assert_eq!(r["truncated"], false, "{r}");
        assert!(r["replayed_to_s"].as_f64().unwrap() > 29.0, "{r}");
        assert!(r["ticks"].as_u64().unwrap() >= 290, "a tick every 0.1 s: {r}");
        assert!(r["team_messages"].as_u64().unwrap() > 0, "{r}");
        assert!(r["transitions"].as_u64().unwrap() > 0, "{r}");
    }
    // The human form says so.
    let o = spomp().args(["replay", "--robot", "ugv2"]).arg(&log).args(["--until", "5", "--trace"]).output().unwrap();
    assert_eq!(o.status.code(), Some(0));
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(text.trim_end().ends_with("identical"), "{text}");
    assert!(text.contains(" -> running"), "--trace prints transitions: {text}");
    // A robot the log does not hold, and no log at all: exit 2.
    spomp().args(["replay", "--robot", "ugv9"]).arg(&log).assert().code(2);
    spomp().args(["replay", "--robot", "ugv1", "no-such.mcap"]).assert().code(2);
}

#[test]
fn a_run_with_the_heavy_skills_in_the_background_replays_identically() {
    let out = tempfile::tempdir().unwrap();
    // Work taken and handed back a modelled compute time later, as `spomp run`'s worker
    // threads do: the replay repeats each hand-over where the log has it.
    let mission = Path::new("missions/visit-all-vehicle-clusters.yaml");
    let log = record_with(mission, "200", "2", out.path(), &["--skill-latency", "0.3,1.5"]);
    for robot in ["uav1", "ugv1", "ugv3"] {
        let (code, r) = replay(&log, robot, &[]);
        assert_eq!(code, Some(0), "{robot}: {r}");
        assert_eq!(r["identical"], true, "{r}");
        if robot.starts_with("ugv") {
            assert!(r["skill_jobs"].as_u64().unwrap() > 10, "{robot}: {r}");
        }
    }
    // A bad latency is a usage error.
    spomp().args(["sim", "--skill-latency", "fast"]).arg(root().join(mission)).assert().code(2);
}

/// The first log time at which `robot`'s outputs differ between two logs (tick commands, team
/// messages sent, node transitions).
fn first_output_difference(a: &Path, b: &Path, robot: &str) -> Option<f64> {
    let outputs = |p: &Path| -> Vec<(u64, String, Vec<u8>)> {
        let log = read_replay_log(&std::fs::read(p).unwrap()).unwrap();
        log.messages
            .iter()
            .filter_map(|m| {
                if m.topic == format!("/{robot}/bt") {
                    return Some((m.log_time, "bt".to_string(), m.data.clone()));
                }
                if m.topic != format!("/{robot}/seam") {
                    return None;
                }
                let msg: SeamCallMsg = decode_cdr(&m.topic, &m.data).unwrap();
                matches!(msg.call.as_str(), "tick" | "team_out").then(|| (m.log_time, msg.call, msg.data))
            })
            .collect()
    };
    let (xa, xb) = (outputs(a), outputs(b));
    xa.iter().zip(&xb).find(|(x, y)| x != y).map(|(x, y)| x.0.min(y.0) as f64 * 1e-9)
}

#[test]
fn a_setting_changed_on_replay_diverges_where_the_simulator_does() {
    let out = tempfile::tempdir().unwrap();
    // The patroller drives from the start; its terrain inflation shapes every command.
    let log = record(Path::new("missions/patrol-return-home.yaml"), "20", "2", &out.path().join("a"));
    let (code, r) = replay(&log, "ugv1", &[]);
    assert_eq!((code, &r["identical"]), (Some(0), &serde_json::json!(true)), "{r}");

    // The same run with the setting changed in the mission: where its outputs first differ is
    // where the replay must report the divergence (the inputs are the same up to there).
    let missions = out.path().join("missions");
    std::fs::create_dir_all(&missions).unwrap();
    let text = std::fs::read_to_string(root().join("missions/patrol-return-home.yaml")).unwrap();
    let changed = text.replace(
        "{ id: ugv1, kind: ugv, role: patroller, priority: 1,",
        "{ id: ugv1, kind: ugv, role: patroller, priority: 1, navigation: { terrain: { inflation_m: 0.9 } },",
    );
    assert_ne!(changed, text, "the mission's ugv1 line changed");
    let mission = missions.join("patrol-return-home.yaml");
    std::fs::write(&mission, changed).unwrap();
    // The subtrees it includes (the operator's branches) beside it, as in `missions/`.
    std::fs::create_dir_all(missions.join("subtrees")).unwrap();
    let subtree = "subtrees/operator.yaml";
    std::fs::copy(root().join("missions").join(subtree), missions.join(subtree)).unwrap();
    let changed_log = record(&mission, "20", "2", &out.path().join("b"));
    let expected = first_output_difference(&log, &changed_log, "ugv1").expect("inflation changes ugv1's commands");

    let (code, r) = replay(&log, "ugv1", &["--set", "navigation.terrain.inflation_m=0.9"]);
    assert_eq!(code, Some(1), "{r}");
    assert_eq!(r["identical"], false);
    let d = &r["divergence"];
    let at = d["time_s"].as_f64().unwrap();
    assert!((at - expected).abs() < 1e-6, "replay diverged at {at} s, the simulator at {expected} s: {d}");
    assert!(d["channel"].as_str().unwrap().starts_with("/ugv1/"), "{d}");
    assert_ne!(d["recorded"], d["replayed"]);

    // A setting that does not validate, or is not a navigation setting: exit 2.
    let o = spomp()
        .args(["replay", "--robot", "ugv1", "--set", "navigation.terrain.inflation_m=-3"])
        .arg(&log)
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(2), "{}", String::from_utf8_lossy(&o.stderr));
    spomp().args(["replay", "--robot", "ugv1", "--set", "priority=3"]).arg(&log).assert().code(2);
}

#[test]
fn a_log_cut_short_replays_to_its_end_and_says_so() {
    let out = tempfile::tempdir().unwrap();
    let log = record(Path::new("missions/patrol-return-home.yaml"), "20", "5", out.path());
    let bytes = std::fs::read(&log).unwrap();
    let cut = out.path().join("cut.mcap");
    std::fs::write(&cut, &bytes[..bytes.len() * 6 / 10]).unwrap();
    for robot in ["ugv1", "ugv2"] {
        let (code, r) = replay(&cut, robot, &[]);
        assert_eq!(code, Some(0), "{r}");
        assert_eq!(r["identical"], true, "{r}");
        assert_eq!(r["truncated"], true, "{r}");
        let end = r["replayed_to_s"].as_f64().unwrap();
        assert!(end > 1.0 && end < 19.0, "replayed part of the run: {r}");
        assert!(end <= r["log_end_s"].as_f64().unwrap() + 1e-9, "{r}");
    }
    let o = spomp().args(["replay", "--robot", "ugv1"]).arg(&cut).output().unwrap();
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(text.contains("cut short"), "{text}");
}

/// A log holding only `info`, the run's setup.
fn log_with_setup(info: &spomp_mcap::RunInfo, path: &Path) {
    let mut rec = spomp_mcap::Recorder::new(std::fs::File::create(path).unwrap(), Default::default()).unwrap();
    rec.run_info(info).unwrap();
    rec.finish().unwrap();
}

/// Regression (issue 36, item 1): a log whose setup names a file outside the replay's scratch
/// folder through a `..` after a name (`a/../../…/victim`) used to overwrite that file and still
/// replay `identical`. It must be refused before anything is written, with exit 2.
#[test]
fn a_crafted_log_cannot_write_outside_the_replay_folder() {
    let out = tempfile::tempdir().unwrap();
    let log = record(Path::new("missions/visit-all-vehicle-clusters.yaml"), "5", "1", out.path());
    let recorded = read_replay_log(&std::fs::read(&log).unwrap()).unwrap().info.unwrap();
    let victim_dir = tempfile::tempdir().unwrap();
    let victim = victim_dir.path().join("victim.txt");
    std::fs::write(&victim, "precious").unwrap();
    let absolute = victim.canonicalize().unwrap();
    let below_root = absolute.strip_prefix("/").unwrap().to_string_lossy().into_owned();
    let crafted = out.path().join("crafted.mcap");
    // The escape through a name is refused as such; an include outside the mission's folder
    // (leading `..` only) is legitimate and lands inside the scratch folder, deep enough.
    for (path, refused) in
        [(format!("a/{}{below_root}", "../".repeat(64)), true), (format!("../../../{below_root}"), false)]
    {
        let mut info = recorded.clone();
        info.files.push((path.clone(), "pwned".into()));
        log_with_setup(&info, &crafted);
        let o = spomp().args(["replay", "--robot", "ugv1"]).arg(&crafted).output().unwrap();
        assert_eq!(std::fs::read_to_string(&victim).unwrap(), "precious", "{path}: the victim was overwritten");
        // The log holds no seam calls: a replay that got past the setup stops there, exit 2 too.
        assert_eq!(o.status.code(), Some(2), "{path}: {}", String::from_utf8_lossy(&o.stdout));
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(err.contains("`..` after a name"), refused, "{path}: {err}");
    }
}
