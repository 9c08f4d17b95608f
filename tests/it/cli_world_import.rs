//! `spomp world import` as a user runs it: the shipped self-made campus raster becomes a world,
//! a mission in that world runs end to end in the simulator, and bad input is refused with a
//! located, explained error.

#![allow(clippy::unwrap_used, clippy::expect_used)] // tests fail loudly by design

use std::path::{Path, PathBuf};

use crate::spomp;

fn campus() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/worlds/campus")
}

fn import(out: &Path, extra: &[&str]) -> std::process::Output {
    spomp()
        .args(["world", "import"])
        .arg(campus().join("campus.png"))
        .arg("--classes")
        .arg(campus().join("campus-classes.yaml"))
        .args(extra)
        .arg("--out")
        .arg(out)
        .output()
        .unwrap()
}

#[test]
fn the_imported_campus_is_a_world_whose_mission_runs_to_completion() {
    let dir = tempfile::tempdir().unwrap();
    let world = dir.path().join("world");
    let out = import(&world, &["--resolution-m", "0.5", "--gps-reference", "39.9526,-75.1652", "--json"]);
    assert_eq!(out.status.code(), Some(0), "{}", String::from_utf8_lossy(&out.stderr));
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!((v["width"].as_u64(), v["height"].as_u64()), (Some(320), Some(240)));
    assert_eq!(v["size_m"], serde_json::json!([160.0, 120.0]));
    // The anti-aliased road edges and the stray yellow pixels matched no class: a small share,
    // reported, and not turned into gravel (the colour nearest the road–grass blend).
    let snapped = v["colours"]["snapped_share"].as_f64().unwrap();
    assert!(snapped > 0.001 && snapped < 0.01, "{v}");
    assert_eq!(v["colours"]["top_snapped"][0][2], "grass_sidewalk", "{v}");
    // The three parking lots drawn, as the goal detector sees them.
    assert_eq!(v["vehicle_clusters"].as_array().unwrap().len(), 3, "{v}");
    // 120 m south of 39.9526° N.
    let lat0 = v["gps_origin"][0].as_f64().unwrap();
    assert!((lat0 - (39.9526 - 120.0 / 6_378_137.0_f64 * 180.0 / std::f64::consts::PI)).abs() < 1e-9);
    assert!(world.join("world.yaml").is_file() && world.join("import.yaml").is_file());

    // The world loads like any other: elevation from the classes (buildings 10 m, curbs).
    let show = spomp().args(["world", "show", "--json"]).arg(&world).output().unwrap();
    assert_eq!(show.status.code(), Some(0), "{}", String::from_utf8_lossy(&show.stderr));
    let s: serde_json::Value = serde_json::from_slice(&show.stdout).unwrap();
    assert!((s["max_elevation_m"].as_f64().unwrap() - 10.0).abs() < 1e-3, "{s}");
    let gravel = s["classes"].as_array().unwrap().iter().find(|c| c["name"] == "gravel").unwrap();
    assert_eq!(gravel["cells"], 22 * 68 - 5 * 5 * 9, "only the drawn gravel yard (less its cars) is gravel: {gravel}");

    // The mission's start poses are the first two the import placed.
    let starts = v["start_poses"].as_array().unwrap();
    assert!(starts.len() >= 2, "{v}");
    let mission_text = std::fs::read_to_string(campus().join("campus-mission.yaml")).unwrap();
    for s in &starts[..2] {
        let at = format!("x_m: {}, y_m: {}", s["x"].as_f64().unwrap(), s["y"].as_f64().unwrap());
        assert!(mission_text.contains(&at), "the mission starts at the imported start poses: {at}");
    }
    let mission = dir.path().join("campus-mission.yaml");
    std::fs::write(&mission, &mission_text).unwrap();
    // It passes every stage, the world stage included, without a warning.
    let validate = spomp().args(["validate", "--json"]).arg(&mission).output().unwrap();
    assert_eq!(validate.status.code(), Some(0), "{}", String::from_utf8_lossy(&validate.stdout));
    let diags: Vec<serde_json::Value> = serde_json::from_slice(&validate.stdout).unwrap();
    assert!(diags.is_empty(), "{diags:?}");

    let run = spomp()
        .args(["sim", "--json", "--no-mcap", "--seed", "1", "--out"])
        .arg(dir.path().join("out"))
        .arg(&mission)
        .output()
        .unwrap();
    assert_eq!(run.status.code(), Some(0), "{}", String::from_utf8_lossy(&run.stderr));
    let r: serde_json::Value = serde_json::from_slice(&run.stdout).unwrap();
    let run = &r["runs"][0];
    assert_eq!(run["outcome"], "complete", "{run}");
    assert_eq!(run["clusters"]["total"], 3);
    assert_eq!(run["clusters"]["visited"], 3, "{run}");
    assert!(run["end_s"].as_f64().unwrap() < 600.0);
    let ugvs: Vec<&serde_json::Value> =
        run["robots"].as_array().unwrap().iter().filter(|r| r["kind"] == "ugv").collect();
    assert_eq!(ugvs.len(), 2);
    assert!(ugvs.iter().all(|u| u["distance_m"].as_f64().unwrap() > 20.0), "both UGVs drove: {run}");
}

#[test]
fn the_world_can_have_its_own_cell_size() {
    let dir = tempfile::tempdir().unwrap();
    // Finer cells than pixels: 0.25 m, four cells per pixel, the same three clusters.
    let out = import(&dir.path().join("fine"), &["--resolution-m", "0.5", "--cell-m", "0.25", "--json"]);
    assert_eq!(out.status.code(), Some(0), "{}", String::from_utf8_lossy(&out.stderr));
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!((v["width"].as_u64(), v["height"].as_u64()), (Some(640), Some(480)));
    assert_eq!((v["resolution_m"].as_f64(), v["pixel_m"].as_f64()), (Some(0.25), Some(0.5)));
    assert_eq!(v["size_m"], serde_json::json!([160.0, 120.0]));
    assert_eq!(v["vehicle_clusters"].as_array().unwrap().len(), 3, "{v}");
    // Coarser: 1 m cells keep the layout, but 2 m wide cars become specks the detector removes,
    // and the import says so.
    let out = import(&dir.path().join("coarse"), &["--resolution-m", "0.5", "--cell-m", "1", "--json"]);
    assert_eq!(out.status.code(), Some(0), "{}", String::from_utf8_lossy(&out.stderr));
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!((v["width"].as_u64(), v["height"].as_u64()), (Some(160), Some(120)));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("finds no cluster") && err.contains("--cell-m"), "{err}");
}

#[test]
fn an_implausible_resolution_is_questioned_unless_forced() {
    let dir = tempfile::tempdir().unwrap();
    // 320 pixels at 30 m: a 9.6 km campus.
    let out = import(&dir.path().join("w"), &["--resolution-m", "30"]);
    assert_eq!(out.status.code(), Some(1));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("9600.0 m × 7200.0 m") && err.contains("--force"), "{err}");
    assert!(!dir.path().join("w").exists(), "nothing written");
    // A raster of a few metres: 320 px at 100 px/m is 3.2 m.
    let out = import(&dir.path().join("w"), &["--pixels-per-m", "100"]);
    assert_eq!(out.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&out.stderr).contains("3.2 m × 2.4 m"), "{}", String::from_utf8_lossy(&out.stderr));
    let out = import(&dir.path().join("w"), &["--pixels-per-m", "2"]);
    assert_eq!(out.status.code(), Some(0), "{}", String::from_utf8_lossy(&out.stderr));
    let out = import(&dir.path().join("big"), &["--resolution-m", "30", "--force"]);
    assert_eq!(out.status.code(), Some(0), "{}", String::from_utf8_lossy(&out.stderr));
    // Neither or both scales: a usage error.
    assert_eq!(import(&dir.path().join("x"), &[]).status.code(), Some(2));
    assert_eq!(import(&dir.path().join("x"), &["--resolution-m", "1", "--pixels-per-m", "1"]).status.code(), Some(2));
}

#[test]
fn a_bad_class_table_is_located_and_shows_the_format() {
    let dir = tempfile::tempdir().unwrap();
    let table = dir.path().join("classes.yaml");
    std::fs::write(&table, "classes:\n  - { index: 0, name: road, rank: 0, color: [128, 64] }\n").unwrap();
    let out = spomp()
        .args(["world", "import"])
        .arg(campus().join("campus.png"))
        .arg("--classes")
        .arg(&table)
        .args(["--resolution-m", "0.5", "--out"])
        .arg(dir.path().join("w"))
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(1));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains(&format!("{}:2:", table.display())), "{err}");
    assert!(err.contains("expected format") && err.contains("height_m"), "{err}");
}

#[test]
fn a_table_that_fits_no_colour_is_refused_and_rasters_are_read_within_limits() {
    let dir = tempfile::tempdir().unwrap();
    // The right classes in the wrong colours: nearly every pixel is far from every class.
    let table = dir.path().join("classes.yaml");
    std::fs::write(
        &table,
        "classes:\n  - { index: 0, name: road, rank: 0, color: [255, 0, 0] }\n  - { index: 2, name: building, rank: 5, color: [0, 255, 255] }\n",
    )
    .unwrap();
    let run = |raster: &Path, table: &Path| {
        spomp()
            .args(["world", "import"])
            .arg(raster)
            .arg("--classes")
            .arg(table)
            .args(["--resolution-m", "0.5", "--out"])
            .arg(dir.path().join("w"))
            .output()
            .unwrap()
    };
    let out = run(&campus().join("campus.png"), &table);
    assert_eq!(out.status.code(), Some(1));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("% of the raster's pixels are farther than") && err.contains("classes.yaml"), "{err}");

    // A device is no raster: refused before it is read.
    let out = run(Path::new("/dev/zero"), &campus().join("campus-classes.yaml"));
    assert_eq!(out.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&out.stderr).contains("not a regular file"));
    // A PNG header claiming 20000 × 20000 pixels is refused from the header alone.
    let huge = dir.path().join("huge.png");
    std::fs::write(&huge, png_header(20_000, 20_000)).unwrap();
    let out = run(&huge, &campus().join("campus-classes.yaml"));
    assert_eq!(out.status.code(), Some(1));
    assert!(
        String::from_utf8_lossy(&out.stderr).contains("20000 × 20000 pixels"),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
}

/// An 8-bit RGB PNG of this size whose image data is one empty chunk (a few dozen bytes).
fn png_header(width: u32, height: u32) -> Vec<u8> {
    let mut ihdr = b"IHDR".to_vec();
    ihdr.extend(width.to_be_bytes());
    ihdr.extend(height.to_be_bytes());
    ihdr.extend([8, 2, 0, 0, 0]);
    let mut out = b"\x89PNG\r\n\x1a\n".to_vec();
    for chunk in [ihdr, b"IDAT".to_vec(), b"IEND".to_vec()] {
        out.extend((chunk.len() as u32 - 4).to_be_bytes());
        out.extend(&chunk);
        out.extend(crc32(&chunk).to_be_bytes());
    }
    out
}

fn crc32(bytes: &[u8]) -> u32 {
    let mut crc = 0xFFFF_FFFFu32;
    for &b in bytes {
        crc ^= u32::from(b);
        for _ in 0..8 {
            crc = if crc & 1 != 0 { (crc >> 1) ^ 0xEDB8_8320 } else { crc >> 1 };
        }
    }
    !crc
}

/// Issue 33: a site's class table spells the classes its own way (`grass/sidewalk`, `car`). The
/// mission maps what differs (`classes: { vehicle: car }`), spellings that differ only in case
/// and punctuation match as they are, and the run is the run of the same site with the built-in
/// names: cross-view localization works (it used to fail every update on `grass/sidewalk`), the
/// same clusters are found and visited. Without the mapping, `validate` says where to add it.
#[test]
fn a_site_table_with_its_own_class_names_runs_as_the_built_in_names_do() {
    let dir = tempfile::tempdir().unwrap();
    let builtin = std::fs::read_to_string(campus().join("campus-classes.yaml")).unwrap();
    let site =
        builtin.replace("name: grass_sidewalk,", "name: \"grass/sidewalk\",").replace("name: vehicle,", "name: car,");
    assert_ne!(site, builtin);
    let site_classes = dir.path().join("site-classes.yaml");
    std::fs::write(&site_classes, &site).unwrap();
    let import_as = |classes: &Path, out: &str, extra: &[&str]| {
        let o = spomp()
            .args(["world", "import"])
            .arg(campus().join("campus.png"))
            .arg("--classes")
            .arg(classes)
            .args(["--resolution-m", "0.5"])
            .args(extra)
            .arg("--out")
            .arg(dir.path().join(out))
            .output()
            .unwrap();
        assert_eq!(o.status.code(), Some(0), "{}", String::from_utf8_lossy(&o.stderr));
    };
    import_as(&campus().join("campus-classes.yaml"), "builtin", &[]);
    import_as(&site_classes, "site", &["--vehicle-class", "car"]);
    // The UGVs localize themselves (cross-view), which uses the class names most.
    let mission = std::fs::read_to_string(campus().join("campus-mission.yaml"))
        .unwrap()
        .replace("localization: { mode: ground_truth, noise_m: 0.05 }", "localization: { mode: cross_view }");
    assert!(mission.contains("mode: cross_view"));
    let builtin_mission = dir.path().join("builtin.yaml");
    std::fs::write(&builtin_mission, mission.replace("dir: world }", "dir: builtin }")).unwrap();
    let unmapped = dir.path().join("unmapped.yaml");
    std::fs::write(&unmapped, mission.replace("dir: world }", "dir: site }")).unwrap();
    let site_mission = dir.path().join("site.yaml");
    std::fs::write(
        &site_mission,
        format!("{}\nclasses: {{ vehicle: car }}\n", mission.replace("dir: world }", "dir: site }")),
    )
    .unwrap();

    let v = spomp().args(["validate", "--json"]).arg(&unmapped).output().unwrap();
    assert_eq!(v.status.code(), Some(1), "{}", String::from_utf8_lossy(&v.stdout));
    let diags: Vec<serde_json::Value> = serde_json::from_slice(&v.stdout).unwrap();
    let errors: Vec<&serde_json::Value> = diags.iter().filter(|d| d["severity"] == "error").collect();
    assert_eq!(errors.len(), 1, "{diags:?}");
    assert_eq!(errors[0]["node_path"], "goals.detect.class", "{diags:?}");
    assert!(errors[0]["message"].as_str().unwrap().contains("map it in `classes:`"), "{diags:?}");
    let v = spomp().args(["validate", "--json"]).arg(&site_mission).output().unwrap();
    assert_eq!(v.status.code(), Some(0), "{}", String::from_utf8_lossy(&v.stdout));
    let diags: Vec<serde_json::Value> = serde_json::from_slice(&v.stdout).unwrap();
    assert!(diags.is_empty(), "every name resolves: {diags:?}");

    let run = |m: &Path, out: &str| -> serde_json::Value {
        let o = spomp()
            .args(["sim", "--json", "--no-mcap", "--seed", "1", "--out"])
            .arg(dir.path().join(out))
            .arg(m)
            .output()
            .unwrap();
        assert_eq!(o.status.code(), Some(0), "{}", String::from_utf8_lossy(&o.stderr));
        let mut r: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
        r["runs"][0].take()
    };
    let (a, b) = (run(&builtin_mission, "out-builtin"), run(&site_mission, "out-site"));
    assert_eq!(b["outcome"], "complete", "{b}");
    assert_eq!(b["clusters"]["visited"], 3, "{b}");
    for key in ["clusters", "goals", "goals_visited", "robots", "end_s", "problems"] {
        assert_eq!(a[key], b[key], "`{key}` differs between the built-in names and the site's");
    }
    let ugv = b["robots"].as_array().unwrap().iter().find(|r| r["id"] == "ugv1").unwrap();
    assert!(ugv["localization_error_m"]["median"].as_f64().unwrap() < 1.0, "{ugv}");
}
