//! The integrator tools `spomp world`, `spomp terrain` and `spomp plan` on a small generated city.

#![allow(clippy::unwrap_used, clippy::expect_used)] // tests fail loudly by design

use std::path::{Path, PathBuf};

use crate::spomp;
use serde_json::Value;

const ROAD: [u8; 3] = [128, 64, 128];
const GRASS_SIDEWALK: [u8; 3] = [152, 251, 152];
const RESOLUTION_M: f64 = 0.5;

fn run_json(args: &[&str]) -> Value {
    let out = spomp().args(args).output().unwrap();
    assert_eq!(out.status.code(), Some(0), "{args:?}: {}", String::from_utf8_lossy(&out.stderr));
    serde_json::from_slice(&out.stdout).unwrap()
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// A 120 m × 100 m city in a temp dir.
fn small_city(tmp: &Path) -> PathBuf {
    let dir = tmp.join("city");
    let v = run_json(&["world", "generate", "--seed", "3", "--size-m", "120,100", "--out", s(&dir), "--json"]);
    assert_eq!(v["width"], 240);
    assert_eq!(v["height"], 200);
    dir
}

/// Map-frame centres of the cells of one colour in the world's class layer.
fn cells_of(dir: &Path, rgb: [u8; 3]) -> Vec<(i64, i64)> {
    let img = image::open(dir.join("class.png")).unwrap().to_rgb8();
    let h = img.height() as i64;
    img.enumerate_pixels().filter(|(_, _, p)| p.0 == rgb).map(|(x, y, _)| (x as i64, h - 1 - y as i64)).collect()
}

fn centre_m(cell: (i64, i64)) -> (f64, f64) {
    ((cell.0 as f64 + 0.5) * RESOLUTION_M, (cell.1 as f64 + 0.5) * RESOLUTION_M)
}

/// A road cell whose nearest sidewalk cell (behind a 0.15 m curb) is 2–3 m away.
fn road_cell_near_curb(dir: &Path) -> (f64, f64) {
    let road = cells_of(dir, ROAD);
    let walk: std::collections::HashSet<_> = cells_of(dir, GRASS_SIDEWALK).into_iter().collect();
    let nearest_walk_cells = |c: (i64, i64)| {
        let mut best = i64::MAX;
        for dx in -8..=8i64 {
            for dy in -8..=8i64 {
                if walk.contains(&(c.0 + dx, c.1 + dy)) {
                    best = best.min(dx * dx + dy * dy);
                }
            }
        }
        best
    };
    let cell = road
        .iter()
        .copied()
        .find(|c| (16..=36).contains(&nearest_walk_cells(*c)))
        .expect("a road cell 2-3 m from a curb");
    centre_m(cell)
}

#[test]
fn world_show_pano_terrain_pipeline() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = small_city(tmp.path());

    // show: size, classes, clusters, and the render.
    let shown = run_json(&["world", "show", s(&dir), "--json"]);
    assert_eq!(shown["size_m"], serde_json::json!([120.0, 100.0]));
    let names: Vec<&str> = shown["classes"].as_array().unwrap().iter().map(|c| c["name"].as_str().unwrap()).collect();
    assert!(names.contains(&"road") && names.contains(&"building"), "{names:?}");
    let cells: u64 = shown["classes"].as_array().unwrap().iter().map(|c| c["cells"].as_u64().unwrap()).sum();
    assert_eq!(cells, 240 * 200);
    assert!(!shown["vehicle_clusters"].as_array().unwrap().is_empty());
    let render = image::open(dir.join("render.png")).unwrap();
    assert_eq!((render.width(), render.height()), (240, 200));
    let human = spomp().args(["world", "show", s(&dir), "--out", s(&tmp.path().join("r.png"))]).output().unwrap();
    assert_eq!(human.status.code(), Some(0));
    assert!(String::from_utf8_lossy(&human.stdout).contains("vehicle clusters:"));
    assert!(tmp.path().join("r.png").exists());

    // pano: a road position near a curb, so some columns end at the curb and others do not.
    let (x, y) = road_cell_near_curb(&dir);
    let pano = tmp.path().join("pano.png");
    let at = format!("{x},{y},0");
    run_json(&["world", "pano", s(&dir), "--at", &at, "--out", s(&pano), "--json"]);
    let img = image::open(&pano).unwrap();
    assert_eq!(img.color(), image::ColorType::L16);
    assert_eq!((img.width(), img.height()), (1024, 256));

    // terrain --json: exactly the documented keys and shapes.
    let stages = tmp.path().join("stages");
    let t = run_json(&["terrain", s(&pano), "--json", "--repeat", "2", "--out", s(&stages)]);
    let mut keys: Vec<&str> = t.as_object().unwrap().keys().map(String::as_str).collect();
    keys.sort_unstable();
    assert_eq!(
        keys,
        [
            "cols",
            "reachability",
            "rows",
            "staged_total_ms",
            "timings_ms",
            "total_min_ms",
            "total_ms",
            "traversable_pixels"
        ]
    );
    assert_eq!(t["rows"], 256);
    assert_eq!(t["cols"], 1024);
    // The total is the fused analysis the robot runs; the stages are timed in a staged run.
    let (total, total_min) = (t["total_ms"].as_f64().unwrap(), t["total_min_ms"].as_f64().unwrap());
    assert!(total > 0.0 && total_min > 0.0 && total_min <= total, "{total} {total_min}");
    let timings = t["timings_ms"].as_object().unwrap();
    let mut stage_sum = 0.0;
    for stage in ["fill_holes", "project", "gradients", "obstacles", "distance_transform", "reachability"] {
        let ms = timings[stage].as_f64().unwrap();
        assert!(ms >= 0.0, "{stage}");
        stage_sum += ms;
    }
    assert!(stage_sum > 0.0 && t["staged_total_ms"].as_f64().unwrap() > 0.0);
    let reach = t["reachability"].as_array().unwrap();
    assert_eq!(reach.len(), 1024);
    let obstacle_cols = reach.iter().filter(|r| r["obstacle"].as_bool().unwrap()).count();
    assert!(obstacle_cols > 0 && obstacle_cols < 1024, "{obstacle_cols} obstacle columns");
    let mut nearest_obstacle_end = f64::INFINITY;
    for r in reach {
        let range = r["range_m"].as_f64().unwrap();
        assert!((0.0..=50.0).contains(&range), "{r}");
        if r["obstacle"].as_bool().unwrap() {
            nearest_obstacle_end = nearest_obstacle_end.min(range);
        }
    }
    // Facing the curb 2–3 m away, the scan ends before it.
    assert!(nearest_obstacle_end < 3.0, "{nearest_obstacle_end}");
    let trav = t["traversable_pixels"].as_u64().unwrap();
    assert!(trav > 0 && trav < 256 * 1024);
    for name in ["filled_depth", "gradient", "obstacles", "distance", "traversable", "reachability", "stages"] {
        assert!(stages.join(format!("{name}.png")).exists(), "{name}.png");
    }
    // The sheet: five 1024 × 256 panels under 26-pixel captions, a 16-pixel gap, the 601-pixel
    // reachability picture; the third panel is the obstacle image, pixel for pixel.
    let sheet = image::open(stages.join("stages.png")).unwrap().to_rgb8();
    assert_eq!(sheet.dimensions(), (1024 + 16 + 601, 5 * (26 + 256)));
    let obstacles = image::open(stages.join("obstacles.png")).unwrap().to_rgb8();
    let panel = image::imageops::crop_imm(&sheet, 0, 2 * (26 + 256) + 26, 1024, 256).to_image();
    assert!(panel == obstacles, "the obstacle panel of the sheet differs from obstacles.png");

    // A parameter file: a steeper threshold than the curb's slope sees no curb.
    let params = tmp.path().join("terrain.yaml");
    std::fs::write(&params, "slope_threshold: 100.0\n").unwrap();
    let relaxed = run_json(&["terrain", s(&pano), "--json", "--repeat", "2", "--params", s(&params)]);
    let relaxed_obstacles =
        relaxed["reachability"].as_array().unwrap().iter().filter(|r| r["obstacle"].as_bool().unwrap()).count();
    assert!(relaxed_obstacles < obstacle_cols, "{relaxed_obstacles} vs {obstacle_cols}");
    // Unknown keys are rejected, naming the file.
    std::fs::write(&params, "slope_treshold: 0.3\n").unwrap();
    let bad = spomp().args(["terrain", s(&pano), "--params", s(&params)]).output().unwrap();
    assert_eq!(bad.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&bad.stderr).contains("terrain.yaml"));

    // Human output: the stage table.
    let human = spomp().args(["terrain", s(&pano), "--repeat", "2"]).output().unwrap();
    let text = String::from_utf8_lossy(&human.stdout);
    assert!(text.contains("distance_transform") && text.contains("traversable pixels"), "{text}");
    assert!(text.contains("total (fused)") && text.contains("staged total"), "{text}");
}

/// Ground height under a map-frame point, metres, from a generated world's `elevation.png`
/// (1 mm per count, no offset, as `spomp world generate` writes it; row 0 is the north edge).
fn elevation_m(dir: &Path, p: (f64, f64)) -> f64 {
    let img = image::open(dir.join("elevation.png")).unwrap().to_luma16();
    let (col, row) = ((p.0 / RESOLUTION_M).floor() as u32, (p.1 / RESOLUTION_M).floor() as u32);
    f64::from(img.get_pixel(col, img.height() - 1 - row).0[0]) * 0.001
}

/// `spomp plan` judges the ground along a path's line too: a path the graph plans straight up a
/// curb (an edge across it with no ramp in reach stays straight) is not drivable, although the
/// sidewalk beyond is ground the UGV reaches up a ramp elsewhere. The corridor check alone
/// passed such paths, so the report overstated what the UGV can drive.
#[test]
fn plan_reports_a_path_straight_up_a_curb_as_not_drivable() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = small_city(tmp.path());
    let r = run_json(&["plan", s(&dir), "--random-pairs", "40", "--seed", "1", "--json"]);
    let blocked = r["ugv_blocked"].as_array().unwrap();
    let up = blocked
        .iter()
        .find(|b| b["why"].as_str().unwrap().contains("step of 0.15 m up"))
        .unwrap_or_else(|| panic!("a path up a curb among the random pairs: {r}"));
    let point = |v: &Value| (v[0].as_f64().unwrap(), v[1].as_f64().unwrap());
    let (from, to) = (point(&up["from"]), point(&up["to"]));

    // The same query alone: its path climbs the curb where the report says it stops.
    let v = run_json(&[
        "plan",
        s(&dir),
        "--from",
        &format!("{},{}", from.0, from.1),
        "--to",
        &format!("{},{}", to.0, to.1),
        "--json",
    ]);
    assert_eq!(v["ugv_drivable_rate"], 0.0, "{v}");
    let at = point(&v["ugv_blocked"][0]["at"]);
    let path: Vec<(f64, f64)> = v["path_waypoints"].as_array().unwrap().iter().map(point).collect();
    let on_segment = |a: (f64, f64), b: (f64, f64)| {
        let (ab, ap) = (((b.0 - a.0), (b.1 - a.1)), ((at.0 - a.0), (at.1 - a.1)));
        let len = (ab.0 * ab.0 + ab.1 * ab.1).sqrt();
        len > 0.0 && (ab.0 * ap.1 - ab.1 * ap.0).abs() / len < 1e-6 && (ab.0 * ap.0 + ab.1 * ap.1) / len <= len + 1e-6
    };
    let (a, b) =
        path.windows(2).map(|w| (w[0], w[1])).find(|&(a, b)| on_segment(a, b)).expect("the stop is on the path");
    let len = ((b.0 - a.0).powi(2) + (b.1 - a.1).powi(2)).sqrt();
    let before = (at.0 - (b.0 - a.0) / len * 0.3, at.1 - (b.1 - a.1) / len * 0.3);
    let climb = elevation_m(&dir, at) - elevation_m(&dir, before);
    assert!(climb > 0.1, "the ground rises {climb} m at {at:?} on {a:?} → {b:?}");
}

#[test]
fn plan_between_road_cells_and_random_pairs() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = small_city(tmp.path());
    let road = cells_of(&dir, ROAD);
    // Two road cells far apart: the road cells nearest the south-west and north-east corners.
    let sw = *road.iter().min_by_key(|c| c.0 + c.1).unwrap();
    let ne = *road.iter().max_by_key(|c| c.0 + c.1).unwrap();
    let (from, to) = (centre_m(sw), centre_m(ne));
    let from_arg = format!("{},{}", from.0, from.1);
    let to_arg = format!("{},{}", to.0, to.1);
    let out_dir = tmp.path().join("plan");
    let v = run_json(&["plan", s(&dir), "--from", &from_arg, "--to", &to_arg, "--json", "--out", s(&out_dir)]);
    assert!(v["nodes"].as_u64().unwrap() > 10);
    assert!(v["edges"].as_u64().unwrap() >= v["nodes"].as_u64().unwrap() - 1);
    assert_eq!(v["success_rate"], 1.0);
    let straight = ((to.0 - from.0).powi(2) + (to.1 - from.1).powi(2)).sqrt();
    let length = v["path_length_m"].as_f64().unwrap();
    assert!(length >= straight - 1e-6 && length < 3.0 * straight, "{length} vs {straight}");
    assert!(v["path_cost"].as_f64().unwrap() > 0.0);
    // The path itself: from the start to the goal, as long as the reported length.
    let points: Vec<(f64, f64)> = v["path_waypoints"]
        .as_array()
        .unwrap()
        .iter()
        .map(|p| (p[0].as_f64().unwrap(), p[1].as_f64().unwrap()))
        .collect();
    assert!(points.len() >= 3, "{points:?}");
    assert_eq!((points[0], points[points.len() - 1]), (from, to));
    let walked: f64 = points.windows(2).map(|w| ((w[1].0 - w[0].0).powi(2) + (w[1].1 - w[0].1).powi(2)).sqrt()).sum();
    assert!((walked - length).abs() < 1e-6, "{walked} vs {length}");
    assert!(v["build_ms"].as_f64().unwrap() > 0.0);
    let pic = image::open(out_dir.join("plan.png")).unwrap();
    assert_eq!((pic.width(), pic.height()), (240, 200));

    // Learning off: the class-rank ablation cost, a different number.
    let off = run_json(&["plan", s(&dir), "--from", &from_arg, "--to", &to_arg, "--json", "--learning", "off"]);
    assert_eq!(off["success_rate"], 1.0);
    assert_ne!(off["path_cost"], v["path_cost"]);

    // Random pairs on road and gravel: a rate, no single-path fields; same seed, same rate.
    let r = run_json(&["plan", s(&dir), "--random-pairs", "20", "--seed", "4", "--json"]);
    assert!(r["success_rate"].as_f64().unwrap() >= 0.9, "{r}");
    assert!(r["path_length_m"].is_null() && r["path_cost"].is_null() && r["path_waypoints"].is_null());
    assert!(r["query_ms_max"].as_f64().unwrap() >= r["query_ms_median"].as_f64().unwrap());
    let again = run_json(&["plan", s(&dir), "--random-pairs", "20", "--seed", "4", "--json"]);
    assert_eq!(again["success_rate"], r["success_rate"]);

    // A goal off the map: exit 1 with the reason.
    let off_map = spomp().args(["plan", s(&dir), "--from", &from_arg, "--to", "500,5"]).output().unwrap();
    assert_eq!(off_map.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&off_map.stderr).contains("off the map"));
}

#[test]
fn bad_inputs_fail_with_the_file_named() {
    let tmp = tempfile::tempdir().unwrap();
    let missing = tmp.path().join("no-such-world");
    for args in [
        vec!["world", "show", s(&missing)],
        vec!["plan", s(&missing), "--from", "1,1", "--to", "2,2"],
        vec!["world", "pano", s(&missing), "--at", "1,1,0", "--out", "x.png"],
    ] {
        let out = spomp().args(&args).output().unwrap();
        assert_eq!(out.status.code(), Some(1), "{args:?}");
        assert!(String::from_utf8_lossy(&out.stderr).contains("no-such-world"), "{args:?}");
    }

    let not_png = tmp.path().join("notes.png");
    std::fs::write(&not_png, "not an image").unwrap();
    let eight_bit = tmp.path().join("eight-bit.png");
    image::GrayImage::from_pixel(64, 16, image::Luma([7])).save(&eight_bit).unwrap();
    let absent = tmp.path().join("absent.png");
    for (file, what) in [(&not_png, "notes.png"), (&eight_bit, "eight-bit.png"), (&absent, "absent.png")] {
        let out = spomp().args(["terrain", s(file)]).output().unwrap();
        assert_eq!(out.status.code(), Some(1), "{what}");
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(err.contains(what), "{err}");
    }
    let err = spomp().args(["terrain", s(&eight_bit)]).output().unwrap();
    assert!(String::from_utf8_lossy(&err.stderr).contains("16-bit"));

    // Usage errors exit 2.
    spomp().args(["plan", "somewhere", "--from", "1,1"]).assert().code(2);
    spomp().args(["world", "pano", "somewhere", "--at", "1,2", "--out", "x.png"]).assert().code(2);
    spomp().args(["world", "generate", "--seed", "1", "--size-m", "0,5", "--out", "x"]).assert().code(2);
    spomp().args(["terrain"]).assert().code(2);
}
