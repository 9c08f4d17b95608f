//! World generation and world files: determinism, round trip, and clear errors for bad files.

use std::path::PathBuf;

use image::{ImageBuffer, Luma, Rgb, RgbImage};
use spomp_core::{ClassTable, GridSpec, Point2};
use spomp_world::{CityParams, UgvLimits, World, WorldError, generate_city, render_png};

fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("spomp-sim-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("scratch dir");
    dir
}

fn small_city() -> CityParams {
    CityParams { width_m: 200.0, height_m: 150.0, vehicle_clusters: 4, roadblocks: 3, ..CityParams::default() }
}

#[test]
fn same_seed_same_world_different_seed_different_world() {
    let a = generate_city(&small_city(), 11).unwrap();
    let b = generate_city(&small_city(), 11).unwrap();
    let c = generate_city(&small_city(), 12).unwrap();
    assert_eq!(a, b);
    assert_eq!(a.map().rgb, b.map().rgb);
    assert_ne!(a.map().rgb, c.map().rgb);
}

#[test]
fn default_city_has_the_papers_features() {
    let p = CityParams::default();
    let w = generate_city(&p, 3).unwrap();
    let t = w.classes();
    let id = |n: &str| t.by_name(n).unwrap().index;
    assert_eq!((w.spec().width, w.spec().height), (800, 600));
    assert_eq!(w.meta.vehicle_clusters.len(), 15);
    assert_eq!(w.meta.roadblocks.len(), 6);
    assert_eq!(w.meta.start_poses.len(), 10);
    // Every cluster centre has vehicles (1.5 m tall) within a few metres, and clusters are
    // far enough apart to be told apart by a 15 m merge distance.
    for (k, &c) in w.meta.vehicle_clusters.iter().enumerate() {
        let near = (0..w.spec().len()).filter(|&i| {
            w.map().class[i] == id("vehicle") && w.spec().center(w.spec().cell_of_index(i)).distance(c) < 10.0
        });
        let n = near.clone().count();
        assert!(n >= 3 * 36, "cluster {k} has only {n} vehicle cells");
        assert!(near.into_iter().all(|i| (w.map().elevation[i] - 1.5).abs() < 1e-6));
        for &o in &w.meta.vehicle_clusters[..k] {
            assert!(o.distance(c) > 20.0, "clusters {o:?} and {c:?} too close");
        }
    }
    // Roadblocks: labelled road, physically high.
    for &r in &w.meta.roadblocks {
        assert_eq!(w.class_at(r), Some(id("road")));
        assert!(w.elevation_at(r).unwrap() > 1.0);
    }
    // Ramps: sidewalk class, in-between heights, a colour unlike the sidewalk's.
    let ramps: Vec<usize> = (0..w.spec().len())
        .filter(|&i| {
            w.map().class[i] == id("grass_sidewalk") && w.map().elevation[i] > 0.0 && w.map().elevation[i] < 0.15
        })
        .collect();
    assert!(ramps.len() > 100, "{} ramp cells", ramps.len());
    let sidewalk_cell = (0..w.spec().len())
        .find(|&i| w.map().class[i] == id("grass_sidewalk") && w.map().elevation[i] == 0.15 && w.map().rgb[i][0] > 140)
        .unwrap();
    let (ramp_rgb, walk_rgb) = (w.map().rgb[ramps[0]], w.map().rgb[sidewalk_cell]);
    let diff: i32 = (0..3).map(|k| (ramp_rgb[k] as i32 - walk_rgb[k] as i32).abs()).sum();
    assert!(diff > 60, "ramp {ramp_rgb:?} vs sidewalk {walk_rgb:?}");
    // Other classes are all present.
    for name in ["building", "vegetation", "tree_trunk", "light_pole", "road"] {
        assert!(w.count_class(id(name)) > 0, "no {name}");
    }
    // Start poses are free for a robot.
    let limits = UgvLimits::default();
    assert!(w.meta.start_poses.iter().all(|s| limits.can_stand(&w, s.position())));
    assert!(w.meta.start_poses.iter().all(|s| s.x < 40.0 && s.y < 15.0));
}

#[test]
fn bad_city_parameters_are_errors() {
    let p = CityParams { block_pitch_m: 15.0, ..CityParams::default() };
    assert!(matches!(generate_city(&p, 0), Err(WorldError::Invalid { .. })));
    let p = CityParams { width_m: f64::NAN, ..CityParams::default() };
    assert!(generate_city(&p, 0).is_err());
    let p = CityParams { width_m: 1e9, ..CityParams::default() };
    assert!(generate_city(&p, 0).is_err());
}

#[test]
fn save_then_load_round_trips() {
    let w = generate_city(&small_city(), 5).unwrap();
    let dir = scratch("roundtrip");
    w.save(&dir).unwrap();
    let back = World::load(&dir).unwrap();
    assert_eq!(back.spec(), w.spec());
    assert_eq!(back.map().class, w.map().class);
    assert_eq!(back.map().rgb, w.map().rgb);
    assert_eq!(back.classes(), w.classes());
    assert_eq!(back.meta, w.meta);
    let worst = back.map().elevation.iter().zip(&w.map().elevation).map(|(a, b)| (a - b).abs()).fold(0.0f32, f32::max);
    assert!(worst < 1e-4, "elevation differs by {worst} m");
    // The picture has one pixel per cell.
    let img = render_png(&w);
    assert_eq!((img.width(), img.height()), (w.spec().width, w.spec().height));
    let _ = std::fs::remove_dir_all(&dir);
}

/// A 4 × 3 world file set: road everywhere, one building pixel at image (1, 0) = cell (1, 2).
fn write_tiny(dir: &std::path::Path, yaml: &str) {
    let t = ClassTable::default_table();
    let road = t.by_name("road").expect("road").color;
    let building = t.by_name("building").expect("building").color;
    let mut img = RgbImage::from_pixel(4, 3, Rgb(road));
    img.put_pixel(1, 0, Rgb(building));
    img.save(dir.join("class.png")).expect("class.png");
    std::fs::write(dir.join("world.yaml"), yaml).expect("world.yaml");
}

const TINY: &str = "resolution_m: 0.5\norigin: {x: 10.0, y: 20.0}\nlayers:\n  class: class.png\n";

#[test]
fn class_only_world_derives_elevation_and_colours() {
    let dir = scratch("tiny");
    write_tiny(&dir, TINY);
    let w = World::load(&dir).unwrap();
    assert_eq!(*w.spec(), GridSpec::new(Point2::new(10.0, 20.0), 0.5, 4, 3));
    // North-up image: pixel row 0 is the northern row 2.
    let building = Point2::new(10.0 + 1.5 * 0.5, 20.0 + 2.5 * 0.5);
    assert_eq!(w.class_at(building), Some(2));
    assert_eq!(w.elevation_at(building), Some(12.0));
    assert_eq!(w.elevation_at(Point2::new(10.25, 20.25)), Some(0.0));
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn unknown_colour_names_its_pixel() {
    let dir = scratch("colour");
    write_tiny(&dir, TINY);
    let mut img = image::open(dir.join("class.png")).unwrap().to_rgb8();
    img.put_pixel(3, 2, Rgb([1, 2, 3]));
    img.save(dir.join("class.png")).unwrap();
    let err = World::load(&dir).unwrap_err();
    assert!(matches!(err, WorldError::UnknownColor { x: 3, y: 2, color: [1, 2, 3], .. }), "{err}");
    assert!(err.to_string().contains("pixel (x 3, y 2)"), "{err}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn wrong_layer_size_is_reported() {
    let dir = scratch("size");
    let yaml = format!("{TINY}  elevation: {{file: elevation.png, scale_m: 0.01}}\n");
    write_tiny(&dir, &yaml);
    let elev: ImageBuffer<Luma<u16>, Vec<u16>> = ImageBuffer::new(5, 3);
    elev.save(dir.join("elevation.png")).unwrap();
    let err = World::load(&dir).unwrap_err();
    assert!(
        matches!(
            err,
            WorldError::WrongSize { layer: "elevation", width: 4, height: 3, got_width: 5, got_height: 3, .. }
        ),
        "{err}"
    );
    // Declared size against the class layer too.
    write_tiny(&dir, "resolution_m: 0.5\nwidth: 7\nheight: 3\nlayers: {class: class.png}\n");
    assert!(matches!(World::load(&dir), Err(WorldError::WrongSize { layer: "class", .. })));
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn eight_bit_elevation_is_rejected() {
    let dir = scratch("elev8");
    write_tiny(&dir, &format!("{TINY}  elevation: {{file: elevation.png, scale_m: 0.01}}\n"));
    image::GrayImage::new(4, 3).save(dir.join("elevation.png")).unwrap();
    let err = World::load(&dir).unwrap_err();
    assert!(matches!(err, WorldError::BadImage { .. }) && err.to_string().contains("16-bit"), "{err}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn missing_layers_and_bad_yaml_are_reported() {
    let dir = scratch("missing");
    write_tiny(&dir, "resolution_m: 0.5\nlayers:\n  class: class.png\n  color: nope.png\n");
    assert!(matches!(World::load(&dir), Err(WorldError::MissingLayer { layer: "color", .. })));
    std::fs::remove_file(dir.join("class.png")).unwrap();
    assert!(matches!(World::load(&dir), Err(WorldError::MissingLayer { layer: "class", .. })));
    write_tiny(&dir, "resolution_m: 0.5\nlayers: {class: class.png}\nbogus: 1\n");
    let err = World::load(&dir).unwrap_err();
    assert!(matches!(err, WorldError::BadYaml { .. }) && err.to_string().contains("bogus"), "{err}");
    write_tiny(&dir, "resolution_m: -1\nlayers: {class: class.png}\n");
    assert!(matches!(World::load(&dir), Err(WorldError::BadYaml { .. })));
    write_tiny(&dir, "layers: [\n");
    assert!(matches!(World::load(&dir), Err(WorldError::BadYaml { .. })));
    std::fs::remove_file(dir.join("world.yaml")).unwrap();
    assert!(matches!(World::load(&dir), Err(WorldError::Io { .. })));
    // A corrupt PNG.
    write_tiny(&dir, TINY);
    std::fs::write(dir.join("class.png"), b"not a png").unwrap();
    assert!(matches!(World::load(&dir), Err(WorldError::BadImage { .. })));
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn an_aerial_view_shows_what_is_seen_from_above_and_survives_a_round_trip() {
    // The ground: a vegetation barrier (1 m) at image (2, 1) = cell (2, 1) across the road; seen
    // from above it is road. The building at cell (1, 2) is seen as it is.
    let dir = scratch("aerial");
    write_tiny(&dir, &format!("{TINY}  aerial: {{class: aerial.png}}\n"));
    let t = ClassTable::default_table();
    let vegetation = t.by_name("vegetation").unwrap();
    let road = t.by_name("road").unwrap();
    let mut ground = image::open(dir.join("class.png")).unwrap().to_rgb8();
    let aerial = ground.clone();
    ground.put_pixel(2, 1, Rgb(vegetation.color));
    ground.save(dir.join("class.png")).unwrap();
    aerial.save(dir.join("aerial.png")).unwrap();
    let w = World::load(&dir).unwrap();
    let barrier = Point2::new(10.0 + 2.5 * 0.5, 20.0 + 1.5 * 0.5);
    let i = w.spec().index(w.spec().cell_at(barrier).unwrap());
    assert!(w.has_aerial_view());
    assert_eq!((w.class_at(barrier), w.elevation_at(barrier)), (Some(vegetation.index), Some(1.0)));
    let seen = w.aerial_map();
    assert_eq!((seen.class[i], seen.rgb[i], seen.elevation[i]), (road.index, road.color, 0.0));
    // A prior map is the view from above; every other cell is the ground's.
    assert_eq!(*w.shared_map(), *seen);
    let differ = (0..w.spec().len()).filter(|&k| seen.class[k] != w.map().class[k]).count();
    assert_eq!(differ, 1);
    // Saved and loaded back: the same world, aerial view and all.
    let saved = scratch("aerial-saved");
    w.save(&saved).unwrap();
    let back = World::load(&saved).unwrap();
    assert_eq!(back.aerial_map(), w.aerial_map());
    assert_eq!(back.map(), w.map());
    // The same raster as the ground is no aerial view of its own.
    ground.save(dir.join("aerial.png")).unwrap();
    assert!(!World::load(&dir).unwrap().has_aerial_view());
    // Errors name the layer: a wrong size, an unknown colour, a missing file.
    RgbImage::new(5, 3).save(dir.join("aerial.png")).unwrap();
    assert!(matches!(World::load(&dir), Err(WorldError::WrongSize { layer: "aerial.class", .. })));
    let mut odd = ground.clone();
    odd.put_pixel(0, 0, Rgb([1, 2, 3]));
    odd.save(dir.join("aerial.png")).unwrap();
    assert!(matches!(World::load(&dir), Err(WorldError::UnknownColor { x: 0, y: 0, .. })));
    std::fs::remove_file(dir.join("aerial.png")).unwrap();
    assert!(matches!(World::load(&dir), Err(WorldError::MissingLayer { layer: "aerial.class", .. })));
    let _ = std::fs::remove_dir_all(&dir);
    let _ = std::fs::remove_dir_all(&saved);
}

#[test]
fn class_table_from_a_file_is_checked() {
    let dir = scratch("table");
    write_tiny(&dir, "resolution_m: 0.5\nclass_table: classes.yaml\nlayers: {class: class.png}\n");
    std::fs::write(dir.join("classes.yaml"), spomp_core::classes::DEFAULT_CLASS_TABLE_YAML).unwrap();
    assert!(World::load(&dir).is_ok());
    std::fs::write(dir.join("classes.yaml"), "classes:\n  - {index: 0, name: a, rank: 9, color: [0,0,0]}\n").unwrap();
    assert!(matches!(World::load(&dir), Err(WorldError::ClassTable(_))));
    let _ = std::fs::remove_dir_all(&dir);
}

mod never_panics {
    use super::*;
    use proptest::prelude::*;

    proptest! {
        #![proptest_config(ProptestConfig { cases: 16, ..ProptestConfig::default() })]
        /// Any city parameters give a world or an error, never a panic; worlds are well formed.
        #[test]
        fn any_city_parameters(
            width in 20.0..160.0f64, height in 20.0..160.0f64, pitch in 10.0..90.0f64,
            road in 0.5..20.0f64, sidewalk in 0.0..6.0f64, clusters in 0usize..8,
            vmin in 0usize..4, vmax in 0usize..8, blocks in 0usize..6, seed in any::<u64>(),
        ) {
            let p = CityParams {
                width_m: width, height_m: height, block_pitch_m: pitch, road_width_m: road,
                sidewalk_width_m: sidewalk, vehicle_clusters: clusters,
                vehicles_per_cluster_min: vmin, vehicles_per_cluster_max: vmax, roadblocks: blocks,
                ..CityParams::default()
            };
            if let Ok(w) = generate_city(&p, seed) {
                prop_assert_eq!(w.map().class.len(), w.spec().len());
                prop_assert!(w.map().elevation.iter().all(|e| e.is_finite()));
            }
        }

        /// Any world.yaml text gives a world or an error, never a panic.
        #[test]
        fn any_world_yaml(text in "\\PC{0,200}") {
            let dir = scratch("fuzz");
            write_tiny(&dir, &text);
            let _ = World::load(&dir);
            let _ = std::fs::remove_dir_all(&dir);
        }
    }
}

#[test]
fn clusters_are_reachable_and_sidewalks_only_up_ramps() {
    use spomp_world::reachable_cells;
    let limits = UgvLimits::default();
    let w = generate_city(&CityParams::default(), 3).unwrap();
    let start = w.meta.start_poses[0].position();
    let reach = reachable_cells(&w, &limits, start);
    let spec = *w.spec();
    for &c in &w.meta.vehicle_clusters {
        let near = (0..spec.len()).any(|i| reach.data[i] && spec.center(spec.cell_of_index(i)).distance(c) < 7.0);
        assert!(near, "no reachable cell within 7 m of the cluster at {c:?}");
    }
    for &r in &w.meta.roadblocks {
        assert!(!*reach.get(r).unwrap());
    }
    let raised = |g: &spomp_core::Grid<bool>, w: &World| {
        (0..spec.len()).filter(|&i| g.data[i] && (w.map().elevation[i] - 0.15).abs() < 1e-6).count()
    };
    assert!(raised(&reach, &w) > 10_000, "ramps lead up onto the blocks");
    // Without ramps, no block can be climbed.
    let flat = generate_city(&CityParams { ramp_probability: 0.0, ..CityParams::default() }, 3).unwrap();
    let reach_flat = reachable_cells(&flat, &limits, flat.meta.start_poses[0].position());
    assert_eq!(raised(&reach_flat, &flat), 0);
    assert!(reach_flat.data.iter().filter(|&&r| r).count() > 100_000, "the roads are still open");
}

/// Every bad `world.yaml` in `tests/fixtures/bad-worlds/` (with a valid class layer beside it) is
/// refused with the line and column of the offending value and its field, as its first two
/// lines say: `# expect: LINE:COLUMN FIELD` and `# message: TEXT THE MESSAGE CONTAINS`.
#[test]
fn bad_world_files_are_refused_at_their_line_column_and_field() {
    let fixtures = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/bad-worlds");
    let mut files: Vec<PathBuf> =
        std::fs::read_dir(&fixtures).expect("fixtures").map(|e| e.expect("entry").path()).collect();
    files.sort();
    assert!(files.len() >= 10, "{} fixtures", files.len());
    let dir = scratch("bad-worlds");
    for file in files {
        let name = file.file_name().expect("name").to_string_lossy().into_owned();
        let text = std::fs::read_to_string(&file).expect("fixture");
        let mut lines = text.lines();
        let expect = lines.next().and_then(|l| l.strip_prefix("# expect: ")).expect("# expect: line");
        let message = lines.next().and_then(|l| l.strip_prefix("# message: ")).expect("# message: line");
        let (place, field) = expect.split_once(' ').expect("LINE:COLUMN FIELD");
        let (line, column) = place.split_once(':').expect("LINE:COLUMN");
        let (line, column): (u32, u32) = (line.parse().expect("line"), column.parse().expect("column"));
        write_tiny(&dir, &text);
        let err = World::load(&dir).expect_err(&name);
        let WorldError::BadYaml { line: got_line, column: got_column, field: got_field, message: got, .. } = &err
        else {
            panic!("{name}: {err:?}");
        };
        assert_eq!((*got_line, *got_column, got_field.as_str()), (line, column, field), "{name}: {err}");
        assert!(got.contains(message), "{name}: `{got}` lacks `{message}`");
        let shown = err.to_string();
        assert!(shown.contains(&format!("world.yaml:{line}:{column}: bad world description: ")), "{name}: {shown}");
        if let Some(last) = field.rsplit('.').next().filter(|s| !s.is_empty()) {
            assert!(shown.contains(last), "{name}: the message does not name `{last}`: {shown}");
        }
    }
    let _ = std::fs::remove_dir_all(&dir);
}
