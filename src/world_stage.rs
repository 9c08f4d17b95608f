//! The world stage of `spomp validate` (parse → schema → wiring → team → world),
//! for a mission that names a world folder (`sim: { world: { dir: … } } }`): the world loads;
//! every robot's start pose is in it and, for a UGV, on ground it can use; a detection mission's
//! world holds clusters of the goal class; the points a mission gives (manual goals, literal
//! waypoints and targets, the waypoints of its QGroundControl plans) lie in it.
//!
//! Errors (the mission cannot run as written): the world does not load; a start pose is off the
//! map, or a UGV's is on an impassable class or where the simulator's UGV cannot stand; the
//! detected class, or every ground class a cross-view robot localizes on, is not in the world's
//! class table (after the mission's `classes:` mapping, which must name the table's classes).
//! Warnings (it runs, but probably not as meant): some of a localizer's ground classes or
//! weighted classes are not in the table (they are left out); the world has no cluster of the
//! goal class the detector would find, so a mission that ends when all goals are visited never
//! completes; a point the mission names lies outside the world. Generated worlds (`generate:`) are left to `--dry-run`: they exist only per seed.
//!
//! The stage lives in the command line, not in the mission language, because loading a world is
//! the simulator's business and the language stays below the adapters.

use std::path::PathBuf;

use spomp_behaviors::BbValue;
use spomp_behaviors::mission::MissionSection;
use spomp_behaviors::mission::compile::{Ir, IrBinding, IrKind};
use spomp_behaviors::mission::limits::resolve_inside;
use spomp_behaviors::mission::schema::CompleteWhen;
use spomp_behaviors::mission::yaml::{self, Loc, Node};
use spomp_behaviors::mission::{Diagnostic, LoadOptions, LoadedMission, Stage};
use spomp_core::classes::IMPASSABLE_RANK;
use spomp_core::{Point2, Pose2, RobotKind};
use spomp_robot::class_names::ClassNames;
use spomp_world::{SimSpec, UgvLimits, World, WorldSpec};

/// One step of a path into the mission's YAML: a mapping key or a list index.
enum Step<'a> {
    Key(&'a str),
    Index(usize),
}

/// The location of the node at `path` in the mission's YAML, or of the deepest node on the way
/// that exists (the whole file when the text does not parse).
fn locate(root: Option<&Node>, path: &[Step<'_>]) -> Loc {
    let Some(mut node) = root else { return Loc { line: 1, column: 1, offset: None, len: 0 } };
    for step in path {
        let next = match step {
            Step::Key(k) => node.get(k),
            Step::Index(i) => node.as_seq().and_then(|s| s.get(*i)),
        };
        match next {
            Some(n) => node = n,
            None => break,
        }
    }
    node.loc
}

/// A step of a field path as [`ClassNote`](spomp_robot::class_names::ClassNote)s write them.
enum OwnedStep {
    Key(String),
    Index(usize),
}

impl OwnedStep {
    fn as_step(&self) -> Step<'_> {
        match self {
            OwnedStep::Key(k) => Step::Key(k),
            OwnedStep::Index(i) => Step::Index(*i),
        }
    }
}

/// `team[1].localization.ground_classes` as steps into the YAML.
fn field_steps(field: &str) -> Vec<OwnedStep> {
    let mut steps = Vec::new();
    for part in field.split('.') {
        let (key, rest) = part.split_once('[').unwrap_or((part, ""));
        steps.push(OwnedStep::Key(key.to_string()));
        for index in rest.split('[') {
            if let Ok(i) = index.trim_end_matches(']').parse() {
                steps.push(OwnedStep::Index(i));
            }
        }
    }
    steps
}

/// Runs the world stage on a mission that passed the earlier stages; returns its diagnostics
/// (none for a mission without a world folder).
pub fn check(loaded: &LoadedMission, options: &LoadOptions) -> Vec<Diagnostic> {
    let Some(mission) = loaded.mission.as_ref().filter(|_| loaded.is_valid()) else { return Vec::new() };
    let Ok(SimSpec { world: Some(WorldSpec::Dir(dir)), .. }) = SimSpec::of_mission(mission) else { return Vec::new() };
    let Some(file) = loaded.files.first().cloned() else { return Vec::new() };
    let root = loaded.sources.first().and_then(|text| yaml::parse(text).ok());
    let at = |path: &[Step<'_>], node_path: &str, message: String| {
        Diagnostic::new(&file, locate(root.as_ref(), path), node_path, Stage::World, message)
    };
    let mut out = Vec::new();

    let base = loaded.base_dir();
    let roots: Vec<PathBuf> = std::iter::once(base.clone()).chain(options.allowed_dirs.iter().cloned()).collect();
    let world_path = [Step::Key("sim"), Step::Key("world"), Step::Key("dir")];
    let world = match resolve_inside(&roots, &base, &dir).map_err(|e| e.to_string()).and_then(|p| {
        if p.is_dir() {
            World::load(&p).map_err(|e| e.to_string())
        } else {
            Err(format!("`{}` is not a world folder (no such directory)", p.display()))
        }
    }) {
        Ok(w) => w,
        Err(e) => {
            out.push(at(&world_path, "sim.world.dir", format!("the world does not load: {e}")));
            return out;
        }
    };
    let spec = *world.spec();
    let (w_m, h_m) = spec.size_m();
    let bounds = format!(
        "the world spans x {:.1}…{:.1} m, y {:.1}…{:.1} m",
        spec.origin.x,
        spec.origin.x + w_m,
        spec.origin.y,
        spec.origin.y + h_m
    );

    // Start poses.
    for (i, robot) in mission.team.iter().enumerate() {
        let path = [Step::Key("team"), Step::Index(i), Step::Key("start")];
        let node_path = format!("team[{i}].start");
        let pose = Pose2::new(robot.start.x_m, robot.start.y_m, robot.start.yaw_deg.to_radians());
        let Some(class) = world.class_at(pose.position()) else {
            out.push(at(
                &path,
                &node_path,
                format!("robot `{}` starts at ({}, {}), outside the world: {bounds}", robot.id, pose.x, pose.y),
            ));
            continue;
        };
        if robot.kind != RobotKind::Ugv {
            continue; // a UAV flies and a basestation stands anywhere in the world
        }
        let classes = world.classes();
        let name = classes.get(class).map_or("?", |c| c.name.as_str());
        if classes.rank(class) >= IMPASSABLE_RANK {
            let drivable: Vec<&str> =
                classes.classes.iter().filter(|c| c.rank < IMPASSABLE_RANK).map(|c| c.name.as_str()).collect();
            out.push(at(
                &path,
                &node_path,
                format!(
                    "UGV `{}` starts at ({}, {}) on `{name}`, which is impassable (rank {}); a UGV must start on {}",
                    robot.id,
                    pose.x,
                    pose.y,
                    classes.rank(class),
                    drivable.join(", ")
                ),
            ));
        } else if let Some(ground) = ground_classes(mission, i, world.classes())
            && !ground.iter().any(|g| g == name)
        {
            // On a parked car or inside vegetation: the robot cannot localize there and, on a
            // real site, would not start there at all.
            out.push(at(
                &path,
                &node_path,
                format!(
                    "UGV `{}` starts at ({}, {}) on `{name}`, which is not ground (a UGV starts on one of its ground \
                     classes: {})",
                    robot.id,
                    pose.x,
                    pose.y,
                    ground.join(", ")
                ),
            ));
        } else if let Err(e) = UgvLimits::default().stand_at(&world, pose.position()) {
            // Worded as the simulator refuses the same start.
            out.push(at(
                &path,
                &node_path,
                format!(
                    "UGV `{}` cannot stand at ({}, {}) on `{name}`: invalid UGV start pose: {e}",
                    robot.id, pose.x, pose.y
                ),
            ));
        }
    }

    // Class names the robots' skills use, as the world's table spells them.
    let names = ClassNames::new(mission, world.classes());
    let mut notes = names.mapping_notes();
    for i in 0..mission.team.len() {
        for note in names.robot(mission, i).1 {
            if !notes.contains(&note) {
                notes.push(note);
            }
        }
    }
    for note in notes {
        let steps = field_steps(&note.field);
        let steps: Vec<Step<'_>> = steps.iter().map(|s| s.as_step()).collect();
        let diagnostic = at(&steps, &note.field, note.message);
        out.push(if note.error { diagnostic } else { diagnostic.into_warning() });
    }

    // Goals the world can offer.
    if let Some(goals) = &mission.goals {
        if let Some(detect) = &goals.detect {
            let path = [Step::Key("goals"), Step::Key("detect")];
            // A class the table lacks is a class note above.
            if let Some(class) = names.resolve(&detect.class).and_then(|n| world.classes().by_name(&n)) {
                let never = if mission.complete_when == CompleteWhen::AllGoalsVisited && goals.manual.is_empty() {
                    "; the mission ends when all goals are visited, so it can never complete"
                } else {
                    ""
                };
                let cells = world.count_class(class.index);
                if cells == 0 {
                    out.push(
                        at(
                            &path,
                            "goals.detect.class",
                            format!("the world has no `{}` cells: detection will find no goal{never}", detect.class),
                        )
                        .into_warning(),
                    );
                } else if detectable_clusters(&world, detect, &class.name) == Some(0) {
                    out.push(
                        at(
                            &path,
                            "goals.detect",
                            format!(
                                "the world has {cells} `{}` cells but no cluster the detector accepts (minimum \
                                 size, placement region): detection will find no goal{never}",
                                detect.class
                            ),
                        )
                        .into_warning(),
                    );
                }
            }
        }
        for (i, g) in goals.manual.iter().enumerate() {
            if world.class_at(Point2::new(g.x_m, g.y_m)).is_none() {
                out.push(
                    at(
                        &[Step::Key("goals"), Step::Key("manual"), Step::Index(i)],
                        &format!("goals.manual[{i}]"),
                        format!("goal ({}, {}) lies outside the world: {bounds}", g.x_m, g.y_m),
                    )
                    .into_warning(),
                );
            }
        }
    }

    // Points the trees are given: literal targets and waypoints, and QGroundControl plans.
    for role in loaded.roles.values() {
        let mut leaves = Vec::new();
        collect_leaves(&role.tree, &mut leaves);
        for ir in leaves {
            let IrKind::Leaf { ports } = &ir.kind else { continue };
            let ir_file = loaded.files.get(ir.file).cloned().unwrap_or_else(|| file.clone());
            for port in ports {
                let IrBinding::Literal(value) = &port.binding else { continue };
                let points: Vec<Point2> = match value {
                    BbValue::Point(p) => vec![*p],
                    BbValue::Points(ps) => ps.to_vec(),
                    BbValue::Str(plan) if port.spec.name.as_ref() == "plan_file" => {
                        // Read and placed as the node reads it over this world; a plan that
                        // does not parse is the build's error to report, not this stage's.
                        spomp_robot::nodes::plan_waypoints(&base.join(&**plan), world.meta.gps_origin)
                            .unwrap_or_default()
                    }
                    _ => continue,
                };
                let outside: Vec<(usize, Point2)> =
                    points.iter().copied().enumerate().filter(|(_, p)| world.class_at(*p).is_none()).collect();
                if let Some(&(first, p)) = outside.first() {
                    let plan = port.spec.name.as_ref() == "plan_file";
                    let what = if plan { "waypoint of the plan" } else { "point" };
                    // A plan is the operator's flight: one that leaves the map is an error
                    // (the UAV would survey nothing there). Literal points may be transit.
                    let placed = match (plan, world.meta.gps_origin) {
                        (false, _) => String::new(),
                        (true, Some(o)) => format!(
                            " (placed by their coordinates: the world's origin is at {:.7}, {:.7})",
                            o.latitude_deg, o.longitude_deg
                        ),
                        (true, None) => " (placed around the plan's home: the world has no GPS reference; import \
                                         it with --gps-reference to place plans by their coordinates)"
                            .to_string(),
                    };
                    let message = format!(
                        "{} of {} `{}` points lie outside the world{placed} (first: {what} {first} at ({:.1}, \
                         {:.1})): {bounds}",
                        outside.len(),
                        points.len(),
                        port.spec.name,
                        p.x,
                        p.y
                    );
                    let d = Diagnostic::new(&ir_file, port.loc, &ir.path, Stage::World, message);
                    out.push(if plan { d } else { d.into_warning() });
                }
            }
        }
    }
    out
}

/// The ground classes of UGV `index` as the world's table spells them: its localizer's (the
/// mission's `localization.ground_classes`, else the localizer's defaults), whatever its
/// localization mode; `None` when none resolves (a class note reports that).
fn ground_classes(
    mission: &spomp_behaviors::mission::MissionFile,
    index: usize,
    table: &spomp_core::ClassTable,
) -> Option<Vec<String>> {
    let ground = ClassNames::new(mission, table).ground_classes(mission, index);
    (!ground.is_empty()).then_some(ground)
}

/// Every leaf of a compiled tree.
fn collect_leaves<'a>(ir: &'a Ir, out: &mut Vec<&'a Ir>) {
    match &ir.kind {
        IrKind::Leaf { .. } => out.push(ir),
        IrKind::Control { children, .. } => children.iter().for_each(|c| collect_leaves(c, out)),
        IrKind::Decorator { child, .. } => collect_leaves(child, out),
        IrKind::StateMachine { states, .. } => {
            states.iter().filter_map(|s| s.run.as_ref()).for_each(|r| collect_leaves(r, out));
        }
    }
}

/// How many clusters the goal detector finds in the whole world with the mission's settings;
/// `None` when the detector cannot be set up (its settings are checked by the team stage).
fn detectable_clusters(
    world: &World,
    detect: &spomp_behaviors::mission::schema::DetectSpec,
    class: &str,
) -> Option<usize> {
    let defaults = spomp_mapping::GoalDetectionParams::default();
    let params = spomp_mapping::GoalDetectionParams {
        class: class.to_string(),
        merge_distance_m: detect.merge_distance_m.unwrap_or(defaults.merge_distance_m),
        min_size_m: detect.min_size_m.unwrap_or(defaults.min_size_m),
        placement_region_m: detect.placement_region_m.unwrap_or(defaults.placement_region_m),
        ..defaults
    };
    let mut detector = spomp_mapping::GoalDetector::new(params, world.classes()).ok()?;
    detector.detect(world.aerial_map(), &[]).ok().map(|d| d.goals.len())
}
