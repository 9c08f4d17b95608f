//! Helpers shared by the integration tests.
#![allow(dead_code, clippy::unwrap_used)]

use spomp_core::{Pose2, ReachabilityScan, RobotId, Time};
use spomp_teamstate::{TeamState, TeamStateParams, TierSet};

pub fn id(s: &str) -> RobotId {
    RobotId::new(s)
}

pub fn robot(name: &str, priority: u32) -> TeamState {
    TeamState::new(id(name), priority, TeamStateParams::default()).unwrap()
}

pub fn t(secs: f64) -> Time {
    Time::from_secs_f64(secs)
}

pub fn scan(robot: &str, x: f64, y: f64, stamp: f64) -> ReachabilityScan {
    ReachabilityScan {
        robot: id(robot),
        stamp: t(stamp),
        pose: Pose2::new(x, y, 0.0),
        range_m: vec![3.5; 64],
        obstacle: vec![false; 64],
    }
}

/// One message from `a` to `b` through the wire format; returns whether one was sent.
pub fn send(a: &mut TeamState, b: &mut TeamState) -> bool {
    let to = b.self_id().clone();
    match a.make_sync(&to, TierSet::ALL, usize::MAX) {
        Some(msg) => {
            let bytes = msg.encode();
            b.apply_bytes(&a.self_id().clone(), &bytes).unwrap();
            true
        }
        None => false,
    }
}

/// Exchanges messages both ways until neither side has anything to say.
pub fn sync_fully(a: &mut TeamState, b: &mut TeamState) {
    for _ in 0..20 {
        let x = send(a, b);
        let y = send(b, a);
        if !x && !y {
            return;
        }
    }
    panic!("sync did not quiesce");
}
