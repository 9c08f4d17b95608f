//! Goal coordination and merge rules on hand-checkable cases.
#![allow(clippy::unwrap_used)] // tests and benchmarks may unwrap

mod common;

use common::*;
use spomp_core::{GoalId, Point2, Pose2};
use spomp_teamstate::{GoalOrigin, GoalStatus, IdentifyOutcome, TeamStateError, TierSet};

fn detect(ts: &mut spomp_teamstate::TeamState, x: f64, y: f64, at: f64) -> GoalId {
    ts.identify_goal(Point2::new(x, y), GoalOrigin::Detected, t(at)).unwrap().id().clone()
}

#[test]
fn independently_identified_nearby_goals_become_one() {
    let mut a = robot("ugv1", 1);
    let mut b = robot("ugv2", 2);
    let ga = detect(&mut a, 0.0, 0.0, 1.0);
    let gb = detect(&mut b, 6.0, 0.0, 2.0);
    let far = detect(&mut b, 40.0, 0.0, 2.0);
    assert_ne!(ga, gb);
    sync_fully(&mut a, &mut b);
    for ts in [&a, &b] {
        assert_eq!(ts.goals().len(), 2, "the pair 6 m apart is one goal, the far one another");
        let v = ts.goal(&gb).unwrap();
        assert_eq!(v.id, ga, "the earlier identification is canonical");
        assert_eq!(v.aliases, vec![gb.clone()]);
        assert_eq!(ts.goal(&far).unwrap().id, far);
    }
    assert!(a.same_records(&b));
    // Identifying near a known goal again adds nothing.
    assert_eq!(
        a.identify_goal(Point2::new(3.0, 1.0), GoalOrigin::Detected, t(3.0)).unwrap(),
        IdentifyOutcome::Existing(ga.clone())
    );
    // A visit of the alias counts for the canonical goal.
    b.mark_visited(&gb, t(4.0)).unwrap();
    sync_fully(&mut a, &mut b);
    assert_eq!(a.goal(&ga).unwrap().status, GoalStatus::Visited);
}

#[test]
fn mission_goals_loaded_everywhere_do_not_duplicate() {
    let mut a = robot("ugv1", 1);
    let mut b = robot("ugv2", 2);
    for ts in [&mut a, &mut b] {
        ts.add_mission_goal(0, Point2::new(10.0, 10.0)).unwrap();
        ts.add_mission_goal(1, Point2::new(50.0, 10.0)).unwrap();
    }
    sync_fully(&mut a, &mut b);
    assert_eq!(a.goals().len(), 2);
    assert!(a.same_records(&b));
    assert_eq!(a.goals()[0].origin, GoalOrigin::Mission);
}

#[test]
fn concurrent_claims_resolve_by_priority_in_one_round() {
    let mut a = robot("ugv1", 1);
    let mut b = robot("ugv2", 2);
    let g = detect(&mut a, 0.0, 0.0, 1.0);
    sync_fully(&mut a, &mut b);
    b.claim(&g, t(2.0)).unwrap();
    a.claim(&g, t(2.1)).unwrap();
    // One round: each applies the other's message.
    let ma = a.make_sync(&id("ugv2"), TierSet::ALL, usize::MAX).unwrap();
    let mb = b.make_sync(&id("ugv1"), TierSet::ALL, usize::MAX).unwrap();
    let rb = b.apply(&id("ugv1"), &ma).unwrap();
    let ra = a.apply(&id("ugv2"), &mb).unwrap();
    assert_eq!(rb.released, vec![g.clone()], "the lower-priority robot gives the goal up");
    assert!(ra.released.is_empty());
    assert!(a.goal(&g).unwrap().is_held_by(&id("ugv1")));
    assert!(b.goal(&g).unwrap().is_held_by(&id("ugv1")));
    assert_eq!(b.goal(&g).unwrap().claims.len(), 1);
    assert_eq!(b.robot_status(&id("ugv2")).unwrap().current_goal, None);
    // ugv2 may not take it back while ugv1 holds it.
    assert!(matches!(b.claim(&g, t(3.0)), Err(TeamStateError::ClaimedByOther { .. })));
    assert!(b.claimable_goals_for(&id("ugv2"), Point2::new(0.0, 0.0)).is_empty());
    sync_fully(&mut a, &mut b);
    assert!(a.same_records(&b));
    assert_eq!(a.goal(&g).unwrap().claims.len(), 1);
}

#[test]
fn equal_priorities_break_ties_by_robot_id() {
    let mut a = robot("ugv_b", 3);
    let mut b = robot("ugv_a", 3);
    let g = detect(&mut a, 0.0, 0.0, 1.0);
    sync_fully(&mut a, &mut b);
    a.claim(&g, t(2.0)).unwrap();
    b.claim(&g, t(2.0)).unwrap();
    sync_fully(&mut a, &mut b);
    assert!(a.goal(&g).unwrap().is_held_by(&id("ugv_a")));
    assert_eq!(a.goal(&g).unwrap().claims.len(), 1);
}

#[test]
fn release_supersedes_claim_even_if_the_claim_is_redelivered() {
    let mut a = robot("ugv1", 1);
    let mut b = robot("ugv2", 2);
    let g = detect(&mut a, 0.0, 0.0, 1.0);
    a.claim(&g, t(2.0)).unwrap();
    let old = a.make_sync(&id("ugv2"), TierSet::ALL, usize::MAX).unwrap();
    a.release(&g, t(3.0)).unwrap();
    let newer = a.make_sync(&id("ugv2"), TierSet::ALL, usize::MAX).unwrap();
    b.apply(&id("ugv1"), &newer).unwrap();
    b.apply(&id("ugv1"), &old).unwrap(); // stale, re-ordered
    assert_eq!(b.goal(&g).unwrap().status, GoalStatus::Identified);
    assert!(b.goal(&g).unwrap().claimant.is_none());
}

#[test]
fn a_visit_releases_other_claims_and_is_permanent() {
    let mut a = robot("ugv1", 1);
    let mut b = robot("ugv2", 2);
    let g = detect(&mut a, 0.0, 0.0, 1.0);
    sync_fully(&mut a, &mut b);
    a.claim(&g, t(2.0)).unwrap();
    b.mark_visited(&g, t(2.5)).unwrap();
    send(&mut b, &mut a);
    let v = a.goal(&g).unwrap();
    assert_eq!(v.status, GoalStatus::Visited);
    assert_eq!(v.visited, Some((t(2.5), id("ugv2"))));
    assert!(v.claims.is_empty(), "ugv1 released on learning of the visit");
    assert!(matches!(a.claim(&g, t(3.0)), Err(TeamStateError::AlreadyVisited(_))));
    assert!(a.all_goals_visited());
}

#[test]
fn unreachable_marks_are_per_robot_and_cleared_by_epoch() {
    let mut a = robot("ugv1", 1);
    let mut b = robot("ugv2", 2);
    let g = detect(&mut a, 0.0, 0.0, 1.0);
    let h = detect(&mut a, 30.0, 0.0, 1.0);
    a.claim(&g, t(2.0)).unwrap();
    a.mark_unreachable(&g, t(3.0)).unwrap();
    sync_fully(&mut a, &mut b);
    assert!(b.goal(&g).unwrap().is_unreachable_for(&id("ugv1")));
    assert!(b.goal(&g).unwrap().claimant.is_none(), "marked unreachable means released");
    let here = Point2::new(0.0, 0.0);
    let for_a: Vec<_> = b.claimable_goals_for(&id("ugv1"), here).iter().map(|v| v.id.clone()).collect();
    assert_eq!(for_a, vec![h.clone()]);
    let for_b: Vec<_> = b.claimable_goals_for(&id("ugv2"), here).iter().map(|v| v.id.clone()).collect();
    assert_eq!(for_b, vec![g.clone(), h.clone()], "nearest first, still open for ugv2");
    a.clear_unreachable();
    sync_fully(&mut a, &mut b);
    assert!(!b.goal(&g).unwrap().is_unreachable_for(&id("ugv1")));
    a.mark_unreachable(&g, t(9.0)).unwrap();
    assert!(a.goal(&g).unwrap().is_unreachable_for(&id("ugv1")), "a new mark in the new epoch counts");
}

#[test]
fn newest_pose_wins_and_is_relayed() {
    let mut a = robot("ugv1", 1);
    let mut uav = robot("uav", 9);
    let mut b = robot("ugv2", 2);
    assert!(a.set_pose(Pose2::new(1.0, 2.0, 0.5), t(5.0)).unwrap());
    assert!(!a.set_pose(Pose2::new(9.0, 9.0, 0.0), t(4.0)).unwrap(), "older pose ignored");
    a.set_path_end(Some(Point2::new(100.0, 0.0))).unwrap();
    let g = detect(&mut a, 50.0, 50.0, 6.0);
    sync_fully(&mut a, &mut uav);
    sync_fully(&mut uav, &mut b);
    let (pose, stamp) = b.robot_pose(&id("ugv1")).unwrap();
    assert_eq!((pose, stamp), (Pose2::new(1.0, 2.0, 0.5), t(5.0)));
    assert_eq!(b.robot_status(&id("ugv1")).unwrap().path_end, Some(Point2::new(100.0, 0.0)));
    assert!(b.goal(&g).is_some(), "goals relay through the UAV");
    assert!(a.same_records(&b));
}

#[test]
fn scans_are_shared_only_two_metres_apart() {
    let mut a = robot("ugv1", 1);
    assert!(a.add_scan(scan("ugv1", 0.0, 0.0, 1.0)).unwrap());
    assert!(!a.add_scan(scan("ugv1", 1.5, 0.0, 2.0)).unwrap());
    assert!(a.add_scan(scan("ugv1", 2.0, 0.0, 3.0)).unwrap());
    assert!(!a.add_scan(scan("ugv1", 1.0, 1.0, 4.0)).unwrap());
    assert!(a.add_scan(scan("ugv2", 9.0, 0.0, 5.0)).is_err(), "only own scans");
    let mut bad = scan("ugv1", 20.0, 0.0, 5.0);
    bad.obstacle.pop();
    assert!(a.add_scan(bad).is_err());
    let (new, cursor) = a.scans_since(0);
    assert_eq!((new.len(), cursor), (2, 2));
    let mut b = robot("ugv2", 2);
    b.add_scan(scan("ugv2", 50.0, 0.0, 1.0)).unwrap();
    let (_, cursor_b) = b.scans_since(0);
    sync_fully(&mut a, &mut b);
    let (arrived, _) = b.scans_since(cursor_b);
    assert_eq!(arrived.len(), 2);
    assert!(arrived.iter().all(|s| s.robot == id("ugv1")));
}

#[test]
fn map_versions_keep_the_newest() {
    let mut uav = robot("uav", 9);
    let mut a = robot("ugv1", 1);
    assert!(uav.add_map_version(3, t(1.0), vec![1, 2, 3]).unwrap());
    assert!(!uav.add_map_version(2, t(2.0), vec![9]).unwrap());
    sync_fully(&mut uav, &mut a);
    assert_eq!(a.latest_map(&id("uav")).unwrap().version, 3);
    assert!(uav.add_map_version(4, t(3.0), vec![4; 10]).unwrap());
    sync_fully(&mut uav, &mut a);
    let (origin, m) = a.newest_map().unwrap();
    assert_eq!((origin.as_str(), m.version, m.blob.len()), ("uav", 4, 10));
}

#[test]
fn higher_tiers_wait_and_budget_is_respected() {
    let mut a = robot("ugv1", 1);
    let mut b = robot("ugv2", 2);
    for i in 0..10 {
        a.add_scan(scan("ugv1", 3.0 * i as f64, 0.0, i as f64)).unwrap();
    }
    a.add_map_version(1, t(1.0), vec![7; 2000]).unwrap();
    let g = detect(&mut a, 0.0, 0.0, 1.0);
    a.set_pose(Pose2::new(0.0, 0.0, 0.0), t(1.0)).unwrap();

    // Position-only link: no scans or maps.
    let m = a.make_sync(&id("ugv2"), TierSet::only(spomp_teamstate::Tier::Coordination), usize::MAX).unwrap();
    assert!(m.records.iter().all(|r| r.tier() == spomp_teamstate::Tier::Coordination));
    assert_eq!(m.records.len(), 2, "goal and pose");
    b.apply(&id("ugv1"), &m).unwrap();
    assert!(b.goal(&g).is_some());

    // A small budget: every message fits, scans go before the map.
    let mut tiers_seen = Vec::new();
    for _ in 0..50 {
        let Some(m) = a.make_sync(&id("ugv2"), TierSet::ALL, 1200) else {
            break;
        };
        assert!(m.encode().len() <= 1200, "{} bytes", m.encode().len());
        tiers_seen.extend(m.records.iter().map(|r| r.tier()));
        b.apply(&id("ugv1"), &m).unwrap();
        if let Some(back) = b.make_sync(&id("ugv1"), TierSet::ALL, usize::MAX) {
            a.apply(&id("ugv2"), &back).unwrap();
        }
    }
    assert_eq!(b.scan_count(), 10);
    assert!(tiers_seen.windows(2).all(|w| w[0] <= w[1]), "tiers in priority order: {tiers_seen:?}");
    assert!(b.latest_map(&id("ugv1")).is_none(), "the 2 kB map never fits a 1.2 kB budget");
    sync_fully(&mut a, &mut b);
    assert!(a.same_records(&b));
}

#[test]
fn sync_completes_and_reopens_on_news() {
    let mut uav = robot("uav", 9);
    let mut a = robot("ugv1", 1);
    detect(&mut a, 0.0, 0.0, 1.0);
    a.add_scan(scan("ugv1", 0.0, 0.0, 1.0)).unwrap();
    a.set_pose(Pose2::new(0.0, 0.0, 0.0), t(1.0)).unwrap();
    uav.add_map_version(1, t(1.0), vec![1; 100]).unwrap();
    assert!(!uav.sync_complete_with(&id("ugv1")));
    sync_fully(&mut uav, &mut a);
    assert!(uav.sync_complete_with(&id("ugv1")));
    assert!(a.sync_complete_with(&id("uav")));
    // Pose updates alone do not reopen the sync (once the peer has any pose); a new goal does.
    a.set_pose(Pose2::new(1.0, 0.0, 0.0), t(2.0)).unwrap();
    assert!(a.sync_complete_with(&id("uav")));
    detect(&mut a, 40.0, 0.0, 2.0);
    assert!(!a.sync_complete_with(&id("uav")));
    sync_fully(&mut uav, &mut a);
    assert!(uav.sync_complete_with(&id("ugv1")) && a.sync_complete_with(&id("uav")));
}

#[test]
fn lost_messages_are_resent_after_the_ack_shows_the_gap() {
    let mut a = robot("ugv1", 1);
    let mut b = robot("ugv2", 2);
    let g1 = detect(&mut a, 0.0, 0.0, 1.0);
    let _lost = a.make_sync(&id("ugv2"), TierSet::ALL, usize::MAX).unwrap();
    let g2 = detect(&mut a, 40.0, 0.0, 2.0);
    let m2 = a.make_sync(&id("ugv2"), TierSet::ALL, usize::MAX).unwrap();
    assert_eq!(m2.records.len(), 1, "only the new goal: the first is presumed in flight");
    b.apply(&id("ugv1"), &m2).unwrap();
    assert!(b.goal(&g1).is_none());
    // b's acknowledgement reveals that message 1 never arrived.
    send(&mut b, &mut a);
    let m3 = a.make_sync(&id("ugv2"), TierSet::ALL, usize::MAX).unwrap();
    assert!(m3.records.iter().any(|r| r.key == spomp_teamstate::RecordKey::Goal(g1.clone())));
    b.apply(&id("ugv1"), &m3).unwrap();
    assert!(b.goal(&g1).is_some() && b.goal(&g2).is_some());
    sync_fully(&mut a, &mut b);
    assert!(a.same_records(&b) && a.sync_complete_with(&id("ugv2")));
}

#[test]
fn nothing_to_say_means_no_message() {
    let mut a = robot("ugv1", 1);
    let mut b = robot("ugv2", 2);
    sync_fully(&mut a, &mut b);
    assert!(a.make_sync(&id("ugv2"), TierSet::ALL, usize::MAX).is_none());
    assert!(a.make_sync(&id("ugv1"), TierSet::ALL, usize::MAX).is_none(), "never to itself");
}

/// Claims are leases: a silent holder's claim stops counting once the lease runs out (a dead
/// robot gives up its goal), a live holder keeps its claim by renewing it, and the renewal, once
/// it arrives, wins back a goal a lower-priority robot took meanwhile.
#[test]
fn a_claim_not_renewed_within_the_lease_expires_and_a_renewed_one_wins_back() {
    let mut a = robot("ugv1", 1);
    let mut b = robot("ugv2", 2);
    let g = detect(&mut a, 0.0, 0.0, 1.0);
    a.claim(&g, t(10.0)).unwrap();
    sync_fully(&mut a, &mut b);
    let lease = spomp_teamstate::TeamStateParams::default().claim_lease_s;
    b.advance_clock(t(10.0 + lease - 1.0));
    assert!(b.claimable_goals_for(b.self_id(), Point2::new(0.0, 0.0)).is_empty(), "within the lease");
    assert!(b.claim(&g, t(10.0 + lease - 1.0)).is_err());
    b.advance_clock(t(10.0 + lease + 1.0));
    assert_eq!(b.claimable_goals_for(b.self_id(), Point2::new(0.0, 0.0)).len(), 1, "expired");
    b.claim(&g, t(10.0 + lease + 1.0)).unwrap();
    assert!(b.goal(&g).unwrap().is_held_by(b.self_id()));
    // The holder was alive all along, only out of contact: it renewed its lease, and once that
    // reaches the lower-priority robot, the goal is the holder's again.
    a.advance_clock(t(10.0 + lease / 2.0 + 1.0));
    sync_fully(&mut a, &mut b);
    assert!(b.goal(&g).unwrap().is_held_by(a.self_id()), "{:?}", b.goal(&g).unwrap().claims);
    assert!(a.goal(&g).unwrap().is_held_by(a.self_id()));
    // Without any clock, nothing expires (replicas that never call `advance_clock`).
    let mut c = robot("ugv3", 3);
    sync_fully(&mut a, &mut c);
    assert!(c.claimable_goals_for(c.self_id(), Point2::new(0.0, 0.0)).is_empty());
}
