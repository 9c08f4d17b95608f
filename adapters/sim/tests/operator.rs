//! The operator in the loop (issue 37), whole missions in the simulator: `sim.operator`
//! commands issued by the operator member at the basestation, reaching the UGVs over the
//! modelled radio.
//! - a goal added mid-mission is claimed and visited (before an ordinary goal: it is urgent);
//! - a cancel while a UGV holds the claim releases it as soon as the UGV hears it (the same
//!   sync round), and the goal is never claimed or visited after;
//! - a hold stops every UGV from the tick that sees it (a zero command), and after the resume
//!   they drive on;
//! - a recall brings the UGV home, where it stays;
//! - a UGV out of range (a radio blackout) when the recall is issued applies it when the radio
//!   comes back, not before.

#![allow(clippy::unwrap_used, clippy::expect_used)] // tests fail loudly by design

mod common;

use std::path::Path;

use common::{load, simulation, write_mission};

use spomp_core::{GoalId, RobotId, Time};
use spomp_sim::run::{NoObserver, SimOptions, Simulation};
use spomp_teamstate::OperatorMode;

/// Two UGVs and a basestation in a small city with a prior map; three mission goals, the
/// `far` one claimed first by ugv1 and a long drive away; `SCRIPT` and `FAULTS` replaced.
const MISSION: &str = r#"
mission: operator-test
include: [OPERATOR, GOAL_CYCLE]
team:
  - { id: base, kind: basestation, role: base, start: { x_m: 5, y_m: 5 } }
  - { id: ugv1, kind: ugv, role: visitor, priority: 1, start: { x_m: 12, y_m: 2.5 }, localization: { mode: ground_truth, noise_m: 0.1 } }
  - { id: ugv2, kind: ugv, role: visitor, priority: 2, start: { x_m: 12, y_m: 7.5 }, localization: { mode: ground_truth, noise_m: 0.1 } }
goals:
  manual:
    - { x_m: 70, y_m: 40, name: near }
    - { x_m: 40, y_m: 110, name: far }
    - { x_m: 135, y_m: 78, name: depot }
  deconfliction_radius_m: 10
  time_limit_per_m_s: 3.0
roles:
  visitor:
    navigation: { profile: simulation }
    tree:
      reactive_fallback:
        - subtree: obey_hold
        - subtree: obey_recall_ugv
        - repeat:
            child:
              fallback:
                - subtree: claim_and_visit
                - subtree: nothing_left
                - succeed:
  base:
    tree: { wait: { duration_s: 1e9 } }
complete_when: time_limit
time_limit_s: TIME_LIMIT
comms: { position_range_m: 1000, data_range_m: 1000, bandwidth_bytes_per_s: 1000000 }
sim:
  world: { generate: { size_m: [400, 300], vehicle_clusters: 0, roadblocks: 2 } }
  prior_map: true
  faults: FAULTS
  operator: SCRIPT
"#;

fn mission(name: &str, time_limit_s: u32, script: &str, faults: &str) -> spomp_behaviors::mission::LoadedMission {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../missions/subtrees");
    let text = MISSION
        .replace("OPERATOR", &format!("\"{}\"", root.join("operator.yaml").display()))
        .replace("GOAL_CYCLE", &format!("\"{}\"", root.join("goal-cycle.yaml").display()))
        .replace("TIME_LIMIT", &time_limit_s.to_string())
        .replace("SCRIPT", script)
        .replace("FAULTS", faults);
    load(&write_mission(name, &text))
}

fn options() -> SimOptions {
    SimOptions { seed: 1, ..SimOptions::default() }
}

fn mission_goal(k: u32) -> GoalId {
    GoalId { origin: RobotId::new("mission"), seq: k }
}

fn holds(sim: &Simulation, robot: &str, goal: &GoalId) -> bool {
    sim.robot(robot).unwrap().team().goal(goal).is_some_and(|v| v.is_held_by(&RobotId::new(robot)))
}

#[test]
fn goals_added_cancelled_and_a_hold_are_applied_by_the_ugvs() {
    let script = "[{ at_s: 40, goal_cancel: { goal: far } }, { at_s: 150, hold: all }, { at_s: 170, resume: all }, \
                  { at_s: 300, goal_add: { at: [40, 150], priority: 1, name: casualty } }]";
    let loaded = mission("ops-a", 900, script, "[]");
    let mut sim = simulation(&loaded, options());
    let far = mission_goal(1);
    let (ugv1, ugv2) = (RobotId::new("ugv1"), RobotId::new("ugv2"));
    let mut claimed_far_before_cancel = false;
    let mut cancel_heard: Option<Time> = None;
    let mut hold_seen: [Option<Time>; 2] = [None, None];
    let mut moved_during_hold = [0.0f64; 2];
    let mut hold_start = [None, None];
    while sim.outcome().is_none() {
        sim.step(&mut NoObserver);
        let now = sim.now();
        let t = now.as_secs_f64();
        if t < 40.0 && (holds(&sim, "ugv1", &far) || holds(&sim, "ugv2", &far)) {
            claimed_far_before_cancel = true;
        }
        for (k, id) in [&ugv1, &ugv2].into_iter().enumerate() {
            let view = sim.robot(id.as_str()).unwrap();
            let cancelled = view.team().goal(&far).is_some_and(|v| v.cancelled.is_some());
            if cancelled && cancel_heard.is_none() && k == 0 {
                cancel_heard = Some(now);
            }
            // Heard the cancel: released in the same step, never claimed again.
            if cancelled {
                assert!(!holds(&sim, id.as_str(), &far), "{id} holds the cancelled goal at {t:.1} s");
            }
            // The hold: the command output is zero from the tick the robot sees it.
            if view.team().operator_mode(id).mode == OperatorMode::Hold && hold_seen[k].is_none() {
                hold_seen[k] = Some(now);
            }
            if let Some(seen) = hold_seen[k]
                && t < 170.0
                && now.secs_since(seen) >= 0.1
            {
                assert!(view.command().is_none(), "{id} commands {:?} while held at {t:.1} s", view.command());
                let here = sim.true_pose(id.as_str()).unwrap().position();
                // The body coasts for a moment after the zero command; measured from 1 s on.
                if now.secs_since(seen) >= 1.0 {
                    let start = *hold_start[k].get_or_insert(here);
                    moved_during_hold[k] = moved_during_hold[k].max(start.distance(here));
                }
            }
        }
    }
    let result = sim.run(&mut NoObserver);
    let s = &result.summary;
    assert!(claimed_far_before_cancel, "the far goal was claimed before the cancel");
    let heard = cancel_heard.expect("ugv1 heard the cancel").as_secs_f64();
    assert!((40.0..41.0).contains(&heard), "the cancel reached ugv1 within a sync round: {heard}");
    let far_summary = s.goals.iter().find(|g| g.id == "mission/1").unwrap();
    assert!(far_summary.visited_s.is_none(), "the cancelled goal was visited: {far_summary:?}");
    for k in 0..2 {
        let seen = hold_seen[k].expect("the hold reached both UGVs").as_secs_f64();
        assert!((150.0..151.0).contains(&seen), "hold heard at {seen}");
        assert!(moved_during_hold[k] < 0.05, "UGV {k} moved {} m while held", moved_during_hold[k]);
    }
    // The added goal: claimed and visited.
    let added = s.goals.iter().find(|g| g.id == "operator/4").unwrap_or_else(|| panic!("{:#?}", s.goals));
    assert!(added.claimed_s.is_some_and(|c| c >= 300.0), "{added:?}");
    assert!(added.visited_s.is_some(), "the operator's goal was not visited: {added:?}");
    // Every command acknowledged by both UGVs, and shown in the summary.
    assert_eq!(s.operator.len(), 4, "{:#?}", s.operator);
    for c in &s.operator {
        let who: Vec<&str> = c.acked_by.iter().map(|(r, _)| r.as_str()).collect();
        assert!(who.contains(&"ugv1") && who.contains(&"ugv2"), "{c:?}");
    }
}

#[test]
fn a_recall_out_of_range_is_applied_when_the_radio_comes_back_and_the_ugv_goes_home() {
    let script = "[{ at_s: 120, recall: ugv2 }]";
    let faults = "[{ blackout: { from_s: 100, to_s: 200 } }]";
    let loaded = mission("ops-b", 600, script, faults);
    let mut sim = simulation(&loaded, options());
    let ugv2 = RobotId::new("ugv2");
    let mut applied: Option<f64> = None;
    while sim.outcome().is_none() {
        sim.step(&mut NoObserver);
        let t = sim.now().as_secs_f64();
        let mode = sim.robot("ugv2").unwrap().team().operator_mode(&ugv2).mode;
        if mode == OperatorMode::Recall && applied.is_none() {
            applied = Some(t);
        }
        if t < 200.0 {
            assert_eq!(mode, OperatorMode::Mission, "ugv2 heard the recall during the blackout ({t:.1} s)");
        }
    }
    let applied = applied.expect("the recall reached ugv2 after the blackout");
    assert!((200.0..201.0).contains(&applied), "applied at {applied} s");
    let home = sim.true_pose("ugv2").unwrap().position();
    let start = spomp_core::Point2::new(12.0, 7.5);
    assert!(home.distance(start) < 3.0, "ugv2 ended at {home:?}, home is {start:?}");
    let result = sim.run(&mut NoObserver);
    let recall = &result.summary.operator[0];
    assert!(recall.acked_by.iter().any(|(r, at)| r == "ugv2" && *at >= 200.0), "{recall:?}");
    // ugv2 held no claim after the recall: its goals went to ugv1.
    assert!(
        result.summary.goals.iter().all(|g| g.visited_by.as_deref() != Some("ugv2") || g.visited_s < Some(applied))
    );
}
