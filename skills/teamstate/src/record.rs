//! The records of the team database.
//!
//! Every record has exactly one writer, named by its key (a claim is written only by its
//! claimant, a pose only by its robot, ...). A record carries a `dot`: the writer's logical
//! counter at the write. Merging two copies of a record keeps the one with the larger dot, and
//! breaks (only theoretically possible) ties by the bytes of the body, so the merge is a
//! join-semilattice: commutative, associative and idempotent. Immutable records (goals, visits,
//! scans) always have dot 1.

use std::cmp::Ordering;
use std::sync::Arc;

use serde::{Deserialize, Serialize};
use spomp_core::{GoalId, Point2, Pose2, ReachabilityScan, RobotId, Time};

use crate::auth::Signature;
use crate::operator::{CommandAckRecord, CommandId, OperatorCommand};

/// Priority tier of a record for sync: lower tiers go first.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
pub enum Tier {
    /// Tier 0: goals, claims, visits, unreachable marks, poses.
    Coordination = 0,
    /// Tier 1: reachability scans.
    Scans = 1,
    /// Tier 2: aerial map versions.
    Maps = 2,
}

impl Tier {
    /// Every tier, lowest first: the one place the tier list is spelled out.
    pub const ALL: [Tier; 3] = [Tier::Coordination, Tier::Scans, Tier::Maps];
}

/// A set of tiers (what a link currently allows to flow).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct TierSet(u8);

impl TierSet {
    /// Every tier.
    pub const ALL: TierSet = TierSet(0b111);
    /// No tier.
    pub const NONE: TierSet = TierSet(0);

    /// Only `tier`.
    pub const fn only(tier: Tier) -> Self {
        TierSet(1 << tier as u8)
    }

    /// Every tier up to and including `tier` (e.g. `up_to(Tier::Coordination)` for a
    /// position-only link).
    pub const fn up_to(tier: Tier) -> Self {
        TierSet((1 << (tier as u8 + 1)) - 1)
    }

    /// This set plus `tier`.
    pub const fn with(self, tier: Tier) -> Self {
        TierSet(self.0 | 1 << tier as u8)
    }

    /// Whether `tier` is in the set.
    pub const fn contains(self, tier: Tier) -> bool {
        self.0 & (1 << tier as u8) != 0
    }

    /// The tiers in both sets.
    pub const fn and(self, other: TierSet) -> Self {
        TierSet(self.0 & other.0)
    }

    /// The set as bits (bit k = tier k), the way logs and wire protocols carry it.
    pub const fn bits(self) -> u8 {
        self.0
    }

    /// The set of `bits` (bit k = tier k; bits of no tier are dropped): the inverse of
    /// [`TierSet::bits`].
    pub const fn from_bits(bits: u8) -> Self {
        TierSet(bits & TierSet::ALL.0)
    }
}

/// Key of a record. The key names the record's only writer.
#[derive(Clone, Debug, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
pub enum RecordKey {
    /// A goal; written once by `GoalId::origin`.
    Goal(GoalId),
    /// A claimant's claim (or release) of a goal; written by the claimant.
    Claim {
        /// The goal.
        goal: GoalId,
        /// The claimant.
        claimant: RobotId,
    },
    /// A robot's visit of a goal; written once by the robot.
    Visit {
        /// The goal.
        goal: GoalId,
        /// The visitor.
        robot: RobotId,
    },
    /// A robot's "unreachable for me" mark on a goal; written by the robot.
    Unreachable {
        /// The goal.
        goal: GoalId,
        /// The robot that could not reach it.
        robot: RobotId,
    },
    /// A robot's retry epoch: marks from older epochs no longer count.
    RetryEpoch(RobotId),
    /// A robot's last known pose, current goal and path end.
    Robot(RobotId),
    /// A shared reachability scan, numbered per robot.
    Scan {
        /// The robot that took it.
        robot: RobotId,
        /// Its sequence number at that robot.
        seq: u64,
    },
    /// The latest aerial-map version published by a robot.
    Map(RobotId),
    /// An operator command (issue 37); written once by the operator named in the id.
    Command(CommandId),
    /// A robot's acknowledgement that it applied an operator command; written once by the robot.
    CommandAck {
        /// The command.
        command: CommandId,
        /// The robot that applied it.
        robot: RobotId,
    },
}

impl RecordKey {
    /// The only robot that writes this record.
    pub fn writer(&self) -> &RobotId {
        match self {
            RecordKey::Goal(g) => &g.origin,
            RecordKey::Claim { claimant, .. } => claimant,
            RecordKey::Visit { robot, .. } | RecordKey::Unreachable { robot, .. } | RecordKey::Scan { robot, .. } => {
                robot
            }
            RecordKey::RetryEpoch(r) | RecordKey::Robot(r) | RecordKey::Map(r) => r,
            RecordKey::Command(c) => &c.operator,
            RecordKey::CommandAck { robot, .. } => robot,
        }
    }

    /// The sync tier of the record.
    pub fn tier(&self) -> Tier {
        match self {
            RecordKey::Scan { .. } => Tier::Scans,
            RecordKey::Map(_) => Tier::Maps,
            _ => Tier::Coordination,
        }
    }

    /// Order of record kinds within a tier when a sync message is filled: goals and their
    /// status before poses.
    pub(crate) fn send_rank(&self) -> u8 {
        match self {
            RecordKey::Goal(_) => 0,
            RecordKey::Visit { .. } => 1,
            RecordKey::Claim { .. } => 2,
            RecordKey::Unreachable { .. } => 3,
            RecordKey::RetryEpoch(_) => 4,
            RecordKey::Robot(_) => 5,
            RecordKey::Scan { .. } => 6,
            RecordKey::Map(_) => 7,
            // Operator commands go first (a cancel before the claims it overrides); the
            // acknowledgements with the other status records.
            RecordKey::Command(_) => 0,
            RecordKey::CommandAck { .. } => 4,
        }
    }

    /// Whether records of this key are immutable (only ever written once, dot 1).
    pub fn is_immutable(&self) -> bool {
        matches!(
            self,
            RecordKey::Goal(_)
                | RecordKey::Visit { .. }
                | RecordKey::Scan { .. }
                | RecordKey::Command(_)
                | RecordKey::CommandAck { .. }
        )
    }

    /// The goal a goal-status record refers to.
    pub fn goal(&self) -> Option<&GoalId> {
        match self {
            RecordKey::Goal(g)
            | RecordKey::Claim { goal: g, .. }
            | RecordKey::Visit { goal: g, .. }
            | RecordKey::Unreachable { goal: g, .. } => Some(g),
            _ => None,
        }
    }
}

/// Where a goal came from.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
pub enum GoalOrigin {
    /// Detected in the aerial map by a robot.
    Detected,
    /// Listed in the mission file.
    Mission,
    /// Sent by the basestation (operator).
    Basestation,
    /// Added by an operator command during the mission ([`crate::OperatorAction::AddGoal`]).
    Operator,
}

/// An identified goal (immutable).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct GoalRecord {
    /// Map-frame position.
    pub position: Point2,
    /// Where the goal came from.
    pub origin: GoalOrigin,
    /// When it was identified.
    pub identified_at: Time,
}

/// A claimant's latest claim or release of a goal.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ClaimRecord {
    /// True for a claim, false for a release.
    pub active: bool,
    /// The claimant's priority (lower number = higher priority).
    pub priority: u32,
    /// When the claim (or release) was made.
    pub stamp: Time,
}

/// A robot's visit of a goal (immutable).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct VisitRecord {
    /// When the robot reached the goal.
    pub stamp: Time,
}

/// A robot's "unreachable" mark on a goal.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct UnreachableRecord {
    /// The robot's retry epoch when it marked the goal; the mark counts while the robot's
    /// current epoch equals it.
    pub epoch: u64,
    /// When the goal was marked.
    pub stamp: Time,
}

/// A robot's last known state.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RobotRecord {
    /// Map-frame pose (None until the robot published one).
    pub pose: Option<Pose2>,
    /// When the pose was measured.
    pub stamp: Time,
    /// The robot's priority (lower = higher).
    pub priority: u32,
    /// The goal it is heading to.
    pub current_goal: Option<GoalId>,
    /// End of its current global path, if it published one.
    pub path_end: Option<Point2>,
}

/// One version of the aerial map, as opaque compressed layers (from `spomp-mapping`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct MapVersion {
    /// The map's version at its origin.
    pub version: u64,
    /// When it was published.
    pub stamp: Time,
    /// The compressed layers.
    pub blob: Arc<Vec<u8>>,
}

/// The content of a record; its variant matches the key's.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub enum RecordBody {
    /// For [`RecordKey::Goal`].
    Goal(GoalRecord),
    /// For [`RecordKey::Claim`].
    Claim(ClaimRecord),
    /// For [`RecordKey::Visit`].
    Visit(VisitRecord),
    /// For [`RecordKey::Unreachable`].
    Unreachable(UnreachableRecord),
    /// For [`RecordKey::RetryEpoch`]: the robot's current epoch.
    RetryEpoch(u64),
    /// For [`RecordKey::Robot`]. Boxed: it is the largest body, and every robot holds a record
    /// of every other record kind for each scan of the team, so the body's size is paid per
    /// record per robot.
    Robot(Box<RobotRecord>),
    /// For [`RecordKey::Scan`].
    Scan(Arc<ReachabilityScan>),
    /// For [`RecordKey::Map`].
    Map(MapVersion),
    /// For [`RecordKey::Command`]. Boxed: rare, and larger than the other bodies.
    Command(Box<OperatorCommand>),
    /// For [`RecordKey::CommandAck`].
    CommandAck(CommandAckRecord),
}

/// A record: key, the writer's counter at the write, and content.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Record {
    /// What the record is about (and who writes it).
    pub key: RecordKey,
    /// The writer's logical counter at the write (1 for immutable records).
    pub dot: u64,
    /// The content.
    pub body: RecordBody,
    /// The writer's signature over key, dot and body (a secured team; see [`crate::auth`]).
    /// Not part of the record's encoding: a signed sync message carries it in its trailer.
    /// Boxed: most teams sign nothing, and an inline signature would add 64 bytes to every
    /// record every robot holds.
    #[serde(skip)]
    pub sig: Option<Box<Signature>>,
}

/// Largest dot accepted from a peer. A writer that wrote a million records a second would need
/// nine years to reach it; a larger one is a corrupt or hostile counter, and taking it over
/// (a robot continues above a relayed copy of its own record) would bring the robot's own
/// counter close to overflow.
pub const MAX_DOT: u64 = 1 << 48;

/// Limits applied when validating records from peers.
pub(crate) struct Limits {
    pub max_scan_bins: usize,
    pub max_map_blob_bytes: usize,
}

fn finite_point(p: &Point2) -> bool {
    p.x.is_finite() && p.y.is_finite()
}

pub(crate) fn finite_pose(p: &Pose2) -> bool {
    p.x.is_finite() && p.y.is_finite() && p.yaw.is_finite()
}

/// Checks a scan's shape and values.
pub(crate) fn check_scan(scan: &ReachabilityScan, max_bins: usize) -> Result<(), String> {
    if !scan.is_consistent() {
        return Err("scan bins are empty or range/obstacle lengths differ".into());
    }
    if scan.bins() > max_bins {
        return Err(format!("scan has {} bins, more than {max_bins}", scan.bins()));
    }
    if !finite_pose(&scan.pose) {
        return Err("scan pose is not finite".into());
    }
    if scan.range_m.iter().any(|r| !r.is_finite() || *r < 0.0) {
        return Err("scan ranges must be finite and ≥ 0".into());
    }
    Ok(())
}

impl Record {
    /// The record's tier.
    pub fn tier(&self) -> Tier {
        self.key.tier()
    }

    /// Whether the record is immutable (only ever written once, dot 1).
    pub fn is_immutable(&self) -> bool {
        self.key.is_immutable()
    }

    /// Checks that key and body agree and that values are sane.
    pub(crate) fn validate(&self, limits: &Limits) -> Result<(), String> {
        if self.dot == 0 {
            return Err("dot 0".into());
        }
        if self.dot > MAX_DOT {
            return Err(format!("dot {} is beyond any real writer's counter (at most {MAX_DOT})", self.dot));
        }
        if self.is_immutable() && self.dot != 1 {
            return Err("immutable record with dot ≠ 1".into());
        }
        match (&self.key, &self.body) {
            (RecordKey::Goal(_), RecordBody::Goal(g)) => {
                if !finite_point(&g.position) {
                    return Err("goal position is not finite".into());
                }
            }
            (RecordKey::Claim { .. }, RecordBody::Claim(_))
            | (RecordKey::Visit { .. }, RecordBody::Visit(_))
            | (RecordKey::Unreachable { .. }, RecordBody::Unreachable(_))
            | (RecordKey::RetryEpoch(_), RecordBody::RetryEpoch(_)) => {}
            (RecordKey::Robot(_), RecordBody::Robot(r)) => {
                if !r.pose.as_ref().is_none_or(finite_pose) || !r.path_end.as_ref().is_none_or(finite_point) {
                    return Err("robot pose or path end is not finite".into());
                }
            }
            (RecordKey::Scan { robot, .. }, RecordBody::Scan(s)) => {
                if &s.robot != robot {
                    return Err("scan robot differs from its key".into());
                }
                check_scan(s, limits.max_scan_bins)?;
            }
            (RecordKey::Map(_), RecordBody::Map(m)) => {
                if m.blob.len() > limits.max_map_blob_bytes {
                    return Err(format!("map blob of {} bytes is too large", m.blob.len()));
                }
            }
            (RecordKey::Command(_), RecordBody::Command(c)) => c.validate()?,
            (RecordKey::CommandAck { .. }, RecordBody::CommandAck(_)) => {}
            _ => return Err("key and body kinds differ".into()),
        }
        Ok(())
    }
}

/// The time a record's body carries, if any (what a peer's clock said when it wrote it).
pub(crate) fn record_stamp(body: &RecordBody) -> Option<Time> {
    match body {
        RecordBody::Goal(g) => Some(g.identified_at),
        RecordBody::Claim(c) => Some(c.stamp),
        RecordBody::Visit(v) => Some(v.stamp),
        RecordBody::Unreachable(u) => Some(u.stamp),
        RecordBody::Robot(r) => Some(r.stamp),
        RecordBody::Map(m) => Some(m.stamp),
        RecordBody::CommandAck(a) => Some(a.stamp),
        // An operator's clock (a laptop's wall time) need not be the robots': the issue time
        // is for the log only, no lease depends on it, so it is never judged.
        RecordBody::RetryEpoch(_) | RecordBody::Scan(_) | RecordBody::Command(_) => None,
    }
}

/// A record filed in a [`RecordSet`]: ordered, compared and looked up by its key alone.
#[derive(Clone, Debug)]
struct Filed(Record);

impl PartialEq for Filed {
    fn eq(&self, other: &Self) -> bool {
        self.0.key == other.0.key
    }
}

impl Eq for Filed {}

impl PartialOrd for Filed {
    fn partial_cmp(&self, other: &Self) -> Option<Ordering> {
        Some(self.cmp(other))
    }
}

impl Ord for Filed {
    fn cmp(&self, other: &Self) -> Ordering {
        self.0.key.cmp(&other.0.key)
    }
}

impl std::borrow::Borrow<RecordKey> for Filed {
    fn borrow(&self) -> &RecordKey {
        &self.0.key
    }
}

/// The records a robot holds, one per key, in key order. A set of records ordered by their
/// own key rather than a map from key to record: the key is held once, not twice (48 bytes of
/// each record every robot holds, for every scan of the team).
#[derive(Clone, Debug, Default)]
pub(crate) struct RecordSet(std::collections::BTreeSet<Filed>);

impl RecordSet {
    /// The record of `key`.
    pub fn get(&self, key: &RecordKey) -> Option<&Record> {
        self.0.get(key).map(|f| &f.0)
    }

    /// How many records are held.
    pub fn len(&self) -> usize {
        self.0.len()
    }

    /// Whether a record of `key` is held.
    pub fn contains_key(&self, key: &RecordKey) -> bool {
        self.0.contains(key)
    }

    /// Stores `rec`, replacing the record of its key.
    pub fn insert(&mut self, rec: Record) {
        self.0.replace(Filed(rec));
    }

    /// Every record, in key order.
    pub fn values(&self) -> impl Iterator<Item = &Record> {
        self.0.iter().map(|f| &f.0)
    }

    /// The records from `key` on, in key order.
    pub fn starting_at(&self, key: RecordKey) -> impl Iterator<Item = &Record> {
        self.0.range::<RecordKey, _>(key..).map(|f| &f.0)
    }

    /// Changes every record with `update` (keys unchanged).
    pub fn update_all(&mut self, mut update: impl FnMut(&mut Record)) {
        let records = std::mem::take(&mut self.0);
        self.0 = records
            .into_iter()
            .map(|mut f| {
                update(&mut f.0);
                f
            })
            .collect();
    }
}

impl PartialEq for RecordSet {
    /// The same records, bodies, dots and signatures included.
    fn eq(&self, other: &Self) -> bool {
        self.0.len() == other.0.len() && self.values().eq(other.values())
    }
}

/// Total order of two copies of the same record: larger dot wins; equal dots with different
/// bodies (a writer that lost its counter) are ordered by their encoded bytes.
pub(crate) fn compare_copies(a: &Record, b: &Record) -> Ordering {
    match a.dot.cmp(&b.dot) {
        Ordering::Equal if a.body != b.body => {
            let ea = postcard::to_stdvec(&a.body).unwrap_or_default();
            let eb = postcard::to_stdvec(&b.body).unwrap_or_default();
            ea.cmp(&eb)
        }
        other => other,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tier_sets() {
        assert!(TierSet::ALL.contains(Tier::Maps));
        assert!(!TierSet::NONE.contains(Tier::Coordination));
        let coord = TierSet::up_to(Tier::Coordination);
        assert!(coord.contains(Tier::Coordination) && !coord.contains(Tier::Scans));
        assert_eq!(TierSet::up_to(Tier::Maps), TierSet::ALL);
        assert_eq!(TierSet::only(Tier::Scans).with(Tier::Maps), TierSet(0b110));
    }

    #[test]
    fn tier_bits_round_trip_and_name_each_tier_by_its_number() {
        for bits in 0..=u8::MAX {
            let set = TierSet::from_bits(bits);
            for t in Tier::ALL {
                assert_eq!(set.contains(t), bits & (1 << t as u8) != 0);
            }
            assert_eq!(TierSet::from_bits(set.bits()), set);
            assert_eq!(set.bits(), bits & 0b111, "bits of no tier are dropped");
        }
        assert_eq!(Tier::ALL.iter().fold(TierSet::NONE, |s, t| s.with(*t)), TierSet::ALL);
    }

    #[test]
    fn keys_name_their_writer_and_tier() {
        let goal = GoalId { origin: RobotId::new("ugv1"), seq: 3 };
        let claim = RecordKey::Claim { goal: goal.clone(), claimant: RobotId::new("ugv2") };
        assert_eq!(claim.writer().as_str(), "ugv2");
        assert_eq!(RecordKey::Goal(goal.clone()).writer().as_str(), "ugv1");
        assert_eq!(claim.tier(), Tier::Coordination);
        assert_eq!(RecordKey::Scan { robot: RobotId::new("a"), seq: 0 }.tier(), Tier::Scans);
        assert_eq!(RecordKey::Map(RobotId::new("uav")).tier(), Tier::Maps);
        assert_eq!(claim.goal(), Some(&goal));
    }

    #[test]
    fn copies_order_by_dot_then_bytes() {
        let key = RecordKey::RetryEpoch(RobotId::new("a"));
        let rec = |dot, epoch| Record { key: key.clone(), dot, body: RecordBody::RetryEpoch(epoch), sig: None };
        assert!(compare_copies(&rec(2, 0), &rec(1, 9)).is_gt());
        assert!(compare_copies(&rec(1, 1), &rec(1, 1)).is_eq());
        let (a, b) = (rec(1, 1), rec(1, 2));
        assert_eq!(compare_copies(&a, &b), compare_copies(&b, &a).reverse());
        assert!(!compare_copies(&a, &b).is_eq());
    }
}
