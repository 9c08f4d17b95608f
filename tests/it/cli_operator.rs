//! `spomp operator` and the operator interfaces of `spomp run`: what is refused before anything
//! is issued (no robot needed; the team link listens nowhere and reaches nobody).

#![allow(clippy::unwrap_used, clippy::expect_used)] // tests fail loudly by design

use std::path::PathBuf;

use super::{root, spomp};

const MISSION: &str = "tests/missions/ros2/farm-operator.yaml";

/// A fresh key folder of the test mission's team.
fn keys(name: &str) -> (tempfile::TempDir, PathBuf) {
    let dir = tempfile::tempdir().unwrap();
    let keys = dir.path().join(name);
    spomp().current_dir(root()).args(["keys", "generate", MISSION, "--out"]).arg(&keys).assert().success();
    (dir, keys)
}

/// `spomp operator` reaching nobody (a closed loopback port), waiting `wait_s`.
fn operator(keys: &std::path::Path, wait_s: &str, command: &[&str]) -> std::process::Output {
    spomp()
        .current_dir(root())
        .args(["operator", MISSION, "--keys"])
        .arg(keys)
        .args(["--connect", "tcp/127.0.0.1:9", "--wait-s", wait_s])
        .args(command)
        .output()
        .unwrap()
}

#[test]
fn keys_generate_writes_the_operators_key_beside_the_robots() {
    let (_dir, keys) = keys("k");
    for f in ["team.json", "transport.passwords", "base.key.json", "ugv1.key.json", "operator.key.json"] {
        assert!(keys.join(f).is_file(), "{f}");
    }
}

#[test]
fn a_robot_that_is_not_the_teams_is_refused_before_waiting_for_anyone() {
    let (_dir, keys) = keys("k");
    let started = std::time::Instant::now();
    let out = operator(&keys, "60", &["recall", "ugv9"]);
    assert_eq!(out.status.code(), Some(1));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("`ugv9` is no robot of the team (base, ugv1, ugv2) nor `all`"), "{err}");
    assert!(started.elapsed().as_secs() < 50, "it waited for the robots first");
}

#[test]
fn without_the_operators_key_nothing_is_issued_and_the_file_is_named() {
    let (_dir, keys) = keys("k");
    std::fs::remove_file(keys.join("operator.key.json")).unwrap();
    let out = operator(&keys, "1", &["goal", "add", "--at", "10,20"]);
    assert_eq!(out.status.code(), Some(1));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("operator.key.json"), "{err}");
}

#[test]
fn a_status_that_reaches_no_robot_exits_2_and_says_so() {
    let (_dir, keys) = keys("k");
    let out = operator(&keys, "1", &["--json", "status"]);
    // `--json` belongs before the subcommand; after it clap refuses it.
    assert_eq!(out.status.code(), Some(2), "{}", String::from_utf8_lossy(&out.stderr));
    let out = spomp()
        .current_dir(root())
        .args(["operator", MISSION, "--keys"])
        .arg(&keys)
        .args(["--connect", "tcp/127.0.0.1:9", "--wait-s", "1", "--json", "status"])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2), "{}", String::from_utf8_lossy(&out.stderr));
    let status: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let robots = status["robots"].as_array().unwrap();
    assert_eq!(robots.len(), 3);
    assert!(robots.iter().all(|r| r["reachable"] == false && r["last_heard_s"].is_null()), "{status:#}");
}

#[test]
fn a_robot_serving_an_operator_interface_needs_the_operators_key() {
    let run = |extra: &[&str], keys: Option<&std::path::Path>| {
        let mut cmd = spomp();
        cmd.current_dir(root()).args(["run", MISSION, "--robot", "base"]).args(extra);
        if let Some(k) = keys {
            cmd.arg("--keys").arg(k);
        }
        cmd.env("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST").output().unwrap()
    };
    let out = run(&["--clicked-point"], None);
    assert_eq!(out.status.code(), Some(1));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("--clicked-point needs --keys DIR with the operator's key (operator.key.json)"), "{err}");
    let (_dir, keys) = keys("k");
    std::fs::remove_file(keys.join("operator.key.json")).unwrap();
    let out = run(&["--live", "127.0.0.1:0", "--live-operator"], Some(&keys));
    assert_eq!(out.status.code(), Some(1));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("--live-operator") && err.contains("operator.key.json"), "{err}");
    // --live-operator means nothing without the live view.
    assert_eq!(run(&["--live-operator"], None).status.code(), Some(2));
}
