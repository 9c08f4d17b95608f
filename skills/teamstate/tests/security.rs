//! A secured team (signed records and messages) under hostile input: forgeries, non-members,
//! replays, future stamps and wrapped counters change nothing; snapshots restore only their own.
#![allow(clippy::unwrap_used)] // tests may unwrap

mod common;

use std::sync::Arc;

use common::*;
use proptest::prelude::*;
use spomp_core::{GoalId, Point2, Pose2, Time};
use spomp_teamstate::{
    ClaimRecord, GoalOrigin, Record, RecordBody, RecordKey, Signature, SnapshotError, SyncError, SyncMessage, TeamKeys,
    TeamSecurity, TeamState, TierSet, VisitRecord,
};

const MEMBERS: [(&str, u8, u32); 3] = [("ugv1", 1, 1), ("ugv2", 2, 2), ("uav", 3, 9)];

fn team_keys(team: &str) -> Arc<TeamKeys> {
    let mut keys = TeamKeys::new(team);
    for (name, seed, _) in MEMBERS {
        keys.add(id(name), &TeamSecurity::public_key_of(&[seed; 32])).unwrap();
    }
    Arc::new(keys)
}

fn secured(name: &str) -> TeamState {
    let (_, seed, priority) = MEMBERS.iter().copied().find(|m| m.0 == name).unwrap();
    let mut ts = robot(name, priority);
    ts.set_security(Arc::new(TeamSecurity::new(id(name), &[seed; 32], team_keys("city")).unwrap())).unwrap();
    ts
}

fn team() -> Vec<TeamState> {
    MEMBERS.iter().map(|m| secured(m.0)).collect()
}

/// A message as an attacker would build it: any sender name, any records, signed with any key
/// (or not at all).
fn forged(from: &str, to: &str, records: Vec<Record>, signer: Option<u8>) -> Vec<u8> {
    let mut msg = SyncMessage {
        from: id(from),
        to: id(to),
        seq: 1,
        ack: Default::default(),
        peer_has_all: false,
        wants_ack: true,
        records,
        session: 7,
        signature: None,
    };
    if let Some(seed) = signer {
        // Well-formed signatures that no member's key made.
        msg.signature = Some(Signature([seed; 64]));
        for r in &mut msg.records {
            r.sig = Some(Box::new(Signature([seed; 64])));
        }
    }
    msg.encode()
}

#[test]
fn signed_teams_sync_as_unsigned_ones_do() {
    let mut t = team();
    let g = t[0].identify_goal(Point2::new(40.0, 5.0), GoalOrigin::Detected, t_(1.0)).unwrap().id().clone();
    t[0].claim(&g, t_(2.0)).unwrap();
    let (a, rest) = t.split_at_mut(1);
    sync_fully(&mut a[0], &mut rest[0]);
    let (b, c) = rest.split_at_mut(1);
    sync_fully(&mut b[0], &mut c[0]);
    assert!(t[2].goal(&g).unwrap().is_held_by(&id("ugv1")), "relayed through ugv2 to the UAV, signatures intact");
    assert!(t[0].same_records(&t[1]) && t[1].same_records(&t[2]));
    assert!(t[0].records().all(|r| r.sig.is_some()));
}

fn t_(s: f64) -> Time {
    t(s)
}

#[test]
fn forged_visits_claims_and_non_members_are_refused_and_change_nothing() {
    let mut t = team();
    let g = t[0].identify_goal(Point2::new(40.0, 5.0), GoalOrigin::Detected, t_(1.0)).unwrap().id().clone();
    let (a, rest) = t.split_at_mut(1);
    sync_fully(&mut a[0], &mut rest[0]);
    let before = t[1].clone();
    let visit = Record {
        key: RecordKey::Visit { goal: g.clone(), robot: id("ugv1") },
        dot: 1,
        body: RecordBody::Visit(VisitRecord { stamp: t_(3.0) }),
        sig: None,
    };
    let claim = Record {
        key: RecordKey::Claim { goal: g.clone(), claimant: id("uav") },
        dot: 5,
        body: RecordBody::Claim(ClaimRecord { active: true, priority: 0, stamp: t_(4.0) }),
        sig: None,
    };
    let cases = [
        ("unsigned", forged("ugv1", "ugv2", vec![visit.clone()], None)),
        ("signed with the attacker's key", forged("ugv1", "ugv2", vec![visit.clone()], Some(66))),
        ("a claim in a member's name", forged("uav", "ugv2", vec![claim.clone()], Some(3))),
        ("a non-member", forged("rogue", "ugv2", vec![visit.clone()], Some(66))),
    ];
    for (what, bytes) in cases {
        let from = SyncMessage::decode(&bytes).unwrap().from;
        let err = t[1].apply_bytes(&from, &bytes).unwrap_err();
        assert!(
            matches!(err, SyncError::Unsigned(_) | SyncError::BadSignature { .. } | SyncError::NotAMember(_)),
            "{what}: {err}"
        );
        assert!(t[1].same_records(&before), "{what} changed the state");
    }
    assert!(t[1].goal(&g).unwrap().visited.is_none());

    // An impostor: a process that calls itself ugv1 and signs properly, with its own key.
    let mut fake_keys = TeamKeys::new("city");
    fake_keys.add(id("ugv1"), &TeamSecurity::public_key_of(&[66; 32])).unwrap();
    let mut impostor = robot("ugv1", 0);
    impostor.set_security(Arc::new(TeamSecurity::new(id("ugv1"), &[66; 32], Arc::new(fake_keys)).unwrap())).unwrap();
    let fake = impostor.identify_goal(Point2::new(-50.0, 0.0), GoalOrigin::Detected, t_(1.0)).unwrap().id().clone();
    impostor.claim(&fake, t_(2.0)).unwrap();
    impostor.mark_visited(&fake, t_(3.0)).unwrap();
    let bytes = impostor.make_sync(&id("ugv2"), TierSet::ALL, usize::MAX).unwrap().encode();
    let err = t[1].apply_bytes(&id("ugv1"), &bytes).unwrap_err();
    assert!(matches!(err, SyncError::BadSignature { .. }), "{err}");
    assert!(t[1].same_records(&before));
}

#[test]
fn a_relay_cannot_alter_a_record_it_passes_on() {
    let mut t = team();
    let g = t[0].identify_goal(Point2::new(40.0, 5.0), GoalOrigin::Detected, t_(1.0)).unwrap().id().clone();
    t[0].claim(&g, t_(2.0)).unwrap();
    let (a, rest) = t.split_at_mut(1);
    sync_fully(&mut a[0], &mut rest[0]);
    // ugv2 (a member, signing its own messages correctly) relays ugv1's claim with a better
    // priority than ugv1 has.
    let mut msg = t[1].make_sync(&id("uav"), TierSet::ALL, usize::MAX).unwrap();
    let claim = msg.records.iter_mut().find(|r| matches!(r.key, RecordKey::Claim { .. })).unwrap();
    if let RecordBody::Claim(c) = &mut claim.body {
        c.stamp = t_(1e6);
    }
    let bytes = msg.encode();
    let err = t[2].apply_bytes(&id("ugv2"), &bytes).unwrap_err();
    assert!(matches!(err, SyncError::BadSignature { .. }), "{err}");
    assert_eq!(t[2].records().count(), 0);
}

#[test]
fn a_counter_near_overflow_is_refused_even_unsigned() {
    let mut a = robot("ugv1", 1);
    let mut b = robot("ugv2", 2);
    let g = a.identify_goal(Point2::new(1.0, 1.0), GoalOrigin::Detected, t(0.0)).unwrap().id().clone();
    sync_fully(&mut a, &mut b);
    let mut msg = b.make_sync(&id("ugv1"), TierSet::ALL, usize::MAX).unwrap_or(SyncMessage {
        from: id("ugv2"),
        to: id("ugv1"),
        seq: 99,
        ack: Default::default(),
        peer_has_all: false,
        wants_ack: true,
        records: vec![],
        session: 0,
        signature: None,
    });
    msg.records.push(Record {
        key: RecordKey::Claim { goal: g.clone(), claimant: id("ugv1") },
        dot: u64::MAX,
        body: RecordBody::Claim(ClaimRecord { active: false, priority: 1, stamp: t(1.0) }),
        sig: None,
    });
    let err = a.apply_bytes(&id("ugv2"), &msg.encode()).unwrap_err();
    assert!(matches!(err, SyncError::InvalidRecord { .. }), "{err}");
    // ugv1 still writes and its writes still reach its peer.
    a.set_pose(Pose2::new(3.0, 4.0, 0.0), t(2.0)).unwrap();
    sync_fully(&mut a, &mut b);
    assert_eq!(b.robot_pose(&id("ugv1")).map(|p| p.0), Some(Pose2::new(3.0, 4.0, 0.0)));
}

#[test]
fn claims_stamped_far_in_the_future_are_left_out() {
    let mut t = team();
    let g = t[0].identify_goal(Point2::new(40.0, 5.0), GoalOrigin::Detected, t_(1.0)).unwrap().id().clone();
    t[0].claim(&g, t_(1e6)).unwrap(); // ugv1's clock is a million seconds ahead
    t[1].advance_clock(t_(10.0));
    let msg = t[0].make_sync(&id("ugv2"), TierSet::ALL, usize::MAX).unwrap();
    let report = t[1].apply_bytes(&id("ugv1"), &msg.encode()).unwrap();
    assert_eq!(report.records_from_the_future, 1, "the claim");
    assert!(t[1].goal(&g).is_some(), "the goal itself is taken");
    assert!(t[1].goal(&g).unwrap().claims.is_empty());
}

#[test]
fn a_restarted_peer_resyncs_and_its_old_session_is_a_replay() {
    let mut a = robot("ugv1", 1);
    let mut b = robot("ugv2", 2);
    a.set_session(100);
    b.set_session(200);
    a.identify_goal(Point2::new(1.0, 1.0), GoalOrigin::Detected, t(0.0)).unwrap();
    let old = a.make_sync(&id("ugv2"), TierSet::ALL, usize::MAX).unwrap().encode();
    b.apply_bytes(&id("ugv1"), &old).unwrap();
    sync_fully(&mut a, &mut b);
    // ugv1 reboots from its snapshot with a newer session.
    let snap = a.snapshot();
    let mut a2 = robot("ugv1", 1);
    a2.set_session(101);
    a2.restore(&snap).unwrap();
    a2.identify_goal(Point2::new(90.0, 1.0), GoalOrigin::Detected, t(5.0)).unwrap();
    sync_fully(&mut a2, &mut b);
    assert!(a2.same_records(&b));
    assert!(a2.sync_complete_with(&id("ugv2")) && b.sync_complete_with(&id("ugv1")));
    let err = b.apply_bytes(&id("ugv1"), &old).unwrap_err();
    assert!(matches!(err, SyncError::StaleSession { .. }), "{err}");
}

#[test]
fn a_snapshot_restores_only_into_its_own_robot_and_team_and_intact() {
    let mut t = team();
    let g = t[0].identify_goal(Point2::new(40.0, 5.0), GoalOrigin::Detected, t_(1.0)).unwrap().id().clone();
    t[0].claim(&g, t_(2.0)).unwrap();
    t[0].add_scan(scan("ugv1", 3.0, 3.0, 2.0)).unwrap();
    let (a, rest) = t.split_at_mut(1);
    sync_fully(&mut a[0], &mut rest[0]);
    let snap = t[1].snapshot();

    let mut fresh = secured("ugv2");
    let summary = fresh.restore(&snap).unwrap();
    assert!(fresh.same_records(&t[1]));
    assert_eq!((summary.goals, summary.own_claims), (1, 0));
    assert_eq!(fresh.scan_count(), 1);
    // It writes above its old counter: its next claim wins over the one it made before.
    fresh.claim(&g, t_(3.0)).ok();

    assert!(matches!(secured("uav").restore(&snap), Err(SnapshotError::OtherRobot { .. })));
    assert!(matches!(robot("ugv2", 2).restore(&snap), Err(SnapshotError::OtherTeam { .. })));
    for cut in [0, 5, snap.len() / 2, snap.len() - 1] {
        assert!(secured("ugv2").restore(&snap[..cut]).is_err(), "cut at {cut}");
    }
    // One byte changed anywhere in the records: refused, never half-taken.
    let mut refused = 0;
    for k in (10..snap.len()).step_by(7) {
        let mut bad = snap.clone();
        bad[k] ^= 0x20;
        let mut target = secured("ugv2");
        match target.restore(&bad) {
            Err(_) => {
                refused += 1;
                assert_eq!(target.records().count(), 0);
            }
            // A flip in a part no signature covers (a counter) may still decode; what was
            // taken must then be exactly the signed records.
            Ok(_) => assert!(target.same_records(&t[1])),
        }
    }
    assert!(refused > 0);
}

// ---------------------------------------------------------------------------------- property

#[derive(Clone, Debug)]
enum Step {
    Identify(usize, u8, u8),
    Claim(usize, usize),
    Visit(usize, usize),
    Pose(usize, u8),
    /// One honest message from a to b, delivered.
    Send(usize, usize),
    /// The attacker's move, between honest steps.
    Attack(Attack),
}

#[derive(Clone, Debug)]
enum Attack {
    /// A made-up visit, claim or goal in a member's name, signed by the attacker's key or not.
    Forge { victim: usize, as_robot: usize, kind: u8, signed: bool, goal: usize },
    /// A genuine message seen on the air, delivered again (to its addressee or another robot).
    Replay { pick: usize, to: usize },
    /// A genuine message with one bit flipped.
    Flip { pick: usize, bit: usize },
}

fn step() -> impl Strategy<Value = Step> {
    let r = 0..3usize;
    prop_oneof![
        2 => (r.clone(), any::<u8>(), any::<u8>()).prop_map(|(a, x, y)| Step::Identify(a, x, y)),
        2 => (0..2usize, any::<usize>()).prop_map(|(a, g)| Step::Claim(a, g)),
        1 => (0..2usize, any::<usize>()).prop_map(|(a, g)| Step::Visit(a, g)),
        2 => (r.clone(), any::<u8>()).prop_map(|(a, x)| Step::Pose(a, x)),
        5 => (r.clone(), r.clone()).prop_map(|(a, b)| Step::Send(a, b)),
        4 => prop_oneof![
            (r.clone(), r.clone(), 0..3u8, any::<bool>(), any::<usize>())
                .prop_map(|(victim, as_robot, kind, signed, goal)| Attack::Forge { victim, as_robot, kind, signed, goal }),
            (any::<usize>(), r.clone()).prop_map(|(pick, to)| Attack::Replay { pick, to }),
            (any::<usize>(), any::<usize>()).prop_map(|(pick, bit)| Attack::Flip { pick, bit }),
        ]
        .prop_map(Step::Attack),
    ]
}

fn pick_goal(ts: &TeamState, pick: usize) -> Option<GoalId> {
    let goals = ts.goals();
    (!goals.is_empty()).then(|| goals[pick % goals.len()].id.clone())
}

/// Runs the honest steps (and the attacks, if `attack`); returns the team after a full sync.
fn run(steps: &[Step], attack: bool) -> Vec<TeamState> {
    let mut t = team();
    let mut seen: Vec<(usize, Vec<u8>)> = Vec::new();
    for (k, s) in steps.iter().enumerate() {
        let now = t_(k as f64);
        match s {
            Step::Identify(a, x, y) => {
                let _ = t[*a].identify_goal(Point2::new(*x as f64, *y as f64), GoalOrigin::Detected, now);
            }
            Step::Claim(a, g) => {
                if let Some(g) = pick_goal(&t[*a], *g) {
                    let _ = t[*a].claim(&g, now);
                }
            }
            Step::Visit(a, g) => {
                if let Some(g) = pick_goal(&t[*a], *g) {
                    let _ = t[*a].mark_visited(&g, now);
                }
            }
            Step::Pose(a, x) => {
                let _ = t[*a].set_pose(Pose2::new(*x as f64, 0.0, 0.0), now);
            }
            Step::Send(a, b) if a != b => {
                let to = t[*b].self_id().clone();
                if let Some(m) = t[*a].make_sync(&to, TierSet::ALL, usize::MAX) {
                    let bytes = m.encode();
                    let from = t[*a].self_id().clone();
                    t[*b].apply_bytes(&from, &bytes).unwrap();
                    seen.push((*b, bytes));
                }
            }
            Step::Send(..) => {}
            Step::Attack(_) if !attack => {}
            Step::Attack(Attack::Forge { victim, as_robot, kind, signed, goal }) => {
                let name = MEMBERS[*as_robot].0;
                let g = pick_goal(&t[*victim], *goal).unwrap_or(GoalId { origin: id(name), seq: 0 });
                let record = match kind {
                    0 => Record {
                        key: RecordKey::Visit { goal: g, robot: id(name) },
                        dot: 1,
                        body: RecordBody::Visit(VisitRecord { stamp: now }),
                        sig: None,
                    },
                    1 => Record {
                        key: RecordKey::Claim { goal: g, claimant: id(name) },
                        dot: 1 << 40,
                        body: RecordBody::Claim(ClaimRecord { active: true, priority: 0, stamp: t_(1e9) }),
                        sig: None,
                    },
                    _ => Record {
                        key: RecordKey::Goal(GoalId { origin: id(name), seq: 900 }),
                        dot: 1,
                        body: RecordBody::Goal(spomp_teamstate::GoalRecord {
                            position: Point2::new(500.0, 500.0),
                            origin: GoalOrigin::Detected,
                            identified_at: now,
                        }),
                        sig: None,
                    },
                };
                let to = MEMBERS[*victim].0;
                let bytes = forged(name, to, vec![record], signed.then_some(77));
                let _ = t[*victim].apply_bytes(&id(name), &bytes);
            }
            Step::Attack(Attack::Replay { pick, to }) => {
                if !seen.is_empty() {
                    let (_, bytes) = &seen[pick % seen.len()];
                    let from = SyncMessage::decode(bytes).unwrap().from;
                    let _ = t[*to].apply_bytes(&from, bytes);
                }
            }
            Step::Attack(Attack::Flip { pick, bit }) => {
                if !seen.is_empty() {
                    let (to, bytes) = &seen[pick % seen.len()];
                    let mut bad = bytes.clone();
                    let i = (bit / 8) % bad.len();
                    bad[i] ^= 1 << (bit % 8);
                    let from = SyncMessage::decode(bytes).unwrap().from;
                    let _ = t[*to].apply_bytes(&from, &bad);
                }
            }
        }
    }
    for _ in 0..30 {
        let mut any = false;
        for a in 0..3 {
            for b in 0..3 {
                if a != b {
                    let to = t[b].self_id().clone();
                    if let Some(m) = t[a].make_sync(&to, TierSet::ALL, usize::MAX) {
                        any = true;
                        let from = t[a].self_id().clone();
                        t[b].apply_bytes(&from, &m.encode()).unwrap();
                    }
                }
            }
        }
        if !any {
            break;
        }
    }
    t
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 48, ..ProptestConfig::default() })]

    /// Whatever a non-key-holder sends (forged records in members' names, replays, flipped
    /// bits), the honest robots' states after a full sync equal those of the same run without
    /// the attacker.
    #[test]
    fn an_attacker_without_keys_changes_nothing(steps in prop::collection::vec(step(), 1..80)) {
        let honest = run(&steps, false);
        let attacked = run(&steps, true);
        for (h, a) in honest.iter().zip(&attacked) {
            prop_assert!(h.same_records(a), "{} differs", h.self_id());
            prop_assert_eq!(h.goals(), a.goals());
        }
        prop_assert!(attacked[0].same_records(&attacked[1]) && attacked[1].same_records(&attacked[2]));
    }
}
