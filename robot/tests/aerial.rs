//! The UAV's aerial-planner nodes in closed loop: a UAV whose pose this test integrates toward
//! `rt.flight` (straight line, capped speed, hover when None), as the simulator does.
//! - `follow_waypoints` flies in order, resumes where it left off when a state machine leaves
//!   and re-enters the state, keeps `progress` (and with `resume_from` flies back to the point of
//!   interruption so a survey leaves no gap), reads QGroundControl plans (the shipped
//!   `missions/explore.plan`, against hand-computed metres), refuses malformed plans with clear
//!   errors, routes transfers around no-fly polygons and keeps them inside inclusion geofences;
//! - `seek_robot` rotates round-robin over the robots its team state knows and flies to the end
//!   of a robot's path when its pose is stale, re-targeting on newer poses;
//! - `wait_for_sync` succeeds after a full exchange of team states, ignores a sync completed
//!   before the wait began, and fails on timeout.

#![allow(clippy::unwrap_used, clippy::expect_used)] // tests fail loudly by design

use std::path::{Path, PathBuf};
use std::sync::Arc;

use spomp_behaviors::mission::{BuildOptions, build_executor, load_mission};
use spomp_behaviors::registry::PortBindings;
use spomp_behaviors::{BbValue, Binding, Status, TreeExecutor};
use spomp_robot::RobotRuntime;
use spomp_robot::registry as builtin_registry;
use spomp_robot::runtime::DrivenRuntime;

type RobotExecutor = TreeExecutor<RobotRuntime>;
use spomp_core::{Point2, Pose2, PoseEstimate, RobotId, RobotKind, Time};
use spomp_teamstate::{TeamStateParams, TierSet};

const DT_S: f64 = 0.1;

fn temp_dir(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("spomp-aerial-{}-{name}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// Loads `yaml` (written into `dir`) and builds `role` for a robot, plans resolved from `dir`.
fn build(dir: &Path, yaml: &str, role: &str, id: &str, start: Pose2) -> RobotExecutor {
    let path = dir.join("mission.yaml");
    std::fs::write(&path, yaml).unwrap();
    build_from(&path, role, id, start)
}

fn build_from(path: &Path, role: &str, id: &str, start: Pose2) -> RobotExecutor {
    let registry = builtin_registry();
    let loaded = load_mission(path, &registry);
    assert!(loaded.diagnostics.is_empty(), "{:#?}", loaded.diagnostics);
    let opts = BuildOptions { base_dir: Some(loaded.base_dir()), ..BuildOptions::default() };
    build_executor(&loaded.roles[role], &registry, &RobotId::new(id), start, opts).unwrap()
}

fn runtime(id: &str, kind: RobotKind, priority: u32, start: Pose2) -> DrivenRuntime {
    RobotRuntime::new(RobotId::new(id), kind, priority, start, TeamStateParams::default()).unwrap().into()
}

/// A robot's position fix at `t` (GPS on the UAV, the UGV's localizer), published to its team
/// state as adapters do.
fn fix(rt: &mut DrivenRuntime, p: Point2, t: Time) {
    rt.on_external_pose(PoseEstimate {
        stamp: t,
        pose: Pose2::new(p.x, p.y, 0.0),
        confidence: 1.0,
        ..Default::default()
    });
}

/// The simulated UAV: one executor tick at `t`, then fly toward `rt.flight` for `DT_S`.
struct Uav {
    rt: DrivenRuntime,
    ex: RobotExecutor,
    pos: Point2,
    /// Positions after every step.
    track: Vec<Point2>,
    /// Distinct flight targets in the order they were first commanded.
    targets: Vec<Point2>,
    /// Altitude of every command.
    altitudes: Vec<f64>,
}

impl Uav {
    fn new(ex: RobotExecutor, start: Point2) -> Uav {
        let rt = runtime("uav1", RobotKind::Uav, 0, Pose2::new(start.x, start.y, 0.0));
        Uav { rt, ex, pos: start, track: Vec::new(), targets: Vec::new(), altitudes: Vec::new() }
    }

    fn step(&mut self, t: Time) -> Status {
        fix(&mut self.rt, self.pos, t);
        self.rt.begin_tick();
        let s = self.ex.tick(t, &mut self.rt, None);
        if let Some(cmd) = self.rt.flight() {
            self.altitudes.push(cmd.altitude_m);
            if self.targets.last().is_none_or(|p| p.distance(cmd.target) > 1e-9) {
                self.targets.push(cmd.target);
            }
            let d = cmd.target - self.pos;
            let step = (cmd.speed_mps * DT_S).min(d.norm());
            if d.norm() > 0.0 {
                self.pos = self.pos + d * (step / d.norm());
            }
        }
        self.track.push(self.pos);
        s
    }

    /// Steps at 10 Hz from t = 0 until the tree finishes, at most `max_steps` times.
    fn run(&mut self, max_steps: usize) -> Status {
        let mut status = Status::Running;
        let mut n = 0;
        while status == Status::Running && n < max_steps {
            status = self.step(at(n));
            n += 1;
        }
        status
    }

    fn int(&self, name: &str) -> Option<i64> {
        match self.ex.blackboard().get_by_name(name) {
            Some(BbValue::Int(i)) => Some(*i),
            _ => None,
        }
    }

    fn robot(&self, name: &str) -> Option<String> {
        match self.ex.blackboard().get_by_name(name) {
            Some(BbValue::Robot(r)) => Some(r.to_string()),
            _ => None,
        }
    }

    fn reports(&mut self) -> Vec<String> {
        self.ex.blackboard_mut().take_reports()
    }
}

fn at(step: usize) -> Time {
    Time::from_millis(100 * step as i64)
}

fn close(a: Point2, b: Point2, tol: f64) -> bool {
    a.distance(b) <= tol
}

// ------------------------------------------------------------------------ follow_waypoints

const EXPLORE: &str = r#"
mission: explore-and-pause
team:
  - { id: uav1, kind: uav, role: explorer, start: { x_m: 0, y_m: 0 } }
roles:
  explorer:
    blackboard: { next_waypoint: 0 }
    tree:
      state_machine:
        initial: explore
        states:
          explore:
            run:
              follow_waypoints:
                waypoints: [{ x: 50, y: 0 }, { x: 50, y: 50 }, { x: 0, y: 50 }]
                altitude_m: 40
                speed_mps: 5
                progress: "{next_waypoint}"
            transitions:
              - { on: timer, after_s: 12, to: pause }
              - { on: success, to: done }
          pause:
            run: { wait: { duration_s: 5 } }
            transitions: [{ on: success, to: explore }]
          done: { terminal: success }
time_limit_s: 100
"#;

#[test]
fn waypoints_are_flown_in_order_and_resumed_after_the_state_is_left() {
    let ex = build(&temp_dir("explore"), EXPLORE, "explorer", "uav1", Pose2::default());
    let mut uav = Uav::new(ex, Point2::new(0.0, 0.0));
    let mut progress_log = Vec::new();
    let mut paused_at = Vec::new();
    let mut status = Status::Running;
    let mut n = 0;
    while status == Status::Running && n < 1000 {
        status = uav.step(at(n));
        let flying = uav.rt.flight().is_some();
        progress_log.push((n, uav.int("next_waypoint").unwrap(), flying));
        if !flying && status == Status::Running {
            paused_at.push((n, uav.pos));
        }
        n += 1;
    }
    assert_eq!(status, Status::Success, "{:?}", uav.reports());
    assert_eq!(uav.int("next_waypoint"), Some(3));
    // Each waypoint was commanded once, in order: re-entering the state resumed at the waypoint
    // it was heading to, never at the start of the list.
    let wps = [Point2::new(50.0, 0.0), Point2::new(50.0, 50.0), Point2::new(0.0, 50.0)];
    assert_eq!(uav.targets, wps.to_vec());
    assert!(uav.altitudes.iter().all(|a| *a == 40.0));
    // Two pauses of 5 s each (hovering in place, progress kept): the first after 12 s with
    // waypoint 0 done (reached within 2 m at (48, 0) after 9.6 s, then 12 m toward (50, 50)),
    // the second after 12 more seconds of flight with waypoint 1 done.
    let first = paused_at.first().unwrap();
    let last = paused_at.last().unwrap();
    assert!(close(first.1, Point2::new(48.5, 12.0), 0.6), "{first:?}");
    assert!(close(last.1, Point2::new(27.0, 49.2), 0.6), "{last:?}");
    assert!(paused_at.iter().filter(|(_, p)| close(*p, first.1, 1e-9)).count() >= 49, "hovered through the pause");
    let progress_while_paused: Vec<i64> =
        progress_log.iter().filter(|(_, _, flying)| !flying).map(|(_, p, _)| *p).collect();
    assert!(progress_while_paused.iter().all(|p| *p == 1 || *p == 2 || *p == 3), "{progress_while_paused:?}");
    assert!(progress_while_paused.contains(&1) && progress_while_paused.contains(&2));
    // 150 m at 5 m/s plus two 5 s pauses: about 40 s.
    let total_s = n as f64 * DT_S;
    assert!((39.0..42.0).contains(&total_s), "{total_s}");
}

/// A survey (100 m, 30 m and 100 m legs) interrupted after every 20 s of flight by an 8 s errand
/// towards a far point (another state: 40 m away from the survey), as the shipped mission's
/// explorer is interrupted to seek UGVs. `{resume}` is the `resume_from` binding (or nothing).
fn survey_with_errands(resume: &str) -> String {
    format!(
        r#"
mission: survey-with-errands
team:
  - {{ id: uav1, kind: uav, role: explorer, start: {{ x_m: 0, y_m: 0 }} }}
roles:
  explorer:
    blackboard: {{ next_waypoint: 0, errand_step: 0 }}
    tree:
      state_machine:
        initial: survey
        states:
          survey:
            run:
              follow_waypoints:
                waypoints: [{{ x: 0, y: 0 }}, {{ x: 100, y: 0 }}, {{ x: 100, y: 30 }}, {{ x: 0, y: 30 }}]
                speed_mps: 5
                progress: "{{next_waypoint}}"{resume}
            transitions:
              - {{ on: timer, after_s: 20, to: errand }}
              - {{ on: success, to: done }}
          errand:
            run:
              follow_waypoints: {{ waypoints: [{{ x: 50, y: -300 }}], speed_mps: 5, progress: "{{errand_step}}" }}
            transitions: [{{ on: timer, after_s: 8, to: survey }}]
          done: {{ terminal: success }}
time_limit_s: 400
"#
    )
}

/// The longest stretch of the survey legs farther than `tol_m` from every point of `track`.
fn longest_gap(legs: &[(Point2, Point2)], track: &[Point2], tol_m: f64) -> f64 {
    let mut longest: f64 = 0.0;
    for &(a, b) in legs {
        let samples = (a.distance(b) / 0.5).ceil() as usize;
        let mut gap = 0.0;
        for k in 0..=samples {
            let p = a + (b - a) * (k as f64 / samples as f64);
            if track.iter().any(|t| t.distance(p) <= tol_m) {
                gap = 0.0;
            } else {
                gap += a.distance(b) / samples as f64;
                longest = longest.max(gap);
            }
        }
    }
    longest
}

#[test]
fn a_resumed_survey_flies_back_to_where_it_was_interrupted_and_leaves_no_gap() {
    let legs = [
        (Point2::new(0.0, 0.0), Point2::new(100.0, 0.0)),
        (Point2::new(100.0, 0.0), Point2::new(100.0, 30.0)),
        (Point2::new(100.0, 30.0), Point2::new(0.0, 30.0)),
    ];
    let fly = |resume: &str| {
        let ex = build(&temp_dir("survey-errands"), &survey_with_errands(resume), "explorer", "uav1", Pose2::default());
        let mut uav = Uav::new(ex, Point2::new(0.0, 0.0));
        let status = uav.run(4000);
        assert_eq!(status, Status::Success, "{:?}", uav.reports());
        assert_eq!(uav.int("next_waypoint"), Some(4));
        uav
    };
    // Without `resume_from` each errand cuts a corner of the survey: the UAV returns to the
    // waypoint it was heading to, and the stretch between is never flown.
    let plain = fly("");
    // (Corners are cut by up to the 2 m arrival radius, so "flown over" means within 3 m.)
    assert!(longest_gap(&legs, &plain.track, 3.0) > 20.0, "{}", longest_gap(&legs, &plain.track, 3.0));
    // With it, every metre of every leg is flown over.
    let resumed = fly("\n                resume_from: \"{survey_resume}\"");
    assert!(longest_gap(&legs, &resumed.track, 3.0) < 1.0, "{}", longest_gap(&legs, &resumed.track, 3.0));
    let Some(BbValue::Point(last)) = resumed.ex.blackboard().get_by_name("survey_resume") else {
        panic!("resume_from was never written");
    };
    // Written while flying the last leg; the flight back costs time but no coverage.
    assert!((last.y - 30.0).abs() < 2.5, "{last:?}");
    assert!(resumed.track.len() > plain.track.len());
}

#[test]
fn the_shipped_plan_is_flown_in_metres_from_its_planned_home() {
    // missions/uav-explore-relay.yaml flies missions/explore.plan; the plan is resolved relative
    // to the mission file. Hand-computed (equirectangular, R = 6378137 m, home 39.9526 N,
    // 75.1652 W): the first waypoints lie at (15, 15), (385, 15) and (385, 45) metres.
    let mission = Path::new(env!("CARGO_MANIFEST_DIR")).join("../missions/uav-explore-relay.yaml");
    let ex = build_from(&mission, "explorer", "uav1", Pose2::new(10.0, 10.0, 0.0));
    let mut uav = Uav::new(ex, Point2::new(10.0, 10.0));
    let mut n = 0;
    while uav.targets.len() < 4 && n < 2000 {
        assert_eq!(uav.step(at(n)), Status::Running, "{:?}", uav.reports());
        n += 1;
    }
    let expected = [(15.000, 15.000), (384.998, 15.000), (384.998, 45.000)];
    for (got, want) in uav.targets.iter().zip(expected) {
        assert!(close(*got, Point2::new(want.0, want.1), 0.01), "{got:?} vs {want:?}");
    }
    assert_eq!(uav.int("next_waypoint"), Some(3));
    assert!(uav.targets.iter().all(|t| t.x > 0.0 && t.y > 0.0 && t.x < 400.0 && t.y < 300.0));

    // Without the mission's folder the relative path does not resolve, and the build says which
    // file it could not read.
    let registry = builtin_registry();
    let loaded = load_mission(&mission, &registry);
    let err = build_executor(
        &loaded.roles["explorer"],
        &registry,
        &RobotId::new("uav1"),
        Pose2::default(),
        BuildOptions::default(),
    )
    .err()
    .unwrap()
    .to_string();
    assert!(err.contains("explore.plan") && err.contains("cannot read"), "{err}");
}

fn follow_node(ports: &[(&'static str, BbValue)]) -> Result<Box<dyn spomp_behaviors::Behavior<RobotRuntime>>, String> {
    let registry = builtin_registry();
    let mut p = PortBindings::declared(registry.get("follow_waypoints").unwrap());
    for (name, v) in ports {
        p.insert(*name, Binding::Literal(v.clone()));
    }
    for (name, v) in [("altitude_m", 60.0), ("speed_mps", 5.0), ("arrive_radius_m", 2.0)] {
        if !ports.iter().any(|(n, _)| *n == name) {
            p.insert(name, Binding::Literal(BbValue::Float(v)));
        }
    }
    (registry.factory("follow_waypoints").unwrap())(&p).map_err(|e| e.to_string())
}

fn plan_port(path: &Path) -> (&'static str, BbValue) {
    ("plan_file", BbValue::Str(Arc::from(path.to_string_lossy().as_ref())))
}

const GOOD_ITEM: &str =
    r#"{"type": "SimpleItem", "command": 16, "frame": 3, "params": [0, 0, 0, null, 39.9528, -75.1650, 60]}"#;

fn plan_text(items: &str) -> String {
    format!(
        r#"{{"fileType": "Plan", "version": 1, "geoFence": {{"polygons": [], "circles": [], "version": 2}},
            "mission": {{"items": [{items}], "plannedHomePosition": [39.9526, -75.1652, 0], "version": 2}}}}"#
    )
}

#[test]
fn malformed_plans_are_refused_at_build_with_the_file_and_the_reason() {
    let dir = temp_dir("bad-plans");
    let cases: Vec<(&str, String, &str)> = vec![
        ("not-json.plan", "{ \"fileType\": \"Plan\", ".into(), "not valid JSON"),
        ("wrong-type.plan", r#"{"fileType": "Fence", "mission": {}}"#.into(), "expected `Plan`"),
        ("list.plan", "[1, 2]".into(), "expected a JSON object"),
        (
            "no-home.plan",
            r#"{"fileType": "Plan", "mission": {"items": []}}"#.into(),
            "missing `mission.plannedHomePosition`",
        ),
        (
            "bad-home.plan",
            r#"{"fileType": "Plan", "mission": {"items": [], "plannedHomePosition": [123, 4, 0]}}"#.into(),
            "latitude 123",
        ),
        ("empty.plan", plan_text(""), "has no waypoints"),
        (
            "survey.plan",
            plan_text(&format!(r#"{GOOD_ITEM}, {{"type": "ComplexItem", "complexItemType": "survey"}}"#)),
            "mission.items[1]: complex item `survey` is not supported",
        ),
        (
            "land.plan",
            plan_text(&GOOD_ITEM.replace("\"command\": 16", "\"command\": 21")),
            "mission.items[0]: navigation command 21 NAV_LAND is not supported",
        ),
        (
            "short-params.plan",
            plan_text(r#"{"type": "SimpleItem", "command": 16, "frame": 3, "params": [0, 0, 39.95, -75.16]}"#),
            "7 `params`",
        ),
        ("null-lat.plan", plan_text(&GOOD_ITEM.replace("39.9528", "null")), "params[4] (latitude) must be a number"),
        ("local-frame.plan", plan_text(&GOOD_ITEM.replace("\"frame\": 3", "\"frame\": 1")), "frame 1"),
    ];
    for (name, text, why) in &cases {
        let path = dir.join(name);
        std::fs::write(&path, text).unwrap();
        let err = follow_node(&[plan_port(&path)]).err().unwrap_or_else(|| panic!("{name} was accepted"));
        assert!(err.contains(name) && err.contains(why), "{name}: {err}");
    }
    let missing = dir.join("missing.plan");
    let err = follow_node(&[plan_port(&missing)]).err().unwrap();
    assert!(err.contains("missing.plan") && err.contains("cannot read"), "{err}");

    // Exactly one waypoint source.
    let good = dir.join("good.plan");
    std::fs::write(&good, plan_text(GOOD_ITEM)).unwrap();
    assert!(follow_node(&[plan_port(&good)]).is_ok());
    let wps = ("waypoints", BbValue::Points(Arc::new(vec![Point2::new(1.0, 2.0)])));
    let both = follow_node(&[plan_port(&good), wps.clone()]).err().unwrap();
    assert!(both.contains("not both"), "{both}");
    let neither = follow_node(&[]).err().unwrap();
    assert!(neither.contains("either `waypoints`") && neither.contains("plan_file"), "{neither}");
    let slow = follow_node(&[wps, ("speed_mps", BbValue::Float(0.0))]).err().unwrap();
    assert!(slow.contains("speed_mps"), "{slow}");
}

fn square(x0: f64, y0: f64, x1: f64, y1: f64) -> Vec<Point2> {
    vec![Point2::new(x0, y0), Point2::new(x1, y0), Point2::new(x1, y1), Point2::new(x0, y1)]
}

fn inside_box(p: Point2, b: &[Point2]) -> bool {
    p.x > b[0].x && p.x < b[2].x && p.y > b[0].y && p.y < b[2].y
}

#[test]
fn transfers_route_around_no_fly_polygons() {
    const NO_FLY: &str = r#"
mission: no-fly
team:
  - { id: uav1, kind: uav, role: explorer, start: { x_m: 0, y_m: 0 } }
roles:
  explorer:
    blackboard: { next: 0 }
    tree:
      follow_waypoints:
        waypoints: [{ x: 100, y: 0 }, { x: 0, y: 5 }]
        speed_mps: 5
        progress: "{next}"
        no_fly: { zones: [[{ x: 40, y: -20 }, { x: 60, y: -20 }, { x: 60, y: 20 }, { x: 40, y: 20 }]], margin_m: 3 }
time_limit_s: 100
"#;
    let zone = square(40.0, -20.0, 60.0, 20.0);
    let ex = build(&temp_dir("no-fly"), NO_FLY, "explorer", "uav1", Pose2::default());
    let mut uav = Uav::new(ex, Point2::new(0.0, 0.0));
    let status = uav.run(2000);
    assert_eq!(status, Status::Success, "{:?}", uav.reports());
    assert!(uav.track.iter().all(|p| !inside_box(*p, &zone)), "the UAV entered the zone");
    // It went around a side (via two corners pushed out by the margin), both ways, and the
    // detour is short: straight 100 m, around about 2 × √(40² + 23²) + 20 ≈ 112 m.
    let flown: f64 = uav.track.windows(2).map(|w| w[0].distance(w[1])).sum();
    assert!(flown > 200.0 && flown < 235.0, "{flown}");
    assert!(
        uav.targets.iter().any(|t| close(*t, Point2::new(37.0, 23.0), 0.1) || close(*t, Point2::new(37.0, -23.0), 0.1))
    );
    assert!(uav.targets.len() >= 6, "corners on both transfers: {:?}", uav.targets);

    // A waypoint inside a zone is refused when the mission is built.
    let inside = follow_node(&[
        ("waypoints", BbValue::Points(Arc::new(vec![Point2::new(50.0, 0.0)]))),
        (
            "no_fly",
            BbValue::Params(Arc::new(
                serde_json::json!({ "zones": [[{"x": 40, "y": -20}, {"x": 60, "y": -20}, {"x": 60, "y": 20}]] }),
            )),
        ),
    ])
    .err()
    .unwrap();
    assert!(inside.contains("waypoint 0") && inside.contains("no-fly zone 0"), "{inside}");
    let bad = follow_node(&[
        ("waypoints", BbValue::Points(Arc::new(vec![Point2::new(50.0, 0.0)]))),
        ("no_fly", BbValue::Params(Arc::new(serde_json::json!({ "zones": [[{"x": 40, "y": -20}]] })))),
    ])
    .err()
    .unwrap();
    assert!(bad.contains("at least 3 vertices"), "{bad}");
}

#[test]
fn exclusion_geofences_of_a_plan_are_avoided() {
    // Home 39.9526 N 75.1652 W; waypoints about 170 m east and back; an exclusion polygon in
    // between.
    let dir = temp_dir("fence");
    let plan = r#"{"fileType": "Plan", "version": 1,
      "geoFence": {"version": 2, "circles": [], "polygons": [{"inclusion": false, "version": 1,
        "polygon": [[39.9525, -75.1645], [39.9525, -75.1640], [39.9528, -75.1640], [39.9528, -75.1645]]}]},
      "mission": {"version": 2, "plannedHomePosition": [39.9526, -75.1652, 0], "items": [
        {"type": "SimpleItem", "command": 16, "frame": 3, "params": [0, 0, 0, null, 39.9526, -75.1632, 60]}]}}"#;
    std::fs::write(dir.join("fenced.plan"), plan).unwrap();
    let yaml = r#"
mission: fenced
team:
  - { id: uav1, kind: uav, role: explorer, start: { x_m: 0, y_m: 0 } }
roles:
  explorer:
    blackboard: { next: 0 }
    tree: { follow_waypoints: { plan_file: fenced.plan, speed_mps: 8, progress: "{next}" } }
time_limit_s: 100
"#;
    let ex = build(&dir, yaml, "explorer", "uav1", Pose2::default());
    let mut uav = Uav::new(ex, Point2::new(0.0, 0.0));
    let status = uav.run(2000);
    assert_eq!(status, Status::Success, "{:?}", uav.reports());
    // The fence in metres: x 59.7..102.4, y -11.1..22.3 (hand-computed as above).
    let fence = square(59.7, -11.1, 102.4, 22.3);
    assert!(uav.track.iter().all(|p| !inside_box(*p, &fence)), "the UAV crossed the geofence");
    assert!(close(uav.pos, Point2::new(170.7, 0.0), 2.1), "{:?}", uav.pos);
}

/// Latitude and longitude of a map point of a plan whose home is 39.9526 N 75.1652 W (the plan
/// module's equirectangular projection, inverted).
fn latlon(x: f64, y: f64) -> [f64; 2] {
    const R: f64 = 6_378_137.0;
    let (lat0, lon0) = (39.9526_f64, -75.1652_f64);
    [lat0 + (y / R).to_degrees(), lon0 + (x / (R * lat0.to_radians().cos())).to_degrees()]
}

/// Even-odd point-in-polygon test (the fence check of the tests, independent of the node's).
fn in_polygon(poly: &[Point2], p: Point2) -> bool {
    let n = poly.len();
    let mut inside = false;
    for i in 0..n {
        let (a, b) = (poly[i], poly[(i + n - 1) % n]);
        if (a.y > p.y) != (b.y > p.y) && p.x < (b.x - a.x) * (p.y - a.y) / (b.y - a.y) + a.x {
            inside = !inside;
        }
    }
    inside
}

#[test]
fn inclusion_geofences_of_a_plan_keep_transfers_inside() {
    // An L-shaped inclusion fence (metres): the straight line between the two waypoints, one at
    // the end of each arm, cuts across the missing quarter, outside the fence.
    let fence = [(-10.0, -10.0), (120.0, -10.0), (120.0, 30.0), (30.0, 30.0), (30.0, 120.0), (-10.0, 120.0)];
    let vertices: Vec<String> = fence
        .iter()
        .map(|&(x, y)| {
            let [lat, lon] = latlon(x, y);
            format!("[{lat:.9}, {lon:.9}]")
        })
        .collect();
    let item = |x: f64, y: f64| {
        let [lat, lon] = latlon(x, y);
        format!(
            r#"{{"type": "SimpleItem", "command": 16, "frame": 3, "params": [0, 0, 0, null, {lat:.9}, {lon:.9}, 60]}}"#
        )
    };
    let plan = |items: &[String]| {
        format!(
            r#"{{"fileType": "Plan", "version": 1,
              "geoFence": {{"version": 2, "circles": [], "polygons": [{{"inclusion": true, "version": 1, "polygon": [{}]}}]}},
              "mission": {{"version": 2, "plannedHomePosition": [39.9526, -75.1652, 0], "items": [{}]}}}}"#,
            vertices.join(", "),
            items.join(", ")
        )
    };
    let dir = temp_dir("inclusion");
    std::fs::write(dir.join("inside.plan"), plan(&[item(100.0, 10.0), item(10.0, 100.0)])).unwrap();
    let yaml = r#"
mission: inclusion
team:
  - { id: uav1, kind: uav, role: explorer, start: { x_m: 0, y_m: 0 } }
roles:
  explorer:
    blackboard: { next: 0 }
    tree: { follow_waypoints: { plan_file: inside.plan, speed_mps: 8, progress: "{next}" } }
time_limit_s: 100
"#;
    let ex = build(&dir, yaml, "explorer", "uav1", Pose2::default());
    let mut uav = Uav::new(ex, Point2::new(0.0, 0.0));
    let status = uav.run(3000);
    assert_eq!(status, Status::Success, "{:?}", uav.reports());
    let poly: Vec<Point2> = fence.iter().map(|&(x, y)| Point2::new(x, y)).collect();
    assert!(uav.track.iter().all(|p| in_polygon(&poly, *p)), "the UAV left the inclusion fence");
    assert!(close(uav.pos, Point2::new(10.0, 100.0), 2.1), "{:?}", uav.pos);
    // It turned at the inner corner, pushed inward by the 5 m margin, instead of cutting across.
    assert!(uav.targets.iter().any(|t| t.x < 30.0 && t.y < 30.0 && t.x > 20.0 && t.y > 20.0), "{:?}", uav.targets);
    let flown: f64 = uav.track.windows(2).map(|w| w[0].distance(w[1])).sum();
    let straight = Point2::new(0.0, 0.0).distance(Point2::new(100.0, 10.0))
        + Point2::new(100.0, 10.0).distance(Point2::new(10.0, 100.0));
    assert!(flown > straight + 5.0 && flown < straight + 40.0, "{flown} vs {straight}");

    // A UAV that takes off outside the fence flies straight in, then stays inside.
    let ex = build(&dir, yaml, "explorer", "uav1", Pose2::new(60.0, 60.0, 0.0));
    let mut uav = Uav::new(ex, Point2::new(60.0, 60.0));
    assert_eq!(uav.run(3000), Status::Success, "{:?}", uav.reports());
    let first_inside = uav.track.iter().position(|p| in_polygon(&poly, *p)).unwrap();
    assert!(uav.track[first_inside..].iter().all(|p| in_polygon(&poly, *p)), "left the fence after entering it");
    assert!(close(uav.pos, Point2::new(10.0, 100.0), 2.1), "{:?}", uav.pos);

    // A waypoint outside the fence is refused when the mission is built, naming it.
    let outside = dir.join("outside.plan");
    std::fs::write(&outside, plan(&[item(100.0, 10.0), item(60.0, 60.0)])).unwrap();
    let err = follow_node(&[plan_port(&outside)]).err().unwrap();
    assert!(
        err.contains("outside.plan") && err.contains("waypoint 1") && err.contains("outside the inclusion geofence"),
        "{err}"
    );

    // The same fence written in the mission: `no_fly.inside`.
    let inside_param = serde_json::json!({
        "inside": [fence.iter().map(|&(x, y)| serde_json::json!({"x": x, "y": y})).collect::<Vec<_>>()],
    });
    let err = follow_node(&[
        ("waypoints", BbValue::Points(Arc::new(vec![Point2::new(60.0, 60.0)]))),
        ("no_fly", BbValue::Params(Arc::new(inside_param.clone()))),
    ])
    .err()
    .unwrap();
    assert!(err.contains("waypoint 0") && err.contains("outside the inclusion geofence"), "{err}");
    assert!(
        follow_node(&[
            ("waypoints", BbValue::Points(Arc::new(vec![Point2::new(10.0, 100.0)]))),
            ("no_fly", BbValue::Params(Arc::new(inside_param))),
        ])
        .is_ok()
    );
}

// ------------------------------------------------------------------------ seek_robot

const SEEKER: &str = r#"
mission: seeker
team:
  - { id: uav1, kind: uav, role: seeker, start: { x_m: 0, y_m: 0 } }
roles:
  seeker:
    tree:
      repeat:
        child:
          sequence:
            - seek_robot: { stale_after_s: 30, arrive_radius_m: 5, speed_mps: 10, target: "{target}" }
            - wait: { duration_s: 1 }
time_limit_s: 1000
"#;

/// Everything `from` holds, copied into `to` (a one-way radio burst; acknowledgements dropped).
fn tell(from: &mut DrivenRuntime, to: &mut DrivenRuntime) {
    let to_id = to.id().clone();
    if let Some(m) = from.team_state_mut().make_sync(&to_id, TierSet::ALL, usize::MAX) {
        to.team_state_mut().apply(from.id(), &m).unwrap();
    }
}

/// A full two-way exchange, as robots in radio contact do.
fn exchange(a: &mut DrivenRuntime, b: &mut DrivenRuntime) {
    for _ in 0..3 {
        tell(a, b);
        tell(b, a);
    }
}

#[test]
fn seek_robot_rotates_round_robin_and_flies_to_the_path_end_of_a_stale_robot() {
    let ex = build(&temp_dir("seek"), SEEKER, "seeker", "uav1", Pose2::default());
    let mut uav = Uav::new(ex, Point2::new(0.0, 0.0));
    let t0 = Time::from_secs_f64(40.0);
    let mut base = runtime("base", RobotKind::Basestation, 0, Pose2::default());
    let mut ugv1 = runtime("ugv1", RobotKind::Ugv, 1, Pose2::default());
    let mut ugv2 = runtime("ugv2", RobotKind::Ugv, 2, Pose2::default());
    fix(&mut base, Point2::new(-50.0, 0.0), t0);
    fix(&mut ugv1, Point2::new(100.0, 0.0), t0);
    // ugv2 was last heard at t = 0, heading to (0, 200): at t0 its pose is stale.
    fix(&mut ugv2, Point2::new(0.0, 100.0), Time::ZERO);
    ugv2.team_state_mut().set_path_end(Some(Point2::new(0.0, 200.0))).unwrap();
    for r in [&mut base, &mut ugv1, &mut ugv2] {
        tell(r, &mut uav.rt);
    }

    let mut picks: Vec<String> = Vec::new();
    let mut moved_ugv1 = false;
    let start = 400; // steps: t0 = 40 s
    for n in start..start + 1500 {
        let t = at(n);
        // Halfway to ugv1, news arrives (relayed): it moved to (120, 10).
        if !moved_ugv1 && uav.robot("target").as_deref() == Some("ugv1") && uav.pos.x > 40.0 {
            fix(&mut ugv1, Point2::new(120.0, 10.0), t);
            tell(&mut ugv1, &mut uav.rt);
            moved_ugv1 = true;
        }
        assert_eq!(uav.step(t), Status::Running, "{:?}", uav.reports());
        if let Some(r) = uav.robot("target")
            && picks.last() != Some(&r)
        {
            picks.push(r);
        }
        if picks.len() >= 5 {
            break;
        }
    }
    // Round-robin in id order, then again from the start.
    assert_eq!(picks, ["base", "ugv1", "ugv2", "base", "ugv1"]);
    // Targets: base's pose, ugv1's pose, then its newer pose, ugv2's path end (not its stale
    // pose), base again.
    let t = &uav.targets;
    assert!(close(t[0], Point2::new(-50.0, 0.0), 1e-9), "{t:?}");
    assert!(close(t[1], Point2::new(100.0, 0.0), 1e-9), "{t:?}");
    assert!(close(t[2], Point2::new(120.0, 10.0), 1e-9), "re-targeted on the newer pose: {t:?}");
    assert!(close(t[3], Point2::new(0.0, 200.0), 1e-9), "stale pose: fly to the path end: {t:?}");
    assert!(!t.iter().any(|p| close(*p, Point2::new(0.0, 100.0), 1e-9)), "{t:?}");
    assert!(close(t[4], Point2::new(-50.0, 0.0), 1e-9), "{t:?}");

    // With ugv2's pose fresh, its pose is sought instead of its path end.
    let mut uav2 = Uav::new(build(&temp_dir("seek2"), SEEKER, "seeker", "uav1", Pose2::default()), Point2::default());
    fix(&mut ugv2, Point2::new(0.0, 100.0), t0);
    tell(&mut ugv2, &mut uav2.rt);
    uav2.step(t0);
    assert_eq!(uav2.targets, vec![Point2::new(0.0, 100.0)]);
}

#[test]
fn seek_robot_fails_when_no_robot_is_known() {
    let ex = build(&temp_dir("seek-none"), SEEKER, "seeker", "uav1", Pose2::default());
    let mut uav = Uav::new(ex, Point2::new(0.0, 0.0));
    assert_eq!(uav.step(Time::ZERO), Status::Failure);
    let reports = uav.reports();
    assert!(reports.iter().any(|r| r.contains("no robot to seek")), "{reports:?}");
    assert!(uav.rt.flight().is_none());
}

// ------------------------------------------------------------------------ wait_for_sync

const WAITER: &str = r#"
mission: waiter
team:
  - { id: uav1, kind: uav, role: waiter, start: { x_m: 0, y_m: 0 } }
roles:
  waiter:
    tree: { wait_for_sync: { robot: ugv1, timeout_s: 10, track: true } }
time_limit_s: 1000
"#;

#[test]
fn wait_for_sync_needs_a_full_exchange_during_the_wait_and_times_out_otherwise() {
    let ex = build(&temp_dir("wait"), WAITER, "waiter", "uav1", Pose2::default());
    let mut uav = Uav::new(ex, Point2::new(0.0, 0.0));
    let mut ugv = runtime("ugv1", RobotKind::Ugv, 1, Pose2::default());
    let ugv_at = Point2::new(20.0, 5.0);
    // Some team data on both sides, as in a mission.
    ugv.team_state_mut().add_mission_goal(0, Point2::new(60.0, 60.0)).unwrap();
    fix(&mut ugv, ugv_at, Time::ZERO);

    // Nothing heard yet: hover (no command), not complete.
    assert_eq!(uav.step(at(0)), Status::Running);
    assert!(uav.rt.flight().is_none());
    // One way only: the UAV hears ugv1 (and tracks it) but ugv1 has not confirmed anything.
    tell(&mut ugv, &mut uav.rt);
    assert_eq!(uav.step(at(1)), Status::Running);
    assert_eq!(uav.rt.flight().map(|f| f.target), Some(ugv_at), "tracks the robot's pose");
    // A full exchange: complete.
    exchange(&mut uav.rt, &mut ugv);
    assert!(uav.rt.team().sync_complete_with(ugv.id()));
    assert_eq!(uav.step(at(2)), Status::Success);

    // A new wait later: the team state still reports the old sync complete, but nothing was
    // exchanged since the wait began, so it does not count — the wait times out after 10 s.
    let begin = 100;
    let mut n = begin;
    let status = loop {
        let s = uav.step(at(n));
        assert!(uav.rt.team().sync_complete_with(ugv.id()), "the stale completion is still reported");
        if s != Status::Running {
            break s;
        }
        n += 1;
    };
    assert_eq!(status, Status::Failure);
    assert_eq!(n - begin, 100, "10 s timeout at 10 Hz");

    // A third wait, with a fresh exchange during it: success.
    let begin = 300;
    assert_eq!(uav.step(at(begin)), Status::Running);
    fix(&mut ugv, Point2::new(25.0, 5.0), at(begin + 5));
    exchange(&mut uav.rt, &mut ugv);
    assert_eq!(uav.step(at(begin + 6)), Status::Success);
}

#[test]
fn wait_for_sync_without_tracking_hovers() {
    let yaml = WAITER.replace("track: true", "track: false");
    let ex = build(&temp_dir("wait-hover"), &yaml, "waiter", "uav1", Pose2::default());
    let mut uav = Uav::new(ex, Point2::new(0.0, 0.0));
    let mut ugv = runtime("ugv1", RobotKind::Ugv, 1, Pose2::default());
    fix(&mut ugv, Point2::new(20.0, 5.0), Time::ZERO);
    tell(&mut ugv, &mut uav.rt);
    for n in 0..20 {
        assert_eq!(uav.step(at(n)), Status::Running);
        assert!(uav.rt.flight().is_none());
    }
    assert_eq!(uav.pos, Point2::new(0.0, 0.0));
}
