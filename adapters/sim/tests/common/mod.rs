//! Shared pieces of the simulator's integration tests: missions written to temporary files and
//! run in the lockstep runner, one UGV's runtime and tree built from a one-role mission, and
//! world painting.

#![allow(dead_code, clippy::unwrap_used, clippy::expect_used)] // each test file uses a subset

use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use spomp_behaviors::mission::{BuildOptions, LoadedMission, load_mission};
use spomp_behaviors::runtime::{LocalizationSetup, NavParams, RuntimeConfig};
use spomp_behaviors::{RobotExecutor, RobotRuntime, builtin_registry};
use spomp_core::{Cell, Pose2, RobotId, RobotKind};
use spomp_global_planner::GlobalPlannerParams;
use spomp_local_planner::LocalPlannerParams;
use spomp_mapping::Orthomap;
use spomp_sim::World;
use spomp_sim::run::{SimOptions, Simulation, world_for_mission};
use spomp_teamstate::TeamStateParams;

/// Writes a mission to a temporary file named after it (unique per test process).
pub fn write_mission(name: &str, text: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("spomp-sim-test-{}-{name}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join(format!("{name}.yaml"));
    std::fs::write(&path, text).unwrap();
    path
}

/// Loads a mission that must be valid.
pub fn load(path: &Path) -> LoadedMission {
    let loaded = load_mission(path, &builtin_registry());
    assert!(loaded.is_valid(), "{:#?}", loaded.diagnostics);
    loaded
}

/// The mission set up in the runner, in its own world.
pub fn simulation(loaded: &LoadedMission, options: SimOptions) -> Simulation {
    let world = world_for_mission(loaded.mission.as_ref().unwrap(), &loaded.base_dir(), options.seed).unwrap();
    Simulation::new(loaded, &builtin_registry(), Arc::new(world), options).unwrap()
}

/// How to set up the one driving UGV.
pub struct DriverSetup<'a> {
    /// Unique name of the scenario (names the temporary mission file).
    pub name: &'a str,
    /// Robot id.
    pub id: &'a str,
    /// UGV priority.
    pub priority: u32,
    /// Start pose.
    pub start: Pose2,
    /// The role's tree, YAML flow style.
    pub tree: &'a str,
    /// Give the robot the world's full aerial map (as if the UAV had flown everything).
    pub with_map: bool,
    /// Global planner parameters.
    pub global: GlobalPlannerParams,
    /// Team-state parameters.
    pub team: TeamStateParams,
}

/// A UGV runtime (pose from outside, simulation local-planner values) and its tree, from a
/// one-role mission written to a temporary file and loaded like any mission.
pub fn driver(world: &World, s: DriverSetup<'_>) -> (RobotRuntime, RobotExecutor) {
    let mission = format!(
        "mission: {name}\nteam:\n  - {{ id: {id}, kind: ugv, role: driver, priority: {priority}, start: {{ x_m: {x}, \
         y_m: {y}, yaw_deg: {yaw} }} }}\nroles:\n  driver:\n    tree:\n      {tree}\ncomplete_when: \
         all_goals_visited\ntime_limit_s: 3000\n",
        name = s.name,
        id = s.id,
        priority = s.priority,
        x = s.start.x,
        y = s.start.y,
        yaw = s.start.yaw.to_degrees(),
        tree = s.tree,
    );
    let dir = std::env::temp_dir().join(format!("spomp-drive-{}-{}-{}", std::process::id(), s.name, s.id));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("mission.yaml");
    std::fs::File::create(&path).unwrap().write_all(mission.as_bytes()).unwrap();
    let registry = builtin_registry();
    let loaded = load_mission(&path, &registry);
    assert!(loaded.diagnostics.is_empty(), "{mission}\n{:#?}", loaded.diagnostics);
    let config = RuntimeConfig {
        id: RobotId::new(s.id),
        kind: RobotKind::Ugv,
        priority: s.priority,
        start: s.start,
        classes: world.classes().clone(),
        map_spec: Some(*world.spec()),
        team: s.team,
        detection: None,
        localization: LocalizationSetup::External,
        nav: Some(NavParams { local: LocalPlannerParams::simulation(), global: s.global }),
        goal_time_per_m_s: 2.0,
        seed: 7,
    };
    let mut rt = RobotRuntime::from_config(config).unwrap();
    if s.with_map {
        rt.map = Some(Orthomap::from_map(world.map().clone()).unwrap());
    }
    let ex = RobotExecutor::new(&loaded.roles["driver"], &registry, &rt.id, s.start, BuildOptions::default()).unwrap();
    (rt, ex)
}

/// Fills the cells whose centre lies in [x0, x1) × [y0, y1).
pub fn fill(world: &mut World, (x0, x1): (f64, f64), (y0, y1): (f64, f64), class: u8, elevation_m: f32) {
    let spec = *world.spec();
    let color = world.classes().get(class).map_or([0, 0, 0], |c| c.color);
    for row in 0..spec.height {
        for col in 0..spec.width {
            let cell = Cell::new(col, row);
            let c = spec.center(cell);
            if (x0..x1).contains(&c.x) && (y0..y1).contains(&c.y) {
                world.set_cell(cell, class, color, elevation_m);
            }
        }
    }
}
