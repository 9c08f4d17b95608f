//! A secured robot under a flood (issue 36): whatever an insider with the transport password
//! but no member's signing key sends — garbage, invented sender names, forgeries in members'
//! names, replays of genuine messages of the current session, bit flips, oversized messages —
//! every message is refused, the robot's tables do not grow by a single entry, and what it
//! holds and will say to its teammates is what it would have without the flood.
#![allow(clippy::unwrap_used)] // tests may unwrap

mod common;

use std::sync::Arc;

use common::*;
use proptest::prelude::*;
use spomp_core::{Point2, Pose2};
use spomp_teamstate::{
    GoalOrigin, Record, RecordBody, RecordKey, Signature, SyncError, SyncMessage, TeamKeys, TeamSecurity, TeamState,
    TeamStateParams, TierSet, VisitRecord,
};

const MEMBERS: [(&str, u8, u32); 3] = [("ugv1", 1, 1), ("ugv2", 2, 2), ("uav", 3, 9)];
/// Small, so oversized messages are cheap to make.
const MAX_MESSAGE_BYTES: usize = 4096;

fn secured(name: &str) -> TeamState {
    let mut keys = TeamKeys::new("city");
    for (member, seed, _) in MEMBERS {
        keys.add(id(member), &TeamSecurity::public_key_of(&[seed; 32])).unwrap();
    }
    let (_, seed, priority) = MEMBERS.iter().copied().find(|m| m.0 == name).unwrap();
    let params = TeamStateParams { max_message_bytes: MAX_MESSAGE_BYTES, ..TeamStateParams::default() };
    let mut ts = TeamState::new(id(name), priority, params).unwrap();
    ts.set_security(Arc::new(TeamSecurity::new(id(name), &[seed; 32], Arc::new(keys)).unwrap())).unwrap();
    ts.set_session(1000 + u64::from(seed));
    ts
}

/// One genuine message from `a` to `b`, applied; its bytes.
fn deliver(a: &mut TeamState, b: &mut TeamState) -> Option<Vec<u8>> {
    let bytes = a.make_sync(&b.self_id().clone(), TierSet::ALL, usize::MAX)?.encode();
    b.apply_bytes(&a.self_id().clone(), &bytes).unwrap();
    Some(bytes)
}

/// ugv1 and the UAV have told ugv2 (the victim) a few things; the genuine messages ugv2 got.
fn honest_team() -> (TeamState, TeamState, TeamState, Vec<(String, Vec<u8>)>) {
    let (mut ugv1, mut ugv2, mut uav) = (secured("ugv1"), secured("ugv2"), secured("uav"));
    let mut seen = Vec::new();
    let g = ugv1.identify_goal(Point2::new(40.0, 5.0), GoalOrigin::Detected, t(1.0)).unwrap().id().clone();
    ugv1.claim(&g, t(2.0)).unwrap();
    uav.set_pose(Pose2::new(3.0, 4.0, 0.0), t(2.0)).unwrap();
    for k in 0..4 {
        ugv1.set_pose(Pose2::new(k as f64, 0.0, 0.0), t(3.0 + k as f64)).unwrap();
        if let Some(b) = deliver(&mut ugv1, &mut ugv2) {
            seen.push(("ugv1".to_string(), b));
        }
        if let Some(b) = deliver(&mut uav, &mut ugv2) {
            seen.push(("uav".to_string(), b));
        }
        deliver(&mut ugv2, &mut ugv1);
        deliver(&mut ugv2, &mut uav);
    }
    ugv1.add_scan(scan("ugv1", 9.0, 9.0, 8.0)).unwrap();
    if let Some(b) = deliver(&mut ugv1, &mut ugv2) {
        seen.push(("ugv1".to_string(), b));
    }
    (ugv1, ugv2, uav, seen)
}

#[derive(Clone, Debug)]
enum Hostile {
    /// Any bytes, named as from any sender.
    Garbage { from: String, bytes: Vec<u8> },
    /// A well-formed message from an invented sender, signed with a key of its own or not.
    Invented { name: String, seq: u32, signed: bool },
    /// A visit of a goal in a member's name, signed with a key that is not the member's.
    Forged { member: usize, seq: u32 },
    /// A genuine message the victim received already (the sender's current session).
    Replay { pick: usize },
    /// A genuine message with one bit flipped.
    Flip { pick: usize, bit: usize },
    /// More than the message limit.
    Oversized { member: usize, extra: usize },
}

fn hostile() -> impl Strategy<Value = Hostile> {
    let name = "[a-z0-9_]{1,24}";
    prop_oneof![
        (name, prop::collection::vec(any::<u8>(), 0..200)).prop_map(|(from, bytes)| Hostile::Garbage { from, bytes }),
        (name, any::<u32>(), any::<bool>()).prop_map(|(name, seq, signed)| Hostile::Invented { name, seq, signed }),
        (0..3usize, any::<u32>()).prop_map(|(member, seq)| Hostile::Forged { member, seq }),
        any::<usize>().prop_map(|pick| Hostile::Replay { pick }),
        (any::<usize>(), any::<usize>()).prop_map(|(pick, bit)| Hostile::Flip { pick, bit }),
        (0..3usize, 1..64usize).prop_map(|(member, extra)| Hostile::Oversized { member, extra }),
    ]
}

fn message(from: &str, seq: u32, records: Vec<Record>, signer: Option<u8>) -> Vec<u8> {
    let mut msg = SyncMessage {
        from: id(from),
        to: id("ugv2"),
        seq: seq.max(1),
        ack: Default::default(),
        peer_has_all: true,
        wants_ack: true,
        records,
        session: u64::MAX,
        signature: None,
    };
    if let Some(seed) = signer {
        msg.signature = Some(Signature([seed; 64]));
        for r in &mut msg.records {
            r.sig = Some(Box::new(Signature([seed; 64])));
        }
    }
    msg.encode()
}

fn visit(by: &str) -> Record {
    Record {
        key: RecordKey::Visit { goal: spomp_core::GoalId { origin: id("ugv1"), seq: 0 }, robot: id(by) },
        dot: 1,
        body: RecordBody::Visit(VisitRecord { stamp: t(5.0) }),
        sig: None,
    }
}

/// The sender the victim is told a hostile message comes from, and its bytes.
fn build(h: &Hostile, seen: &[(String, Vec<u8>)]) -> (String, Vec<u8>) {
    match h {
        Hostile::Garbage { from, bytes } => (from.clone(), bytes.clone()),
        Hostile::Invented { name, seq, signed } => {
            (name.clone(), message(name, *seq, vec![visit(name)], signed.then_some(9)))
        }
        Hostile::Forged { member, seq } => {
            let name = MEMBERS[*member].0;
            (name.to_string(), message(name, *seq, vec![visit(name)], Some(7)))
        }
        Hostile::Replay { pick } => seen[pick % seen.len()].clone(),
        Hostile::Flip { pick, bit } => {
            let (from, mut bytes) = seen[pick % seen.len()].clone();
            let i = (bit / 8) % bytes.len();
            bytes[i] ^= 1 << (bit % 8);
            (from, bytes)
        }
        Hostile::Oversized { member, extra } => {
            let name = MEMBERS[*member].0;
            let mut bytes = message(name, 1, vec![], Some(3));
            bytes.resize(MAX_MESSAGE_BYTES + extra, 0);
            (name.to_string(), bytes)
        }
    }
}

/// Regression (issue 36): a genuine message of the sender's current session, delivered again,
/// was taken (and its old acknowledgement processed) instead of being refused as a replay.
#[test]
fn a_replay_of_the_current_session_is_refused() {
    let (_, mut ugv2, _, seen) = honest_team();
    for (from, bytes) in &seen {
        let err = ugv2.apply_bytes(&id(from), bytes).unwrap_err();
        assert!(matches!(err, SyncError::Replayed { .. }), "{from}: {err}");
        assert_eq!(err.kind(), "replayed");
    }
}

/// A restarted sender's numbering starts again in a new session (taken), and a robot that
/// forgets a peer (the peer restarted) keeps numbering its own messages upwards, so the peer
/// never takes them for replays.
#[test]
fn numbering_survives_restarts_on_either_side() {
    let (mut ugv1, mut ugv2, _, _) = honest_team();
    // ugv1 reboots: a fresh state with a newer session, numbering from 1 again.
    let mut reborn = secured("ugv1");
    reborn.set_session(5000);
    reborn.identify_goal(Point2::new(-30.0, 5.0), GoalOrigin::Detected, t(9.0)).unwrap();
    let report =
        ugv2.apply_bytes(&id("ugv1"), &reborn.make_sync(&id("ugv2"), TierSet::ALL, usize::MAX).unwrap().encode());
    assert!(report.unwrap().peer_restarted);
    // ugv2 forgot what it knew of ugv1's messages, not its own numbering towards ugv1: the old
    // ugv1 (still running in this test) takes ugv2's next message.
    ugv2.set_pose(Pose2::new(7.0, 7.0, 0.0), t(9.0)).unwrap();
    let next = ugv2.make_sync(&id("ugv1"), TierSet::ALL, usize::MAX).unwrap();
    assert!(next.seq > 1, "numbering restarted at {}", next.seq);
    ugv1.apply_bytes(&id("ugv2"), &next.encode()).unwrap();
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 64, ..ProptestConfig::default() })]

    /// The bound: a flood adds no entry to any table of the victim (records, change log,
    /// scans, peers, the peers' in-flight/sent/pending entries) — its size after any number
    /// of hostile messages is its size before — and every one of them is refused. What it
    /// holds, what it tells each teammate next and how it takes their next messages are those
    /// of the same robot without the flood.
    #[test]
    fn a_flood_is_refused_and_leaves_every_table_as_it_was(flood in prop::collection::vec(hostile(), 1..120)) {
        let (mut ugv1, victim, mut uav, seen) = honest_team();
        let mut attacked = victim.clone();
        let mut quiet = victim;
        let sizes = attacked.table_sizes();
        for h in &flood {
            let (from, bytes) = build(h, &seen);
            let result = attacked.apply_bytes(&id(&from), &bytes);
            prop_assert!(result.is_err(), "{h:?} was taken: {result:?}");
            prop_assert_eq!(attacked.table_sizes(), sizes, "after {:?}", h);
        }
        prop_assert!(attacked.same_records(&quiet));
        // The members' side is untouched: the next genuine exchange goes exactly as without
        // the flood (signatures are deterministic, so equal messages encode equally).
        ugv1.set_pose(Pose2::new(50.0, 1.0, 0.0), t(20.0)).unwrap();
        let from_ugv1 = ugv1.make_sync(&id("ugv2"), TierSet::ALL, usize::MAX).unwrap().encode();
        let a = attacked.apply_bytes(&id("ugv1"), &from_ugv1);
        let q = quiet.apply_bytes(&id("ugv1"), &from_ugv1);
        prop_assert_eq!(a, q);
        for member in [ugv1.self_id().clone(), uav.self_id().clone()] {
            let a = attacked.make_sync(&member, TierSet::ALL, usize::MAX).map(|m| m.encode());
            let q = quiet.make_sync(&member, TierSet::ALL, usize::MAX).map(|m| m.encode());
            prop_assert_eq!(a, q, "to {}", member);
        }
        prop_assert!(attacked.same_records(&quiet));
        prop_assert_eq!(attacked.table_sizes(), quiet.table_sizes());
        let _ = deliver(&mut uav, &mut attacked);
    }
}
