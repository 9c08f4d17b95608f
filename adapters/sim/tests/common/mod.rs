//! Shared pieces of the simulator's integration tests: missions written to temporary files and
//! run in the lockstep runner, one UGV's runtime and tree built from a one-role mission and
//! driven in closed loop with the simulator's models, and world painting.

#![allow(dead_code, clippy::unwrap_used, clippy::expect_used)] // each test file uses a subset

use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use spomp_behaviors::mission::{BuildOptions, LoadOptions, LoadedMission, build_executor, load_mission_with};
use spomp_behaviors::{Status, TreeExecutor};
use spomp_core::{Cell, ClassTable, GridSpec, Point2, Pose2, PoseEstimate, RobotId, RobotKind, Time, Twist2};
use spomp_robot::registry as builtin_registry;
use spomp_robot::runtime::{DrivenRuntime, NavParams, RuntimeConfig};
use spomp_robot::{RobotRuntime, WatchdogParams};

/// A UGV's tree over its runtime.
pub type RobotExecutor = TreeExecutor<RobotRuntime>;
use spomp_global_planner::GlobalPlannerParams;
use spomp_local_planner::LocalPlannerParams;
use spomp_sim::run::{SimOptions, Simulation};
use spomp_sim::{OdometryModel, OdometryNoiseParams, PanoramaSensor, SensorParams, Ugv, UgvParams};
use spomp_teamstate::TeamStateParams;
use spomp_world::world_for_mission;
use spomp_world::{Obstacle, World};

/// Writes a mission to a temporary file named after it (unique per test process).
pub fn write_mission(name: &str, text: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("spomp-sim-test-{}-{name}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join(format!("{name}.yaml"));
    std::fs::write(&path, text).unwrap();
    path
}

/// Loads a mission that must be valid; besides its own folder, it may include from the
/// shipped `missions/` folder (as with `--allow-dir missions`).
pub fn load(path: &Path) -> LoadedMission {
    let options = LoadOptions { allowed_dirs: vec![Path::new(env!("CARGO_MANIFEST_DIR")).join("../../missions")] };
    let loaded = load_mission_with(path, &builtin_registry(), &options);
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
pub fn driver(world: &World, s: DriverSetup<'_>) -> (DrivenRuntime, RobotExecutor) {
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
    let loaded = load_mission_with(&path, &registry, &LoadOptions::default());
    assert!(loaded.diagnostics.is_empty(), "{mission}\n{:#?}", loaded.diagnostics);
    let config = RuntimeConfig::basic(RobotId::new(s.id), RobotKind::Ugv, s.priority, s.start)
        .with_classes(world.classes().clone())
        .with_map_spec(*world.spec())
        .with_team(s.team)
        .with_nav(NavParams {
            local: LocalPlannerParams::simulation(),
            global: s.global,
            watchdog: WatchdogParams::default(),
        })
        .with_seed(7)
        .with_prior_map(s.with_map.then(|| world.shared_map()));
    let rt: DrivenRuntime = RobotRuntime::from_config(config).unwrap().into();
    let ex = build_executor(&loaded.roles["driver"], &registry, rt.id(), s.start, BuildOptions::default()).unwrap();
    (rt, ex)
}

/// One UGV in closed loop with the simulator: ground-truth poses, noisy odometry and rendered
/// panoramas into its runtime, its tree ticked at 10 Hz, the skid-steer model driven by the
/// commands.
pub struct DrivingRobot {
    pub world: World,
    pub ugv: Ugv,
    pub odom: OdometryModel,
    pub sensor: PanoramaSensor,
    pub rt: DrivenRuntime,
    pub ex: RobotExecutor,
    pub t: Time,
    /// Everything the tree reported, in order.
    pub reports: Vec<String>,
}

impl DrivingRobot {
    /// The robot of `setup` in `world`.
    pub fn new(world: World, setup: DriverSetup<'_>) -> DrivingRobot {
        let start = setup.start;
        let (rt, ex) = driver(&world, setup);
        let ugv = Ugv::new(&world, UgvParams::default(), start).unwrap();
        let odom = OdometryModel::new(OdometryNoiseParams::default(), 1.0, start, 11);
        let sensor = PanoramaSensor::new(&SensorParams::default()).unwrap();
        DrivingRobot { world, ugv, odom, sensor, rt, ex, t: Time::ZERO, reports: Vec::new() }
    }

    /// Sensor inputs and upkeep (terrain analysis, scans into the planner, training when due).
    pub fn sense(&mut self) {
        self.sense_among(&[]);
    }

    /// [`Self::sense`] with `others` (other robots' bodies) drawn into the panoramas.
    pub fn sense_among(&mut self, others: &[Obstacle]) {
        let t = self.t;
        let pose = self.ugv.pose();
        let odom = self.odom.update(t, pose, self.ugv.twist());
        self.rt.on_odometry(odom);
        self.rt.on_external_pose(PoseEstimate { stamp: t, pose, covariance: [0.0; 9], confidence: 1.0 });
        if let Some(frame) =
            self.sensor.poll_among(t, &self.world, pose, self.ugv.base_elevation_m(), odom.pose, others)
        {
            self.rt.on_panorama(Arc::new(frame));
        }
        self.rt.maintain(t);
    }

    /// The robot moves under `cmd` for 0.1 s.
    pub fn advance(&mut self, cmd: Twist2) {
        self.ugv.step(&self.world, cmd, 0.1);
        self.t = Time::from_millis(self.t.nanos / 1_000_000 + 100);
    }

    /// One 0.1 s period: sensor inputs, upkeep, one tick, the robot moves.
    pub fn step(&mut self) -> Status {
        self.sense();
        self.rt.begin_tick();
        let status = self.ex.tick(self.t, &mut self.rt, None);
        self.reports.extend(self.ex.blackboard_mut().take_reports());
        self.advance(self.rt.command().unwrap_or(Twist2::ZERO));
        status
    }

    /// Steps until the tree finishes or `max_s` of simulated time pass.
    pub fn run(&mut self, max_s: f64) -> Status {
        while self.t.as_secs_f64() < max_s {
            let s = self.step();
            if s != Status::Running {
                return s;
            }
        }
        Status::Running
    }

    pub fn position(&self) -> Point2 {
        self.ugv.pose().position()
    }

    /// Edges the robot's own scans removed from its graph.
    pub fn removed_edges(&self) -> usize {
        self.rt.nav().map_or(0, |n| n.global().graph_stats().removed_edges)
    }

    /// Where the robot is and what it went through, for assertion messages.
    pub fn summary(&self) -> String {
        let nav = self.rt.nav();
        format!(
            "t = {:.1} s, at ({:.1}, {:.1}), driven {:.1} m, {} collisions, graph {:?}, {} edges removed by scans, {} \
             blocked by being stuck, failure {:?}, reports {:?}, problems {:?}",
            self.t.as_secs_f64(),
            self.ugv.pose().x,
            self.ugv.pose().y,
            self.ugv.distance_m(),
            self.ugv.collisions(),
            nav.map(|n| n.global().graph_stats()),
            self.removed_edges(),
            nav.map_or(0, |n| n.blocked_edges().len()),
            self.ex.blackboard().get_by_name("why"),
            self.reports,
            self.rt.problems()
        )
    }
}

/// A ring road around a block: the bottom street y ∈ [0, 8), the top street y ∈ [20, 28), the
/// side streets x ∈ [0, 8) and [52, 60); buildings (class 2, 10 m) fill the block and the
/// world's edges; the roads are class 0.
pub fn ring() -> World {
    let (road, building) = (0, 2);
    let spec = GridSpec::new(Point2::new(-4.0, -4.0), 0.5, 136, 72);
    let mut w = World::flat(spec, ClassTable::default_table(), building, 10.0).unwrap();
    fill(&mut w, (0.0, 60.0), (0.0, 8.0), road, 0.0);
    fill(&mut w, (0.0, 60.0), (20.0, 28.0), road, 0.0);
    fill(&mut w, (0.0, 8.0), (0.0, 28.0), road, 0.0);
    fill(&mut w, (52.0, 60.0), (0.0, 28.0), road, 0.0);
    w
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
