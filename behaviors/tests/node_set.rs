//! The fixture mission that uses every node type added for BT.CPP users
//! (`tests/missions/valid-engine-node-set.yaml`), ticked at 10 Hz with the engine's registry:
//! each part runs when the mission says it does.

#![allow(clippy::unwrap_used, clippy::expect_used)] // tests fail loudly by design

use std::path::Path;

use spomp_behaviors::mission::{BuildOptions, build_executor, load_mission};
use spomp_behaviors::trace::Recorder;
use spomp_behaviors::{Status, engine_registry};
use spomp_core::{Pose2, RobotId, Time};

#[test]
fn the_node_set_fixture_runs_as_written() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../tests/missions/valid-engine-node-set.yaml");
    let registry = engine_registry::<()>();
    let loaded = load_mission(&path, &registry);
    assert!(loaded.diagnostics.is_empty(), "{:#?}", loaded.diagnostics);
    let mut ex = build_executor(
        &loaded.roles["base"],
        &registry,
        &RobotId::new("base"),
        Pose2::default(),
        BuildOptions::default(),
    )
    .unwrap();
    let mut rec = Recorder::default();
    let mut end = None;
    for i in 0..100 {
        let now = Time::from_millis(100 * i);
        if ex.tick(now, &mut (), Some(&mut rec)) != Status::Running {
            end = Some((now, ex.status()));
            break;
        }
    }
    // 1 s wait, 1 s wait, re-checks until 3 s, else-branch until 5 s.
    assert_eq!(end, Some((Time::from_millis(5000), Status::Success)));
    let when = |suffix: &str, to: Status| {
        rec.records.iter().filter(|r| r.path.ends_with(suffix) && r.to == to).map(|r| r.time).collect::<Vec<_>>()
    };
    // The else-branch wait started at 3 s and was halted (running → idle) when the condition
    // turned at 5 s, the same tick the do-branch succeeded.
    assert_eq!(when("while_do_else[2]/wait", Status::Running), vec![Time::from_millis(3000)]);
    assert_eq!(when("while_do_else[2]/wait", Status::Idle), vec![Time::from_millis(5000)]);
    assert_eq!(when("while_do_else[1]/succeed", Status::Success), vec![Time::from_millis(5000)]);
    // The if-then-else took its then-branch: the flag was armed by run_once.
    assert_eq!(when("if_then_else[1]/wait", Status::Running), vec![Time::from_millis(1000)]);
    assert!(when("if_then_else[2]/fail", Status::Failure).is_empty());
    assert_eq!(ex.blackboard().get_by_name("armed"), Some(&true.into()));
}
