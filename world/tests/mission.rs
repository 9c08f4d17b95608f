//! A mission's world and operating area, as `spomp sim` and `spomp run` both take them.

use spomp_behaviors::mission::MissionFile;
use spomp_world::{CityParams, generate_city, operating_area, world_for_mission};

fn mission(sim: &str) -> MissionFile {
    let yaml = format!(
        "mission: m\nteam:\n  - {{ id: ugv1, kind: ugv, role: r, start: {{ x_m: 1, y_m: 1 }} }}\n\
         roles:\n  r:\n    tree: {{ succeed: {{}} }}\ntime_limit_s: 10\n{sim}"
    );
    serde_saphyr::from_str(&yaml).expect("a mission")
}

#[test]
fn a_mission_without_a_world_gets_the_default_city_of_the_trial_seed() {
    let m = mission("");
    let world = world_for_mission(&m, std::path::Path::new("."), 7).expect("a world");
    assert_eq!(world, generate_city(&CityParams::default(), 7).expect("a city"));
    let area = operating_area(&m, &world).expect("area");
    assert_eq!(area.grid, *world.spec());
    assert!(area.prior_map.is_none(), "no prior map unless the mission asks for one");
}

#[test]
fn a_generated_world_takes_the_missions_size_and_seed_and_the_prior_map_is_the_aerial_view() {
    let m = mission(
        "sim:\n  prior_map: true\n  world: { generate: { size_m: [120, 90], vehicle_clusters: 2, roadblocks: 0, seed: 3 } }\n",
    );
    let world = world_for_mission(&m, std::path::Path::new("."), 99).expect("a world");
    let params =
        CityParams { width_m: 120.0, height_m: 90.0, vehicle_clusters: 2, roadblocks: 0, ..CityParams::default() };
    assert_eq!(world, generate_city(&params, 3).expect("a city"), "the mission's world seed wins over the trial's");
    let area = operating_area(&m, &world).expect("area");
    assert_eq!(area.prior_map.as_deref(), Some(&*world.shared_map()));
}

#[test]
fn a_world_folder_that_is_not_there_is_an_error_naming_it() {
    let m = mission("sim:\n  world: { dir: no-such-world }\n");
    let e = world_for_mission(&m, std::path::Path::new("/nonexistent"), 1).expect_err("no world");
    assert!(e.to_string().contains("no-such-world"), "{e}");
}
