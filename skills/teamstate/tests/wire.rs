//! The wire format and rejection of bad messages.
#![allow(clippy::unwrap_used)] // tests and benchmarks may unwrap

mod common;

use common::*;
use spomp_core::Point2;
use spomp_teamstate::{GoalOrigin, RecordBody, SyncError, SyncMessage, TeamStateParams, TierSet, decode, encode};

fn populated() -> (spomp_teamstate::TeamState, spomp_teamstate::TeamState, SyncMessage) {
    let mut a = robot("ugv1", 1);
    let b = robot("ugv2", 2);
    a.identify_goal(Point2::new(1.0, 2.0), GoalOrigin::Detected, t(1.0)).unwrap();
    a.add_scan(scan("ugv1", 0.0, 0.0, 1.0)).unwrap();
    a.add_map_version(1, t(1.0), vec![5; 40]).unwrap();
    let m = a.make_sync(&id("ugv2"), TierSet::ALL, usize::MAX).unwrap();
    (a, b, m)
}

#[test]
fn round_trip_is_exact() {
    let (_, _, m) = populated();
    let bytes = encode(&m);
    assert_eq!(&bytes[..4], b"SPTS");
    assert_eq!(decode(&bytes).unwrap(), m);
}

#[test]
fn bad_messages_are_rejected_and_change_nothing() {
    let (_, mut b, m) = populated();
    let before: Vec<_> = b.records().cloned().collect();
    let bytes = encode(&m);
    let from = id("ugv1");
    assert_eq!(b.apply_bytes(&from, b"XXXX\x01\x00"), Err(SyncError::BadHeader));
    assert_eq!(b.apply_bytes(&from, &bytes[..3]), Err(SyncError::BadHeader));
    assert!(matches!(b.apply_bytes(&from, &bytes[..bytes.len() - 1]), Err(SyncError::Malformed(_))));
    let mut trailing = bytes.clone();
    trailing.push(0);
    assert!(matches!(b.apply_bytes(&from, &trailing), Err(SyncError::Malformed(_))));
    assert!(matches!(b.apply_bytes(&id("uav"), &bytes), Err(SyncError::WrongAddress { .. })));

    let small = TeamStateParams { max_message_bytes: 100, ..TeamStateParams::default() };
    let mut tiny = spomp_teamstate::TeamState::new(id("ugv2"), 2, small).unwrap();
    assert!(matches!(tiny.apply_bytes(&from, &bytes), Err(SyncError::Oversized { .. })));

    // Inconsistent record: a goal key with a scan body, after a valid record.
    let mut bad = m.clone();
    let scan_body = bad.records.iter().find(|r| matches!(r.body, RecordBody::Scan(_))).unwrap().body.clone();
    let last = bad.records.len() - 1;
    bad.records[last].body = scan_body;
    assert!(matches!(b.apply(&from, &bad), Err(SyncError::InvalidRecord { .. })));
    // Non-finite goal position.
    let mut nan = m.clone();
    if let RecordBody::Goal(g) = &mut nan.records[0].body {
        g.position.x = f64::NAN;
    }
    assert!(matches!(b.apply(&from, &nan), Err(SyncError::InvalidRecord { index: 0, .. })));
    let after: Vec<_> = b.records().cloned().collect();
    assert_eq!(before, after);
    assert!(b.apply(&from, &m).is_ok(), "the intact message still applies");
}

#[test]
fn invalid_params_are_rejected() {
    let p = TeamStateParams { deconfliction_radius_m: f64::NAN, ..TeamStateParams::default() };
    assert!(spomp_teamstate::TeamState::new(id("a"), 0, p).is_err());
    let p = TeamStateParams { max_in_flight_messages: 65, ..TeamStateParams::default() };
    assert!(spomp_teamstate::TeamState::new(id("a"), 0, p).is_err());
    let json = r#"{"deconfliction_radius_m": 12.0}"#;
    let p: TeamStateParams = serde_json::from_str(json).unwrap();
    assert_eq!((p.deconfliction_radius_m, p.scan_min_spacing_m), (12.0, 2.0));
    assert!(serde_json::from_str::<TeamStateParams>(r#"{"radius": 1}"#).is_err());
}

#[test]
fn bytes_by_tier_split_the_whole_message_by_what_its_records_are() {
    let (_, _, m) = populated();
    let bytes = encode(&m);
    let [coordination, scans, maps] = m.bytes_by_tier(bytes.len());
    assert_eq!(coordination + scans + maps, bytes.len() as u64, "every byte is counted once");
    // The map version carries 40 bytes of raster, the scan its ranges; the goal and the pose
    // records and the header are coordination.
    assert!(maps >= 40, "maps {maps}");
    assert!(scans > 0 && coordination > 0, "scans {scans}, coordination {coordination}");
    // Without the scan and the map, everything is coordination.
    let mut only_goals = m.clone();
    only_goals.records.retain(|r| r.tier() == spomp_teamstate::Tier::Coordination);
    let len = encode(&only_goals).len();
    assert_eq!(only_goals.bytes_by_tier(len), [len as u64, 0, 0]);
}

#[test]
fn a_message_never_exceeds_the_limit_receivers_enforce_however_large_the_budget() {
    // Regression: with link credit carried over (up to 32 MB) a sync message could outgrow
    // max_message_bytes (16 MB by default) and be refused whole by every receiver.
    let params = TeamStateParams { max_message_bytes: 3_000, ..TeamStateParams::default() };
    let mut a = spomp_teamstate::TeamState::new(id("ugv1"), 1, params.clone()).unwrap();
    let mut b = spomp_teamstate::TeamState::new(id("ugv2"), 2, params).unwrap();
    for i in 0..12 {
        a.add_scan(scan("ugv1", 3.0 * i as f64, 0.0, i as f64)).unwrap();
    }
    let mut messages = 0;
    while let Some(m) = a.make_sync(&id("ugv2"), TierSet::ALL, usize::MAX) {
        let bytes = encode(&m);
        assert!(bytes.len() <= 3_000, "{} bytes", bytes.len());
        b.apply_bytes(&id("ugv1"), &bytes).unwrap();
        if let Some(back) = b.make_sync(&id("ugv1"), TierSet::ALL, usize::MAX) {
            a.apply(&id("ugv2"), &back).unwrap();
        }
        messages += 1;
        assert!(messages < 100, "the sync does not end");
    }
    assert!(messages > 1, "the scans needed more than one message");
    assert_eq!(b.records().filter(|r| matches!(r.body, RecordBody::Scan(_))).count(), 12);
}
