//! The command line as a user meets it: exit codes, JSON output, the shipped schema.

#![allow(clippy::unwrap_used, clippy::expect_used)] // tests fail loudly by design

use crate::{root, spomp};

/// The README's test command tests the whole product: the binary it builds is the `deploy`
/// build, and says so (a default build's `--version` names the feature robots need).
#[test]
fn the_test_build_is_the_deploy_build() {
    let out = spomp().arg("--version").output().unwrap();
    assert!(out.status.success());
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(text.contains("(deploy build"), "{text}");
}

#[test]
fn validate_exit_codes() {
    spomp().current_dir(root()).args(["validate", "missions/visit-all-vehicle-clusters.yaml"]).assert().code(0);
    spomp().current_dir(root()).args(["validate", "tests/missions/invalid-unknown-port.yaml"]).assert().code(1);
    spomp().current_dir(root()).args(["validate"]).assert().code(2);
    spomp().current_dir(root()).args(["validate", "--no-such-flag", "x.yaml"]).assert().code(2);
    spomp().current_dir(root()).args(["validate", "does-not-exist.yaml"]).assert().code(1);
}

#[test]
fn validate_json_lists_diagnostics_with_positions() {
    let out = spomp()
        .current_dir(root())
        .args(["validate", "--json", "tests/missions/invalid-several-errors.yaml", "missions/manual-goals.yaml"])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(1));
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let arr = v.as_array().unwrap();
    assert_eq!(arr.len(), 3);
    for d in arr {
        for key in ["file", "line", "column", "node_path", "message"] {
            assert!(d.get(key).is_some(), "missing {key} in {d}");
        }
    }
    assert_eq!(arr[0]["line"], 7);
    assert_eq!(arr[0]["node_path"], "team[1].speed");
}

#[test]
fn shipped_schema_is_current() {
    let out = spomp().arg("schema").output().unwrap();
    assert!(out.status.success());
    let generated: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let shipped: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(root().join("missions/mission.schema.json")).unwrap()).unwrap();
    assert!(
        generated == shipped,
        "missions/mission.schema.json is stale: run `cargo run -- schema > missions/mission.schema.json`"
    );
    // The tree nodes come from the manifest.
    let variants = generated["$defs"]["TreeNode"]["oneOf"].as_array().unwrap();
    assert!(variants.iter().any(|v| v["properties"].get("claim_goal").is_some()));
}

#[test]
fn node_reference_docs_are_current() {
    let out = spomp().args(["nodes", "--markdown"]).output().unwrap();
    assert!(out.status.success());
    let shipped = std::fs::read_to_string(root().join("docs/nodes.md")).unwrap();
    assert!(
        String::from_utf8_lossy(&out.stdout) == shipped,
        "docs/nodes.md is stale: run `cargo run -- nodes --markdown > docs/nodes.md`"
    );
}

#[test]
fn nodes_catalogue_lists_ports() {
    let out = spomp().args(["nodes", "--json"]).output().unwrap();
    assert!(out.status.success());
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let nav = v.as_array().unwrap().iter().find(|n| n["name"] == "navigate_to").unwrap();
    assert!(nav["ports"].as_array().unwrap().iter().any(|p| p["name"] == "target" && p["type"] == "point"));
    spomp().args(["nodes", "no_such_node"]).assert().code(2);
    let text = spomp().args(["nodes", "timeout"]).output().unwrap();
    assert!(String::from_utf8_lossy(&text.stdout).contains("duration_s"));
}
