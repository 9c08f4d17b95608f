//! Two "real site" worlds (`tests/worlds/sites/`, drawn by `draw_sites.py` as exported maps
//! come: the site's own class names in a list of names and colours, a transparent margin, a
//! white label and scale bar, anti-aliased edges, dead-end pockets) imported as a user would,
//! checked against the committed world folders, and a mission in one of them run end to end:
//! its UAV flies a QGroundControl survey whose planned home is far off the map, placed by its
//! coordinates.

#![allow(clippy::unwrap_used, clippy::expect_used)] // tests fail loudly by design

use std::path::{Path, PathBuf};

use crate::spomp;

fn sites() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/worlds/sites")
}

/// `spomp world import` of a site's raster, as the committed world was made.
fn import(site: &str, out: &Path, extra: &[&str]) -> std::process::Output {
    let (table, gps, vehicle) = match site {
        "yard" => ("yard-classes.yaml", "40.0010,-75.2000", "vehicle"),
        _ => ("hill-classes.json", "39.9000,-75.1000", "Cars"),
    };
    spomp()
        .args(["world", "import"])
        .arg(sites().join(format!("{site}.png")))
        .arg("--classes")
        .arg(sites().join(table))
        .args(["--resolution-m", "0.5", "--starts", "5", "--vehicle-class", vehicle])
        .args(extra)
        .args(["--gps-reference", gps, "--json", "--out"])
        .arg(out)
        .output()
        .unwrap()
}

fn json(out: &std::process::Output) -> serde_json::Value {
    assert_eq!(
        out.status.code(),
        Some(0),
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).unwrap()
}

fn class_cells(world: &Path, name: &str) -> u64 {
    let show = json(&spomp().args(["world", "show", "--json"]).arg(world).output().unwrap());
    show["classes"].as_array().unwrap().iter().find(|c| c["name"] == name).map_or(0, |c| c["cells"].as_u64().unwrap())
}

#[test]
fn the_site_rasters_import_as_they_come_into_the_committed_worlds() {
    let dir = tempfile::tempdir().unwrap();
    for (site, clusters, vehicle) in [("yard", 6, "vehicle"), ("hill", 4, "Cars")] {
        let world = dir.path().join(site);
        let v = json(&import(site, &world, &[]));
        // The transparent margin is no data, never snapped to a colour; the label, the scale bar
        // and the blended edges matched no class and took the class around them.
        assert!(v["colours"]["no_data"].as_u64().unwrap() > 1000, "{site}: {v}");
        let snapped = v["colours"]["snapped_share"].as_f64().unwrap();
        assert!(snapped > 0.01 && snapped < 0.2, "{site}: {v}");
        // Every cluster drawn, and nothing more: the white label is no fake vehicle.
        assert_eq!(v["vehicle_clusters"].as_array().unwrap().len(), clusters, "{site}: {v}");
        let width = v["vehicle_width_m"].as_f64().unwrap();
        // Rows of cars 2 m x 4.5 m whose gaps the blending closed: the rows' depth.
        assert!((3.0..=5.0).contains(&width), "{site}: {v}");
        assert!(class_cells(&world, "no_data") > 200, "{site}");
        assert!(class_cells(&world, vehicle) > 0, "{site}");
        // The committed world is this import (regenerate with the commands in its mission).
        let committed = std::fs::read_to_string(sites().join(site).join("world.yaml")).unwrap();
        let fresh = std::fs::read_to_string(world.join("world.yaml")).unwrap();
        assert_eq!(committed, fresh, "{site}: tests/worlds/sites/{site} is out of date");
        for layer in ["class.png", "elevation.png"] {
            assert_eq!(
                std::fs::read(sites().join(site).join(layer)).unwrap(),
                std::fs::read(world.join(layer)).unwrap(),
                "{site}/{layer}"
            );
        }
        // Its mission passes every stage against it, the world stage included (warnings only:
        // the site has no light poles or tree trunks for the localizer to weigh).
        let mission = sites().join(format!("{site}-mission.yaml"));
        let out = spomp().args(["validate", "--json"]).arg(&mission).output().unwrap();
        let diags: Vec<serde_json::Value> = json(&out).as_array().unwrap().clone();
        assert!(diags.iter().all(|d| d["severity"] == "warning"), "{site}: {diags:#?}");
    }
    // The yard's table names classes spomp lacks: the import says they are impassable.
    let out = import("yard", &dir.path().join("again"), &[]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("\"unknown\", \"water\"") && err.contains("impassable"), "{err}");
}

/// The scale given as pixels per metre where metres per pixel were meant: the vehicles measure
/// 14 m across and the import refuses, saying so and suggesting a scale that makes them cars.
#[test]
fn a_wrong_scale_is_refused_by_the_size_of_the_cars() {
    let dir = tempfile::tempdir().unwrap();
    let out = spomp()
        .args(["world", "import"])
        .arg(sites().join("yard.png"))
        .arg("--classes")
        .arg(sites().join("yard-classes.yaml"))
        .args(["--pixels-per-m", "0.5", "--out"])
        .arg(dir.path().join("w"))
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(1));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("vehicles are 14.3 m wide") && err.contains("--resolution-m 0.279"), "{err}");
    assert!(!dir.path().join("w").exists());
}

/// The yard's mission as it comes: validated, then run a short while. The UAV's survey is placed
/// by its coordinates (its home, the launch site, is 600 m off the map): it stays over the map
/// and maps it, so the UGVs find clusters; a dry run fails a robot that leaves the map.
#[test]
fn the_yard_mission_flies_its_georeferenced_survey_and_finds_clusters() {
    let dir = tempfile::tempdir().unwrap();
    let mission = sites().join("yard-mission.yaml");
    let out =
        spomp().args(["validate", "--json", "--dry-run", "--time-limit-s", "120"]).arg(&mission).output().unwrap();
    // A dry run cut short of the mission's end does not pass; what it did is in the report.
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let run = &v["dry_runs"][0]["dry_run"];
    assert_eq!(run["outcome"], "time_limit", "{v}");
    assert_eq!(run["left_the_map"], serde_json::json!([]), "{v}");
    assert!(run["goals"].as_u64().unwrap() >= 4, "the UAV mapped the clusters within 120 s: {run}");

    // The same plan in the same world imported without a GPS reference: laid out around its
    // home, as before, it lies off the map: an error at the plan path.
    let plain = dir.path().join("yard");
    json(
        &spomp()
            .args(["world", "import"])
            .arg(sites().join("yard.png"))
            .arg("--classes")
            .arg(sites().join("yard-classes.yaml"))
            .args(["--resolution-m", "0.5", "--json", "--out"])
            .arg(&plain)
            .output()
            .unwrap(),
    );
    for file in ["yard-survey.plan", "goal-cycle.yaml"] {
        std::fs::copy(sites().join(file), dir.path().join(file)).unwrap();
    }
    std::fs::copy(&mission, dir.path().join("m.yaml")).unwrap();
    let out = spomp().args(["validate", "--json"]).arg(dir.path().join("m.yaml")).output().unwrap();
    assert_eq!(out.status.code(), Some(1));
    let diags: Vec<serde_json::Value> = serde_json::from_slice(&out.stdout).unwrap();
    assert!(
        diags.iter().any(|d| d["severity"] == "error"
            && d["node_path"] == "explorer/state_machine.survey/follow_waypoints"
            && d["message"].as_str().unwrap().contains("placed around the plan's home")),
        "{diags:#?}"
    );
}

/// `spomp plan` on the yard: graph connectivity overstates what the UGV can drive (curbs,
/// bushes in the pockets); the report gives both.
#[test]
fn plan_reports_what_the_simulated_ugv_can_drive_beside_the_graph() {
    let out = spomp()
        .args(["plan", "--json", "--random-pairs", "60", "--pair-max-rank", "2"])
        .arg(sites().join("yard"))
        .output()
        .unwrap();
    let v = json(&out);
    let graph = v["success_rate"].as_f64().unwrap();
    let drivable = v["ugv_drivable_rate"].as_f64().unwrap();
    assert!(drivable < graph, "{v}");
    assert_eq!(v["ugv_blocked"].as_array().unwrap().len() as f64, ((graph - drivable) * 60.0).round(), "{v}");
}

/// The yard's class names rewritten in the world's table (`road` → `Asphalt`, … as another
/// mapping pipeline would name them): with the mission's `classes:` mapping, two UGVs driving
/// one behind the other localize exactly as on the built-in names (the same seed gives the same
/// median errors), and well (under a metre). (The simulator once showed the UGVs to each other
/// as whatever index the built-in name `vehicle` fell back to — the yard's grass in a renamed
/// table — and whole site missions drifted apart; this short drive does not show that.)
#[test]
fn a_world_with_its_own_class_names_localizes_as_well_as_the_built_in_names() {
    let dir = tempfile::tempdir().unwrap();
    let renames = [
        ("road", "Asphalt"),
        ("vegetation", "Shrubs"),
        ("building", "House"),
        ("grass/sidewalk", "Lawn"),
        ("vehicle", "Car"),
        ("gravel", "Loose stones"),
        ("human", "Person"),
    ];
    let world_yaml = std::fs::read_to_string(sites().join("yard/world.yaml")).unwrap();
    for (variant, names) in [("builtin", &[("grass/sidewalk", "grass_sidewalk")][..]), ("renamed", &renames[..])] {
        let world = dir.path().join(format!("yard-{variant}"));
        std::fs::create_dir(&world).unwrap();
        for layer in ["class.png", "color.png", "elevation.png"] {
            std::fs::copy(sites().join("yard").join(layer), world.join(layer)).unwrap();
        }
        let mut text = world_yaml.clone();
        for (from, to) in names {
            let (a, b) = (format!("name: {from}\n"), format!("name: {to}\n"));
            assert!(text.contains(&a), "{from}");
            text = text.replace(&a, &b);
        }
        std::fs::write(world.join("world.yaml"), text).unwrap();
    }
    let mission = |variant: &str, classes: &str| {
        format!(
            r#"
mission: yard-names-{variant}
{classes}
team:
  - id: ugv1
    kind: ugv
    role: r
    priority: 1
    start: {{ x_m: 2.25, y_m: 19.0, yaw_deg: 0 }}
    localization: {{ mode: cross_view, prior_sigma_m: 2.0, prior_sigma_deg: 5.0 }}
  - id: ugv2
    kind: ugv
    role: r
    priority: 2
    start: {{ x_m: 7.0, y_m: 19.0, yaw_deg: 0 }}
    localization: {{ mode: cross_view, prior_sigma_m: 2.0, prior_sigma_deg: 5.0 }}
roles:
  r:
    navigation: {{ profile: simulation }}
    tree:
      navigate_to: {{ target: {{ x: 60.0, y: 19.0 }} }}
complete_when: all_trees_done
time_limit_s: 40
sim: {{ world: {{ dir: yard-{variant} }} }}
"#
        )
    };
    let mapping = format!(
        "classes: {{ {} }}",
        [("road", "Asphalt"), ("vegetation", "Shrubs"), ("building", "House"), ("grass_sidewalk", "Lawn")]
            .iter()
            .chain(&[("vehicle", "Car"), ("gravel", "Loose stones"), ("human", "Person")])
            .map(|(k, v)| format!("{k}: {v}"))
            .collect::<Vec<_>>()
            .join(", ")
    );
    let mut medians = Vec::new();
    for (variant, classes) in [("builtin", String::new()), ("renamed", mapping)] {
        let path = dir.path().join(format!("{variant}.yaml"));
        std::fs::write(&path, mission(variant, &classes)).unwrap();
        let out = spomp()
            .args(["sim", "--json", "--no-mcap", "--seed", "3", "--out"])
            .arg(dir.path().join(format!("run-{variant}")))
            .arg(&path)
            .output()
            .unwrap();
        let v = json(&out);
        let mut errors = Vec::new();
        for ugv in v["runs"][0]["robots"].as_array().unwrap().iter().filter(|r| r["kind"] == "ugv") {
            let median = ugv["localization_error_m"]["median"].as_f64().unwrap();
            assert!(median < 1.0, "{variant}: {ugv}");
            errors.push(median);
        }
        assert_eq!(errors.len(), 2, "{variant}");
        let problems = v["runs"][0]["problems"].as_array().unwrap();
        assert!(
            !problems.iter().any(|p| p["message"].as_str().unwrap().contains("ground_classes")),
            "{variant}: {problems:?}"
        );
        medians.push(errors);
    }
    // The acceptance bound is 0.1 m; the names change nothing, so the runs are the same.
    assert_eq!(medians[0], medians[1]);
}

/// The site missions run the shipped goal cycle (its recoveries included) from a copy beside
/// them (a mission includes files inside its own folder only): the copy is the shipped file.
#[test]
fn the_site_missions_goal_cycle_is_the_shipped_one() {
    let shipped =
        std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("missions/subtrees/goal-cycle.yaml"))
            .unwrap();
    let copy = std::fs::read_to_string(sites().join("goal-cycle.yaml")).unwrap();
    let body = |s: &str| {
        s.lines()
            .skip_while(|l| {
                l.starts_with("# yaml-language-server") || l.starts_with("# A copy") || l.starts_with("# only)")
            })
            .collect::<Vec<_>>()
            .join("\n")
    };
    assert_eq!(body(&copy), shipped.lines().skip(1).collect::<Vec<_>>().join("\n"));
}
