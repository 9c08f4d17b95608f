//! A robot's team database as bytes, so a robot that reboots mid-mission resumes with the goals,
//! claims and visits it knew (the adapter writes them to a file atomically; see `spomp-zenoh`).
//!
//! Format: the 8 bytes `SPTSNAP1`, then [postcard](https://docs.rs/postcard). Restoring trusts
//! nothing: the snapshot must be this robot's, of this team, and every record is validated as if
//! a peer had sent it (and its signature checked on a secured team), so a corrupt, foreign or
//! edited file is refused as a whole.

use serde::{Deserialize, Serialize};
use spomp_core::{Point2, RobotId};

use crate::auth::Signature;
use crate::record::{Limits, Record, RecordBody, RecordKey};
use crate::state::{TeamState, record_bytes};

const MAGIC: &[u8; 8] = b"SPTSNAP1";

/// Why a snapshot was refused. Nothing of it was taken.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SnapshotError {
    /// Not a snapshot, or cut short, or damaged.
    #[error("not a team-state snapshot, or a damaged one: {0}")]
    Malformed(String),
    /// Another robot's snapshot.
    #[error("the snapshot is robot {found}'s, not {expected}'s")]
    OtherRobot {
        /// The robot restoring.
        expected: String,
        /// The robot the snapshot belongs to.
        found: String,
    },
    /// Another team's snapshot (secured teams name themselves).
    #[error("the snapshot is of team `{found}`, not `{expected}`")]
    OtherTeam {
        /// The team of the robot restoring.
        expected: String,
        /// The team named in the snapshot.
        found: String,
    },
    /// A record fails validation or its signature does not check.
    #[error("record {index} of the snapshot is not to be trusted: {reason}")]
    BadRecord {
        /// Position of the record in the snapshot.
        index: usize,
        /// What is wrong.
        reason: String,
    },
}

#[derive(Serialize, Deserialize)]
struct Snapshot {
    robot: RobotId,
    team: Option<String>,
    clock: u64,
    next_goal_seq: u32,
    next_scan_seq: u64,
    own_scan_positions: Vec<Point2>,
    records: Vec<Record>,
    sigs: Vec<Option<Signature>>,
}

/// What a restore brought back.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RestoreSummary {
    /// Records taken.
    pub records: usize,
    /// Goals known (deduplicated).
    pub goals: usize,
    /// This robot's active claims.
    pub own_claims: usize,
}

impl TeamState {
    /// This database as bytes (see the module doc); what is known of peers is not kept: after a
    /// restore everything is offered to them again.
    pub fn snapshot(&self) -> Vec<u8> {
        let records: Vec<Record> = self.records().cloned().collect();
        let snap = Snapshot {
            robot: self.self_id().clone(),
            team: self.security().map(|s| s.keys().team().to_string()),
            clock: self.counters().0,
            next_goal_seq: self.counters().1,
            next_scan_seq: self.counters().2,
            // (counters: this robot's dot, next goal number, next scan number)
            own_scan_positions: self.own_scan_positions().to_vec(),
            sigs: records.iter().map(|r| r.sig.as_deref().copied()).collect(),
            records,
        };
        // Plain data into a Vec does not fail; if it ever did, the bare magic is refused on
        // restore.
        postcard::to_extend(&snap, MAGIC.to_vec()).unwrap_or_else(|_| MAGIC.to_vec())
    }

    /// Takes the records and counters of `bytes` (made by [`TeamState::snapshot`] of this robot
    /// before a restart) into this database, which must be fresh (nothing written yet) and
    /// secured as it will run. Refused as a whole when the snapshot is not this robot's, not
    /// this team's, damaged, or holds a record that fails validation or its signature.
    pub fn restore(&mut self, bytes: &[u8]) -> Result<RestoreSummary, SnapshotError> {
        let payload = bytes
            .strip_prefix(MAGIC.as_slice())
            .ok_or_else(|| SnapshotError::Malformed("it does not start with SPTSNAP1".into()))?;
        let snap: Snapshot = postcard::from_bytes(payload).map_err(|e| SnapshotError::Malformed(e.to_string()))?;
        if &snap.robot != self.self_id() {
            return Err(SnapshotError::OtherRobot {
                expected: self.self_id().to_string(),
                found: snap.robot.to_string(),
            });
        }
        let team = self.security().map(|s| s.keys().team().to_string());
        if snap.team != team {
            return Err(SnapshotError::OtherTeam {
                expected: team.unwrap_or_else(|| "(unsecured)".into()),
                found: snap.team.unwrap_or_else(|| "(unsecured)".into()),
            });
        }
        if snap.sigs.len() != snap.records.len() {
            return Err(SnapshotError::Malformed("signature and record counts differ".into()));
        }
        let limits =
            Limits { max_scan_bins: self.params().max_scan_bins, max_map_blob_bytes: self.params().max_map_blob_bytes };
        let mut records = Vec::with_capacity(snap.records.len());
        for (index, (mut rec, sig)) in snap.records.into_iter().zip(snap.sigs).enumerate() {
            let bad = |reason: String| SnapshotError::BadRecord { index, reason };
            rec.validate(&limits).map_err(bad)?;
            rec.sig = sig.map(Box::new);
            if let Some(security) = self.security() {
                let writer = rec.key.writer();
                let mission = writer.as_str() == crate::state::MISSION_WRITER;
                let checks = mission
                    || rec.sig.as_ref().is_some_and(|s| security.record_signed_by(writer, &record_bytes(&rec), s));
                if !checks {
                    return Err(bad(format!("{writer}'s signature does not check")));
                }
            }
            records.push(rec);
        }
        let counters = (snap.clock.min(crate::record::MAX_DOT), snap.next_goal_seq, snap.next_scan_seq);
        let summary = self.take_restored(records, counters, snap.own_scan_positions);
        Ok(summary)
    }
}

impl TeamState {
    /// Inserts restored records (validated) and counters.
    fn take_restored(
        &mut self,
        records: Vec<Record>,
        counters: (u64, u32, u64),
        own_scan_positions: Vec<Point2>,
    ) -> RestoreSummary {
        let count = records.len();
        let me = self.self_id().clone();
        let mut clock = counters.0;
        for rec in records {
            if rec.key.writer() == &me && !rec.is_immutable() {
                clock = clock.max(rec.dot);
            }
            self.insert_restored(rec);
        }
        self.set_counters(clock, counters.1, counters.2, own_scan_positions);
        let own_claims = self
            .records()
            .filter(|r| {
                matches!((&r.key, &r.body), (RecordKey::Claim { claimant, .. }, RecordBody::Claim(c)) if claimant == &me && c.active)
            })
            .count();
        RestoreSummary { records: count, goals: self.goals().len(), own_claims }
    }
}
