//! The lab's binary through the public entry point (`spomp::cli::main_with`): its node type is
//! listed beside the built-in ones, is in the JSON Schema and the node reference, and a mission
//! that uses it validates and runs in the simulator.

#![allow(clippy::unwrap_used, clippy::expect_used)] // tests fail loudly by design

use std::path::Path;

use assert_cmd::Command;

fn lab() -> Command {
    let mut c = Command::cargo_bin("custom-node").unwrap();
    c.current_dir(Path::new(env!("CARGO_MANIFEST_DIR")));
    c
}

fn stdout(c: &mut Command) -> String {
    let out = c.output().unwrap();
    assert!(out.status.success(), "{}\n{}", String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr));
    String::from_utf8(out.stdout).unwrap()
}

#[test]
fn nodes_lists_the_lab_type_beside_the_built_in_ones() {
    let nodes: serde_json::Value = serde_json::from_str(&stdout(lab().args(["nodes", "--json"]))).unwrap();
    let names: Vec<&str> = nodes.as_array().unwrap().iter().map(|n| n["name"].as_str().unwrap()).collect();
    for name in ["teammates_heard", "navigate_to", "sequence_with_memory", "wait"] {
        assert!(names.contains(&name), "{name} missing from {names:?}");
    }
    let ours = nodes.as_array().unwrap().iter().find(|n| n["name"] == "teammates_heard").unwrap();
    assert_eq!(ours["category"], "condition");
    assert_eq!(ours["skills"], serde_json::json!(["teamstate"]));
    let ports: Vec<&str> = ours["ports"].as_array().unwrap().iter().map(|p| p["name"].as_str().unwrap()).collect();
    assert_eq!(ports, ["at_least", "within_s", "count"]);
    assert!(stdout(lab().args(["nodes", "--markdown"])).contains("### `teammates_heard`"));
    assert!(stdout(lab().arg("schema")).contains("\"teammates_heard\""));
}

#[test]
fn the_mission_validates_and_runs_to_its_end_in_the_simulator() {
    let out = stdout(lab().args(["validate", "missions/teammates-heard.yaml", "--dry-run", "--json"]));
    let v: serde_json::Value = serde_json::from_str(&out).unwrap();
    assert_eq!(v["diagnostics"], serde_json::json!([]));
    let run = &v["dry_runs"][0]["dry_run"];
    assert_eq!(run["outcome"], "complete", "{run:#}");
    assert_eq!(run["terminated_within_time_limit"], true);
    // The lab's node ran (the team state heard both UGVs from the start, so the wait that
    // would cover a slow radio is the one node left unticked).
    let never: Vec<&str> = run["never_ticked"].as_array().unwrap().iter().filter_map(|n| n.as_str()).collect();
    assert!(never.iter().all(|n| !n.contains("teammates_heard")), "{run:#}");
}

#[test]
fn only_the_lab_registry_knows_the_lab_type() {
    // The lab's own registry is what makes the type known: a mission using it is refused by a
    // registry without it (the library's default registry, used by `spomp`).
    let registry = spomp::registry();
    assert!(registry.get("teammates_heard").is_none());
    let lab = custom_node::lab_registry(custom_node::LabSettings::default()).unwrap();
    assert!(lab.get("teammates_heard").is_some());
    // Registering it twice is an error, not a silent replacement.
    let mut twice = lab.clone();
    assert!(custom_node::register(&mut twice, Default::default()).is_err());
}

#[test]
fn the_lab_binary_checks_the_adapter_sections_as_spomp_does() {
    // `spomp::registry()` brings the owners of `comms:`, `sim:`, `ros2:` and `team_link:`: a bad
    // key inside a robot's `ros2:` is reported at its place by the lab's binary too.
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    let fixture = root.join("tests/missions/invalid-ros2-unknown-key.yaml");
    let out = lab().arg("validate").arg(&fixture).output().unwrap();
    assert_eq!(out.status.code(), Some(1));
    let text = format!("{}{}", String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr));
    assert!(text.contains("11:32") && text.contains("team[1].ros2.odometry_timout_s"), "{text}");
    let schema = stdout(lab().arg("schema"));
    for def in ["\"CommsSpec\"", "\"SimSpec\"", "\"Ros2Spec\"", "\"TeamLinkSpec\""] {
        assert!(schema.contains(def), "{def} missing from the lab's schema");
    }
}
