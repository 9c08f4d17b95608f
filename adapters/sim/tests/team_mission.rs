//! Issue 7's team-mission scenarios in the simulator, on a small version of the shipped mission
//! (`tests/missions/team-small.yaml`: 1 UAV + 3 UGVs + basestation, 200×150 m city with 5
//! vehicle clusters):
//! - baseline: every cluster is visited, and no goal twice by robots that were in contact;
//! - the UGV–UGV radio off: positions and claims flow only through the UAV and basestation, and
//!   the mission still completes (the paper: it degrades gracefully);
//! - a UGV killed while it holds a claim: its claim is a lease, so once the lease runs out
//!   another UGV takes the goal and visits it, and the dead robot's claim never blocks it after.

#![allow(clippy::unwrap_used, clippy::expect_used)] // tests fail loudly by design

mod common;

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

use common::{load, simulation, write_mission};

use spomp_behaviors::mission::LoadedMission;
use spomp_core::{GoalId, RobotId, Time};
use spomp_sim::run::{NoObserver, Outcome, RunSummary, SimOptions, Simulation, SkillLatency};
use spomp_sim::{Faults, KillFault};

/// Trial seed of every scenario (the city is fixed by the mission's `generate.seed`).
const SEED: u64 = 1;

const UGVS: [&str; 3] = ["ugv1", "ugv2", "ugv3"];

fn mission_path() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/missions/team-small.yaml")
}

/// The small team mission with the text edits `(from, to)` applied, written to a temporary
/// folder (its include made absolute) and loaded like any mission file.
fn variant(name: &str, edits: &[(&str, &str)]) -> LoadedMission {
    let mut text = std::fs::read_to_string(mission_path()).unwrap();
    let subtrees = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../missions/subtrees/goal-cycle.yaml");
    let include = "include: [../../../../missions/subtrees/goal-cycle.yaml]";
    assert!(text.contains(include));
    text = text.replace(include, &format!("include: [\"{}\"]", subtrees.display()));
    for (from, to) in edits {
        assert!(text.contains(from), "the mission has no `{from}`");
        text = text.replace(from, to);
    }
    load(&write_mission(name, &text))
}

fn options() -> SimOptions {
    SimOptions { seed: SEED, ..SimOptions::default() }
}

/// Steps until the run ends, calling `every_second` once per simulated second.
fn run_to_end(sim: &mut Simulation, mut every_second: impl FnMut(&Simulation)) {
    let mut next = 0.0;
    while sim.outcome().is_none() {
        sim.step(&mut NoObserver);
        if sim.now().as_secs_f64() >= next {
            next += 1.0;
            every_second(sim);
        }
    }
}

/// Every cluster of the world visited, every goal visited, none twice by robots in contact.
fn assert_complete_without_revisits(s: &RunSummary, scenario: &str) {
    assert_eq!(s.outcome, Outcome::Complete, "{scenario}: {s:#?}");
    assert!(s.end_s < s.time_limit_s, "{scenario}");
    let clusters = s.clusters.expect("a generated world has clusters");
    assert_eq!(clusters.total, 5, "{scenario}");
    assert_eq!(clusters.visited, clusters.total, "{scenario}: {clusters:?}");
    for g in &s.goals {
        assert!(g.visited_s.is_some(), "{scenario}: goal {} not visited", g.id);
        assert!(
            g.visited_by.as_deref().is_some_and(|v| UGVS.contains(&v)),
            "{scenario}: goal {} visited by {:?}",
            g.id,
            g.visited_by
        );
        assert_eq!(g.revisits_in_contact, 0, "{scenario}: goal {} visited twice by robots in contact", g.id);
    }
}

fn visit_times(s: &RunSummary) -> String {
    s.goals
        .iter()
        .map(|g| {
            format!("{} {:.0} s by {}", g.id, g.visited_s.unwrap_or(f64::NAN), g.visited_by.as_deref().unwrap_or("-"))
        })
        .collect::<Vec<_>>()
        .join(", ")
}

#[test]
fn baseline_visits_every_cluster_and_no_goal_twice_in_contact() {
    let loaded = load(&mission_path());
    let summary = simulation(&loaded, options()).run(&mut NoObserver).summary;
    eprintln!("baseline: {:?} at {:.0} s; {}", summary.outcome, summary.end_s, visit_times(&summary));
    assert_complete_without_revisits(&summary, "baseline");
    // The work is shared: more than one UGV visits goals.
    let visitors: BTreeSet<&str> = summary.goals.iter().filter_map(|g| g.visited_by.as_deref()).collect();
    assert!(visitors.len() >= 2, "one UGV did everything: {visitors:?}");
}

#[test]
fn with_the_ugv_radio_off_the_uav_relays_and_the_mission_still_completes() {
    let loaded = variant(
        "radio-off",
        &[("bandwidth_bytes_per_s: 1000000 }", "bandwidth_bytes_per_s: 1000000, ugv_to_ugv: false }")],
    );
    use spomp_behaviors::mission::MissionSection;
    assert_eq!(spomp_robot::CommsSpec::of_mission(loaded.mission.as_ref().unwrap()).unwrap().ugv_to_ugv, Some(false));
    let mut sim = simulation(&loaded, options());
    // Claims of another UGV each UGV learned, without ever hearing that UGV directly.
    let mut learned: BTreeMap<&str, BTreeSet<String>> = BTreeMap::new();
    let mut direct_links = Vec::new();
    run_to_end(&mut sim, |sim| {
        for (i, a) in UGVS.iter().enumerate() {
            for b in &UGVS[i + 1..] {
                if sim.linked(a, b).is_some() {
                    direct_links.push(format!("{a}–{b} at {:.0} s", sim.now().as_secs_f64()));
                }
            }
            let team = &sim.robot(a).unwrap().team();
            for g in team.goals() {
                for c in g.claims.iter().filter(|c| c.robot.as_str() != *a) {
                    learned.entry(a).or_default().insert(c.robot.to_string());
                }
            }
        }
    });
    assert!(direct_links.is_empty(), "UGVs talked directly: {direct_links:?}");
    for ugv in UGVS {
        assert!(
            learned.get(ugv).is_some_and(|others| others.iter().any(|o| UGVS.contains(&o.as_str()))),
            "{ugv} never learned another UGV's claim through the relays: {learned:?}"
        );
    }
    let summary = sim.run(&mut NoObserver).summary;
    eprintln!("radio off between UGVs: {:?} at {:.0} s; {}", summary.outcome, summary.end_s, visit_times(&summary));
    assert_complete_without_revisits(&summary, "radio off");
}

#[test]
fn a_dead_robots_claim_expires_and_another_ugv_visits_its_goal() {
    const LEASE_S: f64 = 60.0;
    let loaded = variant("kill", &[("claim_lease_s: 300", "claim_lease_s: 60")]);
    let dt = options().dt_s;

    // Find, by running, the first moment a UGV renews a claim it holds: killed just after it,
    // its claim stays valid for a whole lease.
    let mut sim = simulation(&loaded, options());
    for ugv in UGVS {
        assert_eq!(sim.robot(ugv).unwrap().team().params().claim_lease_s, LEASE_S, "the mission's lease is wired");
    }
    let mut first_stamp: BTreeMap<(String, GoalId), Time> = BTreeMap::new();
    let (victim, goal, renewed_at) = 'found: loop {
        sim.step(&mut NoObserver);
        assert!(sim.outcome().is_none(), "no UGV renewed a claim before the end");
        for ugv in UGVS {
            let me = RobotId::new(ugv);
            let team = &sim.robot(ugv).unwrap().team();
            for g in team.goals().iter().filter(|g| g.visited.is_none() && g.is_held_by(&me)) {
                let Some(mine) = g.claims.iter().find(|c| c.robot == me) else { continue };
                let first = *first_stamp.entry((ugv.to_string(), g.id.clone())).or_insert(mine.stamp);
                if mine.stamp > first {
                    break 'found (ugv, g.id.clone(), mine.stamp.as_secs_f64());
                }
            }
        }
    };
    drop(sim);
    let kill_s = renewed_at + 0.5;

    // The same run with the holder killed there.
    let faults = Faults { kill: vec![KillFault { robot: RobotId::new(victim), at_s: kill_s }], ..Faults::default() };
    let mut sim = simulation(&loaded, SimOptions { faults, ..options() });
    while sim.now().as_secs_f64() < kill_s - 1.5 * dt {
        sim.step(&mut NoObserver);
    }
    let dead = RobotId::new(victim);
    let view = sim.robot(victim).unwrap().team().goal(&goal).cloned().expect("the victim knows its goal");
    assert!(view.is_held_by(&dead), "{victim} holds {goal} just before the kill: {view:?}");
    let stamp = view.claims.iter().find(|c| c.robot == dead).unwrap().stamp.as_secs_f64();
    assert!((stamp - renewed_at).abs() < 1e-6, "same run up to the kill: claim stamped {stamp}, expected {renewed_at}");
    let expires_s = stamp + LEASE_S;

    let others: Vec<&str> = ["base", "uav1"].into_iter().chain(UGVS.into_iter().filter(|u| *u != victim)).collect();
    let mut saw_dead_claim = BTreeSet::new();
    let mut blocked_after_expiry = Vec::new();
    // Earliest claim another UGV made on the goal (its own stamp), and who.
    let mut taken: Option<(f64, String)> = None;
    run_to_end(&mut sim, |sim| {
        let now = sim.now().as_secs_f64();
        for id in &others {
            let Some(v) = sim.robot(id).unwrap().team().goal(&goal) else { continue };
            if v.claims.iter().any(|c| c.robot == dead) {
                saw_dead_claim.insert(id.to_string());
                if now > expires_s + 1.0 {
                    blocked_after_expiry.push(format!("{id} at {now:.0} s"));
                }
            }
            let me = RobotId::new(id);
            if let Some(c) = v.claims.iter().find(|c| c.robot == me) {
                let t = c.stamp.as_secs_f64();
                if t > kill_s && taken.as_ref().is_none_or(|(first, _)| t < *first) {
                    taken = Some((t, id.to_string()));
                }
            }
        }
    });
    let summary = sim.run(&mut NoObserver).summary;
    eprintln!(
        "kill: {victim} killed at {kill_s:.1} s holding {goal} (claim stamped {stamp:.1} s, lease {LEASE_S} s); taken \
         over: {taken:?}; {:?} at {:.0} s; {}",
        summary.outcome,
        summary.end_s,
        visit_times(&summary)
    );

    let killed = summary.robots.iter().find(|r| r.id == victim).unwrap();
    assert!(killed.killed_s.is_some_and(|k| (k - kill_s).abs() <= dt + 1e-9), "{killed:?}");
    // The live robots knew the claim, so it kept the goal for the victim while the lease ran…
    assert!(!saw_dead_claim.is_empty(), "no live robot knew {victim}'s claim");
    // …and not a second longer.
    assert!(
        blocked_after_expiry.is_empty(),
        "the dead claim still counted after {expires_s:.0} s: {blocked_after_expiry:?}"
    );
    let (claimed_s, by) = taken.expect("another UGV claimed the dead robot's goal");
    assert!(UGVS.contains(&by.as_str()) && by != victim, "{by}");
    assert!(
        claimed_s >= expires_s - dt,
        "{by} claimed {goal} at {claimed_s:.1} s, while {victim}'s lease ran to {expires_s:.1} s"
    );
    let g = summary
        .goals
        .iter()
        .find(|g| (g.position[0] - view.position.x).hypot(g.position[1] - view.position.y) < 1.0)
        .expect("the goal is in the summary");
    let visited_s = g.visited_s.expect("the dead robot's goal was visited");
    assert_ne!(g.visited_by.as_deref(), Some(victim));
    assert!(visited_s > kill_s + LEASE_S, "visited at {visited_s:.0} s, before the kill + lease");
    // The two survivors finish the mission.
    assert_complete_without_revisits(&summary, "kill");
}

/// The heavy skills in the background, as `spomp run` runs them, with `spomp run`'s typical
/// compute times: the team still visits every cluster, and the run repeats bit for bit (the
/// hand-overs are simulated-time events, not thread timing).
#[test]
fn with_the_heavy_skills_in_the_background_the_mission_completes_and_repeats() {
    let loaded = load(&mission_path());
    let background = SimOptions { skill_latency: Some(SkillLatency::TYPICAL), ..options() };
    let first = simulation(&loaded, background.clone()).run(&mut NoObserver).summary;
    eprintln!("background skills: {:?} at {:.0} s; {}", first.outcome, first.end_s, visit_times(&first));
    assert_complete_without_revisits(&first, "background skills");
    let again = simulation(&loaded, background).run(&mut NoObserver).summary;
    assert_eq!(visit_times(&first), visit_times(&again), "a background-skills run repeats exactly");
    assert_eq!(first.end_s, again.end_s);
}
