//! The team database of one robot.

use std::collections::{BTreeMap, HashMap};
use std::sync::Arc;

use spomp_core::{GoalId, Point2, Pose2, ReachabilityScan, RobotId, Time};

use crate::auth::SIGNATURE_BYTES;
use crate::auth::TeamSecurity;
use crate::error::{SyncError, TeamStateError};
use crate::intern::{KeyNo, key_no, with_keys};
use crate::params::TeamStateParams;
use crate::record::{
    ClaimRecord, GoalOrigin, GoalRecord, Limits, MapVersion, Record, RecordBody, RecordKey, RecordSet, RobotRecord,
    Tier, TierSet, UnreachableRecord, VisitRecord, check_scan, finite_pose, record_stamp,
};
use crate::sync::{HEADER_BYTES, InFlight, PeerState, SyncMessage};
use crate::view::{GoalIndex, GoalView, Lease, build_goal_index};

/// Writer name of goals listed in the mission file: every robot loads them identically.
pub const MISSION_WRITER: &str = "mission";

/// Result of [`TeamState::identify_goal`].
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum IdentifyOutcome {
    /// A new goal was added.
    New(GoalId),
    /// A known goal lies within the deconfliction radius; nothing was added.
    Existing(GoalId),
}

impl IdentifyOutcome {
    /// The id of the goal, new or existing.
    pub fn id(&self) -> &GoalId {
        match self {
            IdentifyOutcome::New(id) | IdentifyOutcome::Existing(id) => id,
        }
    }
}

/// Result of [`TeamState::claim`].
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ClaimOutcome {
    /// Canonical id of the claimed goal.
    pub goal: GoalId,
}

/// What applying a sync message did.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ApplyReport {
    /// Records that changed this robot's state.
    pub records_changed: usize,
    /// Records already known (duplicates, stale copies).
    pub records_ignored: usize,
    /// Goals this robot released because it learned that a higher-priority robot claims them or
    /// someone visited them (canonical ids).
    pub released: Vec<GoalId>,
    /// Goals new to this robot (canonical ids as of after the merge).
    pub new_goals: Vec<GoalId>,
    /// Reachability scans new to this robot.
    pub new_scans: usize,
    /// Map origins whose version this robot did not have.
    pub new_maps: Vec<RobotId>,
    /// Records left out because their stamp lies further in the future than
    /// [`TeamStateParams::max_clock_ahead_s`] (the rest of the message was applied).
    pub records_from_the_future: usize,
    /// The sender started a new session (it restarted): what was known of its messages was
    /// forgotten before this one was applied.
    pub peer_restarted: bool,
}

/// Entry counts of a team database's tables ([`TeamState::table_sizes`]). Each grows only with
/// records that passed validation (and, on a secured team, every signature check) or with
/// peers this robot syncs with; a refused message adds to none of them.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct TableSizes {
    /// Records held.
    pub records: usize,
    /// Change-log entries (one per record at most).
    pub change_log: usize,
    /// Scans in arrival order.
    pub scans: usize,
    /// Peers with sync state: senders of accepted messages and addressees of `make_sync`.
    pub peers: usize,
    /// Entries of the peers' tables: messages in flight, records sent and pending.
    pub peer_entries: usize,
}

/// A robot's last known state, as recorded in the team state.
pub type RobotStatus = RobotRecord;

/// The replicated team database of one robot (the paper's MOCHA role), transport-free.
///
/// Local mutations write records this robot owns; [`TeamState::make_sync`] and
/// [`TeamState::apply`] exchange records with peers; every query reads the merged state.
#[derive(Clone, Debug)]
pub struct TeamState {
    self_id: RobotId,
    priority: u32,
    params: TeamStateParams,
    /// This robot's logical counter: the dot of its last write.
    clock: u64,
    next_goal_seq: u32,
    next_scan_seq: u64,
    records: RecordSet,
    goal_index: GoalIndex,
    /// Scans in local arrival order, for `scans_since`.
    scan_log: Vec<Arc<ReachabilityScan>>,
    /// Positions of the scans this robot shared, for the spacing rule.
    own_scan_positions: Vec<Point2>,
    peers: HashMap<RobotId, PeerState>,
    /// Local change log: change number → key number, one entry per key (its latest change), so
    /// a peer only looks at what changed since it last looked.
    changes: BTreeMap<u64, KeyNo>,
    /// The change number of each mutable record (immutable ones change once: see `note_change`).
    change_of: HashMap<KeyNo, u64>,
    change_seq: u64,
    /// The latest time given to [`TeamState::advance_clock`] (claim leases are judged by it).
    now: Time,
    /// What the last look for own claims to renew found with nothing to renew: `change_seq`
    /// then, and the stamp of the oldest own active claim. While no record has changed and
    /// that claim is not yet half a lease old, none is, and the look is skipped.
    own_claims_checked: Option<(u64, Option<Time>)>,
    /// Signing key and team keys (a secured team); None believes every well-formed message.
    security: Option<Arc<TeamSecurity>>,
    /// Which boot of this robot this is (see [`SyncMessage::session`]).
    session: u64,
    /// Operator commands issued here are numbered above this (see
    /// [`TeamState::set_command_seq_floor`]).
    command_seq_floor: u32,
    /// Messages refused because of an operator record: a command signed by a key that is not
    /// the operator's, or written by a robot (a secured team).
    refused_operator_records: u64,
    /// Bumped whenever a command or acknowledgement record is stored (see
    /// [`TeamState::operator_records_version`]).
    operator_version: u64,
}

impl TeamState {
    /// An empty database for robot `self_id` with claim priority `priority` (lower = higher).
    pub fn new(self_id: RobotId, priority: u32, params: TeamStateParams) -> Result<Self, TeamStateError> {
        params.validate()?;
        Ok(TeamState {
            self_id,
            priority,
            params,
            clock: 0,
            next_goal_seq: 0,
            next_scan_seq: 0,
            records: RecordSet::default(),
            goal_index: GoalIndex::default(),
            scan_log: Vec::new(),
            own_scan_positions: Vec::new(),
            peers: HashMap::new(),
            changes: BTreeMap::new(),
            change_of: HashMap::new(),
            now: Time::ZERO,
            change_seq: 0,
            own_claims_checked: None,
            security: None,
            session: 0,
            command_seq_floor: 0,
            refused_operator_records: 0,
            operator_version: 0,
        })
    }

    /// Secures the database: from now on its own records and messages are signed, and a
    /// message is applied only if its sender and every record's writer are team members whose
    /// signatures check. Records held already are signed now if they are this robot's. Fails if
    /// the security is another robot's.
    pub fn set_security(&mut self, security: Arc<TeamSecurity>) -> Result<(), TeamStateError> {
        if security.robot() != &self.self_id {
            return Err(TeamStateError::InvalidInput(format!(
                "the signing key of {} given to the team state of {}",
                security.robot(),
                self.self_id
            )));
        }
        let me = &self.self_id;
        self.records.update_all(|rec| {
            if rec.key.writer() == me {
                rec.sig = Some(Box::new(security.sign_record(&record_bytes(rec))));
            }
        });
        self.security = Some(security);
        Ok(())
    }

    /// The security in force, if any.
    pub fn security(&self) -> Option<&TeamSecurity> {
        self.security.as_deref()
    }

    /// Sets which boot of this robot this is: a number larger than at any earlier boot (e.g. the
    /// wall-clock start time in nanoseconds, or a boot counter kept with the state file). Peers
    /// that see it grow forget what they knew of this robot's earlier messages.
    pub fn set_session(&mut self, session: u64) {
        self.session = session;
    }

    /// This robot's session.
    pub fn session(&self) -> u64 {
        self.session
    }

    /// Numbers the operator commands issued from this team state above `floor`: a short-lived
    /// operator process (a new `TeamState` per invocation) passes a number above any it used
    /// before (e.g. its wall clock in seconds since a fixed date), so two invocations never
    /// issue two commands under one id. Commands learnt from peers raise the numbering too.
    pub fn set_command_seq_floor(&mut self, floor: u32) {
        self.command_seq_floor = self.command_seq_floor.max(floor);
    }

    /// See [`TeamState::set_command_seq_floor`].
    pub fn command_seq_floor(&self) -> u32 {
        self.command_seq_floor
    }

    /// Messages this robot refused because of an operator record (issue 37): a command signed
    /// by a key other than the operator's, a command written by a robot, or another record
    /// written under an operator's id. Each also counts as a refused message of its kind.
    pub fn refused_operator_records(&self) -> u64 {
        self.refused_operator_records
    }

    /// A number that changes whenever an operator command or an acknowledgement is added to
    /// this team state (written here or merged from a peer), and only then: whoever derives
    /// something from the commands (a robot's orders and acknowledgements, a log of them)
    /// redoes it only when the number moved. It never decreases.
    pub fn operator_records_version(&self) -> u64 {
        self.operator_version
    }

    /// The records (for the operator module).
    pub(crate) fn records_set(&self) -> &RecordSet {
        &self.records
    }

    /// This robot's id.
    pub fn self_id(&self) -> &RobotId {
        &self.self_id
    }

    /// This robot's claim priority.
    pub fn priority(&self) -> u32 {
        self.priority
    }

    /// The parameters.
    pub fn params(&self) -> &TeamStateParams {
        &self.params
    }

    // ------------------------------------------------------------------ local writes

    fn tick(&mut self) -> u64 {
        // Saturates: a peer's numbers never reach here beyond MAX_DOT (validated), and a
        // counter of 2^64 − 1 local writes does not happen.
        self.clock = self.clock.saturating_add(1);
        self.clock
    }

    /// Inserts a record this robot wrote (or a mission record) and keeps derived state current.
    fn put(&mut self, key: RecordKey, dot: u64, body: RecordBody) {
        self.put_record(Record { key, dot, body, sig: None });
    }

    /// Inserts a record written here (signed now if it is this robot's and unsigned) and keeps
    /// derived state current.
    pub(crate) fn put_record(&mut self, mut rec: Record) {
        crate::intern::share_body(&rec.key, &mut rec.body);
        if let Some(security) = &self.security
            && rec.sig.is_none()
            && rec.key.writer() == &self.self_id
        {
            rec.sig = Some(Box::new(security.sign_record(&record_bytes(&rec))));
        }
        let key = rec.key.clone();
        let goal_related = changes_goals(&key);
        if let RecordBody::Scan(s) = &rec.body {
            self.scan_log.push(s.clone());
        }
        self.note_change(&key);
        self.records.insert(rec);
        if goal_related {
            self.rebuild_goals();
        }
    }

    /// Logs a change of `key`; called before the record is stored.
    fn note_change(&mut self, key: &RecordKey) {
        self.change_seq += 1;
        if matches!(key, RecordKey::Command(_) | RecordKey::CommandAck { .. }) {
            self.operator_version += 1;
        }
        let no = key_no(key);
        let earlier = if no.is_immutable() {
            // Written once, except by a writer that lost its counter (a different body under
            // the same key): the rare replacement finds its earlier entry by walking the log,
            // so the scans, most of what a robot holds, need no index entry.
            match self.records.contains_key(key) {
                true => self.changes.iter().find(|(_, k)| **k == no).map(|(seq, _)| *seq),
                false => None,
            }
        } else {
            self.change_of.insert(no, self.change_seq)
        };
        if let Some(old) = earlier {
            self.changes.remove(&old);
        }
        self.changes.insert(self.change_seq, no);
    }

    fn rebuild_goals(&mut self) {
        let lease = Lease { me: &self.self_id, now: self.now, lease_s: self.params.claim_lease_s };
        self.goal_index = build_goal_index(&self.records, self.params.deconfliction_radius_m, &lease);
    }

    /// Moves the database's clock to `now` (the robot's time; called every step by the
    /// runtime): renews this robot's claims older than half a lease, and drops from the goal
    /// views the claims of other robots whose lease ran out, so their goals become claimable.
    /// Without calls the clock stays at zero and no claim ever expires.
    pub fn advance_clock(&mut self, now: Time) {
        if now <= self.now {
            return;
        }
        self.now = now;
        let half = self.params.claim_lease_s / 2.0;
        // Age is monotonic in the stamp: if the oldest own claim is not stale, none is.
        let nothing_stale = |oldest: Option<Time>| oldest.is_none_or(|stamp| now.secs_since(stamp) <= half);
        let stale_own: Vec<(GoalId, u32)> = match self.own_claims_checked {
            Some((seq, oldest)) if seq == self.change_seq && nothing_stale(oldest) => Vec::new(),
            _ => {
                let mut oldest: Option<Time> = None;
                // Only the claim records, which sit together in key order: walking every
                // record (the team's shared scans among them) on each change was 3 % of a
                // team simulation.
                let stale: Vec<(GoalId, u32)> = self
                    .claim_records()
                    .filter_map(|r| match (&r.key, &r.body) {
                        (RecordKey::Claim { goal, claimant }, RecordBody::Claim(c))
                            if c.active && claimant == &self.self_id =>
                        {
                            oldest = Some(oldest.map_or(c.stamp, |o| o.min(c.stamp)));
                            (now.secs_since(c.stamp) > half).then(|| (goal.clone(), c.priority))
                        }
                        _ => None,
                    })
                    .collect();
                self.own_claims_checked = stale.is_empty().then_some((self.change_seq, oldest));
                stale
            }
        };
        for (goal, priority) in stale_own {
            let dot = self.tick();
            let key = RecordKey::Claim { goal, claimant: self.self_id.clone() };
            self.put(key, dot, RecordBody::Claim(ClaimRecord { active: true, priority, stamp: now }));
        }
        let lease_s = self.params.claim_lease_s;
        let expired = self
            .goal_index
            .views
            .iter()
            .flat_map(|v| &v.claims)
            .any(|c| c.robot != self.self_id && now.secs_since(c.stamp) > lease_s);
        if expired {
            self.rebuild_goals();
        }
    }

    fn own_robot_record(&self) -> RobotRecord {
        match self.records.get(&RecordKey::Robot(self.self_id.clone())).map(|r| &r.body) {
            Some(RecordBody::Robot(r)) => (**r).clone(),
            _ => RobotRecord {
                pose: None,
                stamp: Time::ZERO,
                priority: self.priority,
                current_goal: None,
                path_end: None,
            },
        }
    }

    fn write_robot(&mut self, update: impl FnOnce(&mut RobotRecord)) {
        let mut rec = self.own_robot_record();
        update(&mut rec);
        let dot = self.tick();
        self.put(RecordKey::Robot(self.self_id.clone()), dot, RecordBody::Robot(Box::new(rec)));
    }

    /// Records a goal this robot identified (detected in the aerial map, or entered at the
    /// basestation). If a known goal lies within the deconfliction radius, nothing is added and
    /// that goal is returned.
    pub fn identify_goal(
        &mut self,
        position: Point2,
        origin: GoalOrigin,
        stamp: Time,
    ) -> Result<IdentifyOutcome, TeamStateError> {
        if !(position.x.is_finite() && position.y.is_finite()) {
            return Err(TeamStateError::InvalidInput("goal position is not finite".into()));
        }
        if let Some(v) = self.goal_near(position) {
            return Ok(IdentifyOutcome::Existing(v.id.clone()));
        }
        let id = GoalId { origin: self.self_id.clone(), seq: self.next_goal_seq };
        self.next_goal_seq += 1;
        let body = RecordBody::Goal(GoalRecord { position, origin, identified_at: stamp });
        self.put(RecordKey::Goal(id.clone()), 1, body);
        self.resolve_own_conflicts();
        Ok(IdentifyOutcome::New(id))
    }

    /// Adds goal number `index` of the mission file. Every robot adds the same mission goals
    /// under the same ids (`mission/index`), so they never duplicate.
    pub fn add_mission_goal(&mut self, index: u32, position: Point2) -> Result<GoalId, TeamStateError> {
        if !(position.x.is_finite() && position.y.is_finite()) {
            return Err(TeamStateError::InvalidInput("goal position is not finite".into()));
        }
        let id = GoalId { origin: RobotId::new(MISSION_WRITER), seq: index };
        let body = RecordBody::Goal(GoalRecord { position, origin: GoalOrigin::Mission, identified_at: Time::ZERO });
        self.put(RecordKey::Goal(id.clone()), 1, body);
        self.resolve_own_conflicts();
        Ok(id)
    }

    fn view_of(&self, goal: &GoalId) -> Result<&GoalView, TeamStateError> {
        self.goal(goal).ok_or_else(|| TeamStateError::UnknownGoal(goal.clone()))
    }

    /// This robot's active claims (goal ids as written).
    fn own_active_claims(&self) -> Vec<GoalId> {
        self.records
            .values()
            .filter_map(|r| match (&r.key, &r.body) {
                (RecordKey::Claim { goal, claimant }, RecordBody::Claim(c))
                    if c.active && claimant == &self.self_id =>
                {
                    Some(goal.clone())
                }
                _ => None,
            })
            .collect()
    }

    fn write_release(&mut self, goal: GoalId, stamp: Time) {
        let dot = self.tick();
        let key = RecordKey::Claim { goal, claimant: self.self_id.clone() };
        let body = RecordBody::Claim(ClaimRecord { active: false, priority: self.priority, stamp });
        self.put(key, dot, body);
    }

    /// Releases every own claim on the goal group of `canonical` (or on all goals if None).
    fn release_own(&mut self, canonical: Option<&GoalId>, stamp: Time) -> bool {
        let mut released = false;
        for g in self.own_active_claims() {
            let in_group = match canonical {
                None => true,
                Some(c) => self.goal(&g).is_some_and(|v| &v.id == c),
            };
            if in_group {
                self.write_release(g, stamp);
                released = true;
            }
        }
        released
    }

    /// Claims a goal for this robot (it is heading there). Any other claim of this robot is
    /// released: a robot pursues one goal at a time. Fails if the goal is unknown or visited, or
    /// if a robot with higher priority holds it. Taking a goal from a lower-priority robot is
    /// allowed: that robot releases it when it learns of this claim.
    pub fn claim(&mut self, goal: &GoalId, stamp: Time) -> Result<ClaimOutcome, TeamStateError> {
        let view = self.view_of(goal)?;
        if view.status == crate::view::GoalStatus::Visited {
            return Err(TeamStateError::AlreadyVisited(view.id.clone()));
        }
        if let Some(by) = &view.cancelled {
            return Err(TeamStateError::Cancelled { goal: view.id.clone(), by: by.to_string() });
        }
        if let Some(holder) = view
            .claimant
            .as_ref()
            .filter(|c| c.robot != self.self_id && (c.priority, &c.robot) < (self.priority, &self.self_id))
        {
            return Err(TeamStateError::ClaimedByOther { goal: view.id.clone(), robot: holder.robot.clone() });
        }
        let canonical = view.id.clone();
        let others: Vec<GoalId> =
            self.own_active_claims().into_iter().filter(|g| self.goal(g).is_none_or(|v| v.id != canonical)).collect();
        for g in others {
            self.write_release(g, stamp);
        }
        let dot = self.tick();
        let key = RecordKey::Claim { goal: canonical.clone(), claimant: self.self_id.clone() };
        let body = RecordBody::Claim(ClaimRecord { active: true, priority: self.priority, stamp });
        self.put(key, dot, body);
        let c = canonical.clone();
        self.write_robot(|r| r.current_goal = Some(c));
        Ok(ClaimOutcome { goal: canonical })
    }

    /// Releases this robot's claim on a goal (and its aliases) so others may take it.
    pub fn release(&mut self, goal: &GoalId, stamp: Time) -> Result<(), TeamStateError> {
        let canonical = self.view_of(goal)?.id.clone();
        self.release_own(Some(&canonical), stamp);
        self.clear_current_goal_if(&canonical);
        Ok(())
    }

    /// Releases every claim of this robot (a recalled robot gives its goal back at once) and
    /// clears its current goal; returns whether it held any.
    pub fn release_all_claims(&mut self, stamp: Time) -> bool {
        let released = self.release_own(None, stamp);
        if self.own_robot_record().current_goal.is_some() {
            self.write_robot(|r| r.current_goal = None);
        }
        released
    }

    fn clear_current_goal_if(&mut self, canonical: &GoalId) {
        let rec = self.own_robot_record();
        let heading_there = rec
            .current_goal
            .as_ref()
            .is_some_and(|g| g == canonical || self.goal(g).is_some_and(|v| &v.id == canonical));
        if heading_there {
            self.write_robot(|r| r.current_goal = None);
        }
    }

    /// Records that this robot reached a goal; releases its claim. A visit is permanent.
    pub fn mark_visited(&mut self, goal: &GoalId, stamp: Time) -> Result<(), TeamStateError> {
        let canonical = self.view_of(goal)?.id.clone();
        let key = RecordKey::Visit { goal: canonical.clone(), robot: self.self_id.clone() };
        if !self.records.contains_key(&key) {
            self.put(key, 1, RecordBody::Visit(VisitRecord { stamp }));
        }
        self.release_own(Some(&canonical), stamp);
        self.clear_current_goal_if(&canonical);
        Ok(())
    }

    fn retry_epoch(&self, robot: &RobotId) -> u64 {
        match self.records.get(&RecordKey::RetryEpoch(robot.clone())).map(|r| &r.body) {
            Some(RecordBody::RetryEpoch(e)) => *e,
            _ => 0,
        }
    }

    /// Marks a goal unreachable for this robot (no path, failure or time limit) and releases it
    /// so others may try.
    pub fn mark_unreachable(&mut self, goal: &GoalId, stamp: Time) -> Result<(), TeamStateError> {
        let canonical = self.view_of(goal)?.id.clone();
        let epoch = self.retry_epoch(&self.self_id);
        let dot = self.tick();
        let key = RecordKey::Unreachable { goal: canonical.clone(), robot: self.self_id.clone() };
        self.put(key, dot, RecordBody::Unreachable(UnreachableRecord { epoch, stamp }));
        self.release_own(Some(&canonical), stamp);
        self.clear_current_goal_if(&canonical);
        Ok(())
    }

    /// Clears every "unreachable" mark of this robot (it retries them when nothing else is
    /// left) by starting a new retry epoch; marks made in earlier epochs stop counting.
    pub fn clear_unreachable(&mut self) {
        let epoch = self.retry_epoch(&self.self_id) + 1;
        let dot = self.tick();
        self.put(RecordKey::RetryEpoch(self.self_id.clone()), dot, RecordBody::RetryEpoch(epoch));
    }

    /// Updates this robot's last known pose. A pose older than the recorded one is ignored
    /// (returns false).
    pub fn set_pose(&mut self, pose: Pose2, stamp: Time) -> Result<bool, TeamStateError> {
        if !finite_pose(&pose) {
            return Err(TeamStateError::InvalidInput("pose is not finite".into()));
        }
        let key = RecordKey::Robot(self.self_id.clone());
        if self.records.contains_key(&key) && stamp < self.own_robot_record().stamp {
            return Ok(false);
        }
        self.write_robot(|r| {
            r.pose = Some(pose);
            r.stamp = stamp;
        });
        Ok(true)
    }

    /// Publishes the end of this robot's current global path (the UAV seeks it when the pose is
    /// stale), or clears it.
    pub fn set_path_end(&mut self, end: Option<Point2>) -> Result<(), TeamStateError> {
        if end.is_some_and(|p| !(p.x.is_finite() && p.y.is_finite())) {
            return Err(TeamStateError::InvalidInput("path end is not finite".into()));
        }
        self.write_robot(|r| r.path_end = end);
        Ok(())
    }

    /// Offers a reachability scan this robot took. It is shared only if it lies at least
    /// `scan_min_spacing_m` from every scan this robot shared before; returns whether it was.
    pub fn add_scan(&mut self, scan: ReachabilityScan) -> Result<bool, TeamStateError> {
        if scan.robot != self.self_id {
            return Err(TeamStateError::InvalidInput(format!(
                "scan of {} offered to the team state of {}",
                scan.robot, self.self_id
            )));
        }
        check_scan(&scan, self.params.max_scan_bins).map_err(TeamStateError::InvalidInput)?;
        let here = scan.pose.position();
        let spacing = self.params.scan_min_spacing_m;
        if self.own_scan_positions.iter().any(|p| p.distance(here) < spacing) {
            return Ok(false);
        }
        self.own_scan_positions.push(here);
        let seq = self.next_scan_seq;
        self.next_scan_seq += 1;
        let key = RecordKey::Scan { robot: self.self_id.clone(), seq };
        self.put(key, 1, RecordBody::Scan(Arc::new(scan)));
        Ok(true)
    }

    /// Publishes a new aerial-map version (compressed layers from `spomp-mapping`). Versions not
    /// newer than the current one are ignored (returns false).
    pub fn add_map_version(&mut self, version: u64, stamp: Time, blob: Vec<u8>) -> Result<bool, TeamStateError> {
        if blob.len() > self.params.max_map_blob_bytes {
            return Err(TeamStateError::InvalidInput(format!(
                "map blob of {} bytes exceeds max_map_blob_bytes",
                blob.len()
            )));
        }
        if self.latest_map(&self.self_id.clone()).is_some_and(|m| m.version >= version) {
            return Ok(false);
        }
        let dot = self.tick();
        let body = RecordBody::Map(MapVersion { version, stamp, blob: Arc::new(blob) });
        self.put(RecordKey::Map(self.self_id.clone()), dot, body);
        Ok(true)
    }

    // ------------------------------------------------------------------ queries

    /// Every goal, deduplicated (aliases merged), in order of identification.
    pub fn goals(&self) -> &[GoalView] {
        &self.goal_index.views
    }

    /// The goal with this id, or the goal it is an alias of.
    pub fn goal(&self, id: &GoalId) -> Option<&GoalView> {
        self.goal_index.by_id.get(id).and_then(|&i| self.goal_index.views.get(i))
    }

    /// The known goal within the deconfliction radius of `position`, if any (nearest).
    pub fn goal_near(&self, position: Point2) -> Option<&GoalView> {
        let r = self.params.deconfliction_radius_m;
        self.goals()
            .iter()
            .filter(|v| v.position.distance(position) <= r)
            .min_by(|a, b| a.position.distance(position).total_cmp(&b.position.distance(position)))
    }

    /// Goals `robot` may claim, most urgent first (operator priority, higher first), nearest to
    /// `position` first among equals: not visited, not cancelled, not unreachable for it, and
    /// not claimed by another robot.
    pub fn claimable_goals_for(&self, robot: &RobotId, position: Point2) -> Vec<&GoalView> {
        let mut out: Vec<&GoalView> = self
            .goals()
            .iter()
            .filter(|v| v.visited.is_none() && v.cancelled.is_none())
            .filter(|v| !v.is_unreachable_for(robot))
            .filter(|v| v.claims.iter().all(|c| &c.robot == robot))
            .collect();
        out.sort_by(|a, b| {
            b.priority
                .cmp(&a.priority)
                .then_with(|| a.position.distance(position).total_cmp(&b.position.distance(position)))
                .then_with(|| a.id.cmp(&b.id))
        });
        out
    }

    /// Whether every goal is visited or cancelled by the operator (and there is at least one).
    pub fn all_goals_visited(&self) -> bool {
        !self.goals().is_empty() && self.goals().iter().all(|v| v.visited.is_some() || v.cancelled.is_some())
    }

    /// The last known state (pose, stamp, current goal, path end) of a robot.
    pub fn robot_status(&self, id: &RobotId) -> Option<&RobotStatus> {
        match self.records.get(&RecordKey::Robot(id.clone())).map(|r| &r.body) {
            Some(RecordBody::Robot(r)) => Some(r.as_ref()),
            _ => None,
        }
    }

    /// The last known pose of a robot and its stamp.
    pub fn robot_pose(&self, id: &RobotId) -> Option<(Pose2, Time)> {
        self.robot_status(id).and_then(|r| r.pose.map(|p| (p, r.stamp)))
    }

    /// Every robot with a known state.
    pub fn robots(&self) -> Vec<(&RobotId, &RobotStatus)> {
        self.records
            .values()
            .filter_map(|r| match (&r.key, &r.body) {
                (RecordKey::Robot(id), RecordBody::Robot(s)) => Some((id, s.as_ref())),
                _ => None,
            })
            .collect()
    }

    /// Scans that arrived (locally or from peers) after `cursor`, and the new cursor. Start
    /// with cursor 0.
    pub fn scans_since(&self, cursor: usize) -> (&[Arc<ReachabilityScan>], usize) {
        let from = cursor.min(self.scan_log.len());
        (&self.scan_log[from..], self.scan_log.len())
    }

    /// Number of scans held.
    pub fn scan_count(&self) -> usize {
        self.scan_log.len()
    }

    /// The latest map version published by `origin`.
    pub fn latest_map(&self, origin: &RobotId) -> Option<&MapVersion> {
        match self.records.get(&RecordKey::Map(origin.clone())).map(|r| &r.body) {
            Some(RecordBody::Map(m)) => Some(m),
            _ => None,
        }
    }

    /// The claim records held, in key order, without walking the other records (claims sort
    /// together: after every goal record, before every visit record).
    fn claim_records(&self) -> impl Iterator<Item = &Record> + '_ {
        let first = RecordKey::Claim { goal: GoalId { origin: RobotId::new(""), seq: 0 }, claimant: RobotId::new("") };
        self.records.starting_at(first).take_while(|r| matches!(r.key, RecordKey::Claim { .. }))
    }

    /// The robots whose map records are held, in key order (the order of [`Self::records`]),
    /// without walking the other records.
    pub fn map_writers(&self) -> impl Iterator<Item = &RobotId> + '_ {
        self.records.starting_at(RecordKey::Map(RobotId::new(""))).map_while(|r| match &r.key {
            RecordKey::Map(robot) => Some(robot),
            _ => None,
        })
    }

    /// The newest map version held, over all origins (highest version, ties by origin).
    pub fn newest_map(&self) -> Option<(&RobotId, &MapVersion)> {
        self.records
            .values()
            .filter_map(|r| match (&r.key, &r.body) {
                (RecordKey::Map(o), RecordBody::Map(m)) => Some((o, m)),
                _ => None,
            })
            .max_by(|a, b| a.1.version.cmp(&b.1.version).then_with(|| b.0.cmp(a.0)))
    }

    /// Every record held, in key order (for inspection, logging and tests).
    pub fn records(&self) -> impl Iterator<Item = &Record> {
        self.records.values()
    }

    /// Whether two databases hold exactly the same records.
    pub fn same_records(&self, other: &TeamState) -> bool {
        self.records == other.records
    }

    // ------------------------------------------------------------------ snapshots

    /// This robot's counters: its dot, its next goal number and next scan number.
    pub(crate) fn counters(&self) -> (u64, u32, u64) {
        (self.clock, self.next_goal_seq, self.next_scan_seq)
    }

    /// Positions of the scans this robot shared.
    pub(crate) fn own_scan_positions(&self) -> &[Point2] {
        &self.own_scan_positions
    }

    /// Takes a validated record from a snapshot (newer copies win, as in a merge).
    pub(crate) fn insert_restored(&mut self, mut rec: Record) {
        if self.records.get(&rec.key).is_some_and(|cur| crate::record::compare_copies(&rec, cur).is_le()) {
            return;
        }
        crate::intern::share_body(&rec.key, &mut rec.body);
        if let RecordBody::Scan(s) = &rec.body {
            self.scan_log.push(s.clone());
        }
        self.note_change(&rec.key);
        self.records.insert(rec);
    }

    /// Sets the counters after a restore (never below what they are) and rebuilds the goals.
    pub(crate) fn set_counters(&mut self, clock: u64, next_goal: u32, next_scan: u64, scan_positions: Vec<Point2>) {
        self.clock = self.clock.max(clock);
        self.next_goal_seq = self.next_goal_seq.max(next_goal);
        self.next_scan_seq = self.next_scan_seq.max(next_scan);
        self.own_scan_positions.extend(scan_positions);
        self.own_claims_checked = None;
        self.rebuild_goals();
    }

    // ------------------------------------------------------------------ sync

    fn peer_has_all(&self, peer: &PeerState, takes: TierSet) -> bool {
        // Only records changed since the peer's cursor, pending ones and in-flight ones can be
        // missing at the peer.
        let unseen = self.changes.range(peer.change_cursor + 1..).map(|(_, no)| no);
        with_keys(|table| {
            let held_by_peer = |no: &KeyNo| {
                let Some(rec) = table.key(*no).and_then(|key| self.records.get(key)) else { return true };
                // A record of a tier the peer does not take is not missing there.
                if !takes.contains(rec.tier()) {
                    return true;
                }
                let held = peer.confirmed.get(*no);
                // Poses change every tick; any version counts, or a sync would never complete.
                match rec.key {
                    RecordKey::Robot(_) => held > 0,
                    _ => held >= rec.dot,
                }
            };
            unseen.chain(&peer.pending).chain(peer.sent.keys()).all(held_by_peer)
        })
    }

    /// Builds the next message for `peer`: records of the allowed tiers the peer is not known to
    /// hold, highest priority first (tier, then goals before claims before poses; scans oldest
    /// first), within `byte_budget` encoded bytes; plus acknowledgements. Records larger than
    /// the remaining budget are skipped. None when there is nothing to say.
    pub fn make_sync(&mut self, peer: &RobotId, allowed_tiers: TierSet, byte_budget: usize) -> Option<SyncMessage> {
        if peer == &self.self_id {
            return None;
        }
        let takes = self.tiers_taken_by(peer);
        let allowed_tiers = allowed_tiers.and(takes);
        let state = self.peers.entry(peer.clone()).or_default();
        let changed = self.changes.range(state.change_cursor + 1..).map(|(_, &no)| no);
        if takes == TierSet::ALL {
            state.pending.extend(changed);
        } else {
            // Records of tiers the peer never takes are never pending for it: they would pile
            // up there (every scan) and keep its sync from ever being complete.
            with_keys(|table| {
                state.pending.extend(changed.filter(|&no| table.key(no).is_some_and(|k| takes.contains(k.tier()))));
            });
        }
        state.change_cursor = self.change_seq;
        let records = &self.records;
        let mut pending = std::mem::take(&mut state.pending);
        let mut candidates: Vec<(KeyNo, &Record)> = with_keys(|table| {
            let held = |no: KeyNo| table.key(no).and_then(|key| records.get(key));
            // Drop pending records the peer holds (or will, from in-flight messages).
            pending.retain(|&no| held(no).is_some_and(|r| r.dot > state.known_dot(no)));
            pending
                .iter()
                .filter_map(|&no| Some((no, held(no)?)))
                .filter(|(_, r)| allowed_tiers.contains(r.tier()))
                .collect()
        });
        state.pending = pending;
        candidates.sort_by(|(_, a), (_, b)| {
            (a.tier(), a.key.send_rank()).cmp(&(b.tier(), b.key.send_rank())).then_with(|| a.key.cmp(&b.key))
        });

        let mut msg = SyncMessage {
            from: self.self_id.clone(),
            to: peer.clone(),
            seq: state.last_sent_seq.wrapping_add(1).max(1),
            ack: state.received,
            peer_has_all: false,
            wants_ack: false,
            records: Vec::new(),
            session: self.session,
            signature: None,
        };
        let signed = self.security.is_some();
        // Header, envelope and the record-count varint (≤ 5 bytes); the trailer: session
        // (≤ 10 bytes), signature count (≤ 5), the sender's signature.
        let trailer = if signed {
            10 + 5 + SIGNATURE_BYTES
        } else if self.session != 0 {
            11
        } else {
            0
        };
        let per_record = if signed { 1 + SIGNATURE_BYTES } else { 0 };
        // A message above the receivers' limit would be refused whole (the team shares params):
        // however much the link could carry, one message stays within it.
        let byte_budget = byte_budget.min(self.params.max_message_bytes);
        let mut used = HEADER_BYTES + postcard::experimental::serialized_size(&msg).unwrap_or(0) + 5 + trailer;
        let mut sent: Vec<(KeyNo, u64)> = Vec::new();
        for (no, rec) in candidates {
            let size = postcard::experimental::serialized_size(rec).unwrap_or(usize::MAX).saturating_add(per_record);
            if used.saturating_add(size) <= byte_budget {
                used += size;
                msg.records.push(rec.clone());
                sent.push((no, rec.dot));
            }
        }
        let flag = {
            let state = self.peers.get(peer)?;
            self.peer_has_all(state, takes)
        };
        let state = self.peers.get_mut(peer)?;
        let flag_unconfirmed = state.last_flag_sent != Some(flag) || !state.flag_confirmed;
        if msg.records.is_empty() && !state.ack_owed && !flag_unconfirmed {
            return None;
        }
        msg.peer_has_all = flag;
        msg.wants_ack = !msg.records.is_empty() || flag_unconfirmed;
        state.last_sent_seq = msg.seq;
        state.ack_owed = false;
        if flag_unconfirmed {
            state.last_flag_sent = Some(flag);
            state.flag_seq = msg.seq;
            state.flag_confirmed = false;
        }
        if !msg.records.is_empty() {
            for &(no, dot) in &sent {
                state.sent.insert(no, (dot, msg.seq));
                state.pending.remove(&no);
            }
            state.in_flight.push_back(InFlight { seq: msg.seq, records: sent });
            state.trim(self.params.max_in_flight_messages);
        }
        if let Some(security) = &self.security {
            msg.signature = Some(security.sign_message(&msg.signed_part(true)));
        }
        Some(msg)
    }

    /// Decodes and applies a message, rejecting messages over `max_message_bytes`.
    pub fn apply_bytes(&mut self, from: &RobotId, bytes: &[u8]) -> Result<ApplyReport, SyncError> {
        let msg = SyncMessage::decode_with_limit(bytes, self.params.max_message_bytes)?;
        self.apply(from, &msg)
    }

    /// Merges a message from `from`. Everything is validated first: a malformed message is
    /// rejected with an error and changes nothing. Own claims that lost to a higher-priority
    /// claim, or whose goal was visited, are released at once (listed in the report).
    pub fn apply(&mut self, from: &RobotId, msg: &SyncMessage) -> Result<ApplyReport, SyncError> {
        if &msg.from != from || msg.to != self.self_id || from == &self.self_id {
            return Err(SyncError::WrongAddress {
                claimed: msg.from.to_string(),
                to: msg.to.to_string(),
                actual: from.to_string(),
                me: self.self_id.to_string(),
            });
        }
        if msg.seq == 0 {
            return Err(SyncError::Malformed("message sequence number 0".into()));
        }
        let limits =
            Limits { max_scan_bins: self.params.max_scan_bins, max_map_blob_bytes: self.params.max_map_blob_bytes };
        for (index, rec) in msg.records.iter().enumerate() {
            rec.validate(&limits).map_err(|reason| SyncError::InvalidRecord { index, reason })?;
        }
        if let Some(security) = &self.security
            && let Err((e, operator_record)) = self.authenticate(security, from, msg)
        {
            self.refused_operator_records += u64::from(operator_record);
            return Err(e);
        }
        let peer_restarted = match self.peers.get(from) {
            Some(p) if msg.session < p.session => {
                return Err(SyncError::StaleSession {
                    from: from.to_string(),
                    session: msg.session,
                    current: p.session,
                });
            }
            // A signed message of the current session is taken once: again, or older than the
            // window of recent messages remembered, it is a replay. (An unsigned team cannot
            // tell a replay from a forgery, and the simulator's radio may deliver twice.)
            Some(p) if msg.session == p.session && self.security.is_some() && p.received.seen_or_older(msg.seq) => {
                return Err(SyncError::Replayed { from: from.to_string(), seq: msg.seq, newest: p.received.upto });
            }
            Some(p) => msg.session > p.session,
            None => false,
        };
        if peer_restarted {
            // What we knew of its messages (sequence numbers, acknowledgements) belongs to its
            // earlier boot; what it holds now is learnt again from its acknowledgements.
            self.reset_peer(from);
        }
        // Stamps judged on this robot's clock: a peer's stamp from far in the future would keep
        // a claim alive long past its lease. Before the clock runs (no time yet) nothing is.
        let ahead_limit = (self.now > Time::ZERO).then(|| {
            Time::from_nanos(self.now.nanos.saturating_add(Time::from_secs_f64(self.params.max_clock_ahead_s).nanos))
        });
        let from_the_future =
            |rec: &Record| ahead_limit.is_some_and(|limit| record_stamp(&rec.body).is_some_and(|stamp| stamp > limit));

        // Merge.
        let goals_before: Vec<GoalId> = self.goals().iter().map(|v| v.id.clone()).collect();
        let mut report = ApplyReport { peer_restarted, ..ApplyReport::default() };
        let mut goals_touched = false;
        for rec in &msg.records {
            if from_the_future(rec) {
                report.records_from_the_future += 1;
                continue;
            }
            // Mission goals are loaded by every robot from the mission file, never learnt.
            if rec.key.writer().as_str() == MISSION_WRITER && self.security.is_some() {
                report.records_ignored += 1;
                continue;
            }
            // A relayed copy of our own record newer than our counter means we lost our counter
            // (restart): continue above it so our next writes win.
            if rec.key.writer() == &self.self_id && !rec.is_immutable() {
                self.clock = self.clock.max(rec.dot);
            }
            let newer = match self.records.get(&rec.key) {
                None => true,
                Some(cur) => crate::record::compare_copies(rec, cur).is_gt(),
            };
            if !newer {
                report.records_ignored += 1;
                continue;
            }
            report.records_changed += 1;
            goals_touched |= changes_goals(&rec.key);
            let mut rec = rec.clone();
            crate::intern::share_body(&rec.key, &mut rec.body);
            match &rec.body {
                RecordBody::Scan(s) => {
                    self.scan_log.push(s.clone());
                    report.new_scans += 1;
                }
                RecordBody::Map(_) => report.new_maps.push(rec.key.writer().clone()),
                _ => {}
            }
            if let RecordKey::Goal(g) = &rec.key
                && g.origin == self.self_id
            {
                self.next_goal_seq = self.next_goal_seq.max(g.seq.saturating_add(1));
            }
            if let RecordKey::Scan { robot, seq } = &rec.key
                && robot == &self.self_id
            {
                self.next_scan_seq = self.next_scan_seq.max(seq.saturating_add(1));
            }
            self.note_change(&rec.key);
            self.records.insert(rec);
        }
        if goals_touched {
            self.rebuild_goals();
            report.new_goals =
                self.goals().iter().filter(|v| !goals_before.contains(&v.id)).map(|v| v.id.clone()).collect();
        }

        // Peer bookkeeping.
        let max_in_flight = self.params.max_in_flight_messages;
        let state = self.peers.entry(from.clone()).or_default();
        state.session = msg.session;
        state.process_ack(msg.ack, max_in_flight);
        for rec in &msg.records {
            state.confirmed.raise(key_no(&rec.key), rec.dot);
        }
        // A re-delivered message was acknowledged already (or will be with the original).
        let duplicate = state.received.covers(msg.seq);
        state.received.record(msg.seq);
        if msg.seq >= state.newest_from_peer {
            state.newest_from_peer = msg.seq;
            state.peer_says_we_have_all = msg.peer_has_all;
        }
        if msg.wants_ack && !duplicate {
            state.ack_owed = true;
        }

        // Coordination: give up own claims that lost or whose goal was visited.
        if goals_touched {
            report.released = self.resolve_own_conflicts();
        }
        Ok(report)
    }

    /// Checks a message's signatures: the sender's over the message, each writer's over its
    /// record; and that operator commands are written by an operator and operators write
    /// nothing else. Any failure rejects the whole message; the flag says whether an operator
    /// record was the cause.
    fn authenticate(
        &self,
        security: &TeamSecurity,
        from: &RobotId,
        msg: &SyncMessage,
    ) -> Result<(), (SyncError, bool)> {
        let keys = security.keys();
        if !keys.is_member(from) {
            return Err((SyncError::NotAMember(from.to_string()), false));
        }
        let Some(signature) = &msg.signature else {
            return Err((SyncError::Unsigned(from.to_string()), false));
        };
        if !security.message_signed_by(from, &msg.signed_part(true), signature) {
            return Err((SyncError::BadSignature { from: from.to_string(), what: "the message".into() }, false));
        }
        for (index, rec) in msg.records.iter().enumerate() {
            let writer = rec.key.writer();
            if writer.as_str() == MISSION_WRITER {
                continue;
            }
            if !keys.is_member(writer) {
                let reason = format!("written by non-member {writer}");
                return Err((SyncError::InvalidRecord { index, reason }, matches!(rec.key, RecordKey::Command(_))));
            }
            let is_command = matches!(rec.key, RecordKey::Command(_));
            let by_operator = keys.is_operator(writer);
            if is_command != by_operator {
                let reason = if is_command {
                    format!("an operator command written by {writer}, which is not an operator")
                } else {
                    format!("a {:?} record under operator {writer}'s id (operators write only commands)", rec.tier())
                };
                return Err((SyncError::InvalidRecord { index, reason }, true));
            }
            let checks = rec.sig.as_ref().is_some_and(|sig| security.record_signed_by(writer, &record_bytes(rec), sig));
            if !checks {
                let what = format!("record {index} ({writer}'s {:?})", rec.key.tier());
                return Err((SyncError::BadSignature { from: from.to_string(), what }, is_command));
            }
        }
        Ok(())
    }

    /// Releases own claims whose goal group is visited, cancelled by the operator or held by a
    /// higher-priority robot; returns the canonical ids released.
    pub(crate) fn resolve_own_conflicts(&mut self) -> Vec<GoalId> {
        // No clock here: the release is stamped with the robot's latest pose time.
        let stamp = self.own_robot_record().stamp;
        let mut released = Vec::new();
        for g in self.own_active_claims() {
            let Some(view) = self.goal(&g) else { continue };
            if view.visited.is_some() || view.cancelled.is_some() || !view.is_held_by(&self.self_id) {
                let canonical = view.id.clone();
                self.write_release(g, stamp);
                self.clear_current_goal_if(&canonical);
                if !released.contains(&canonical) {
                    released.push(canonical);
                }
            }
        }
        released
    }

    /// Whether a full sync with `peer` has completed: the peer acknowledged every record this
    /// robot holds (any version of a pose), and the peer's newest message said the same of this
    /// robot. The UAV waits on this before it returns to exploring.
    pub fn sync_complete_with(&self, peer: &RobotId) -> bool {
        self.peers.get(peer).is_some_and(|p| p.peer_says_we_have_all && self.peer_has_all(p, self.tiers_taken_by(peer)))
    }

    /// The tiers `peer` is sent, whatever its link allows: an operator (the reserved id
    /// [`crate::OPERATOR_ID`], or a member the team's keys list as an operator) takes the
    /// coordination tier only — goals, claims, visits, poses, commands and acknowledgements are
    /// all it reads, and scans and maps would crowd its link to the robot it reaches (a laptop
    /// on the base's radio). Every robot takes every tier. The one place this rule is kept:
    /// [`TeamState::make_sync`] applies it, so every link (the simulator's radio, the Zenoh
    /// team link) carries the same to an operator.
    pub fn tiers_taken_by(&self, peer: &RobotId) -> TierSet {
        let operator =
            peer.as_str() == crate::OPERATOR_ID || self.security.as_ref().is_some_and(|s| s.keys().is_operator(peer));
        if operator { TierSet::only(Tier::Coordination) } else { TierSet::ALL }
    }

    /// Forgets what is known about `peer`'s holdings (e.g. the peer restarted); everything is
    /// offered again on the next sync.
    pub fn reset_peer(&mut self, peer: &RobotId) {
        if let Some(old) = self.peers.remove(peer) {
            // This robot's own numbering towards the peer goes on: restarted at 1, its next
            // messages would look like replays to a peer that remembers the higher numbers.
            let kept = PeerState { last_sent_seq: old.last_sent_seq, session: old.session, ..PeerState::default() };
            self.peers.insert(peer.clone(), kept);
        }
    }

    /// How many entries the database's tables hold (see [`TableSizes`]): what a bound on its
    /// memory is stated in.
    pub fn table_sizes(&self) -> TableSizes {
        TableSizes {
            records: self.records.len(),
            change_log: self.changes.len(),
            scans: self.scan_log.len(),
            peers: self.peers.len(),
            peer_entries: self.peers.values().map(|p| p.in_flight.len() + p.sent.len() + p.pending.len()).sum(),
        }
    }
}

/// Whether a change of a record with this key changes the goal view: goal records and their
/// status, retry epochs, operator commands.
fn changes_goals(key: &RecordKey) -> bool {
    key.goal().is_some() || matches!(key, RecordKey::RetryEpoch(_) | RecordKey::Command(_))
}

/// The bytes a record's signature covers: its encoding (key, dot, body; the signature itself is
/// not part of it).
pub(crate) fn record_bytes(rec: &Record) -> Vec<u8> {
    postcard::to_stdvec(rec).unwrap_or_default()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Skipping the look for claims to renew while nothing changed gives the records of a
    /// database that looks every time: renewals at the same steps, with the same stamps.
    #[test]
    fn renewal_skipping_matches_looking_every_step() {
        let mut fast = TeamState::new(RobotId::new("ugv1"), 1, TeamStateParams::default()).unwrap();
        let at = |s: f64| Time::from_millis((s * 1000.0) as i64);
        let mut goals = Vec::new();
        for k in 0..3 {
            let outcome = fast.identify_goal(Point2::new(100.0 * k as f64, 0.0), GoalOrigin::Detected, at(0.0));
            goals.push(outcome.unwrap().id().clone());
        }
        let mut slow = fast.clone();
        let lease = fast.params.claim_lease_s;
        let mut renewals = 0;
        for step in 1..(lease * 30.0) as i64 {
            let now = at(step as f64 * 0.1);
            // Claims taken (and given up) along the way, at different times.
            if step == 40 || step == 170 {
                let g = &goals[(step as usize / 100) % goals.len()];
                fast.claim(g, now).unwrap();
                slow.claim(g, now).unwrap();
            }
            if step == 300 {
                fast.release(&goals[0], now).unwrap();
                slow.release(&goals[0], now).unwrap();
            }
            let before = fast.change_seq;
            fast.advance_clock(now);
            slow.own_claims_checked = None;
            slow.advance_clock(now);
            renewals += usize::from(fast.change_seq != before);
            assert!(fast.same_records(&slow), "step {step}");
        }
        assert!(renewals >= 4, "{renewals} renewals");
    }

    #[test]
    fn map_writers_are_the_map_records_in_order() {
        let mut team = TeamState::new(RobotId::new("ugv1"), 1, TeamStateParams::default()).unwrap();
        for (k, robot) in ["uav1", "base", "ugv1", "a"].iter().enumerate() {
            let key = RecordKey::Map(RobotId::new(robot));
            let body =
                RecordBody::Map(MapVersion { version: k as u64 + 1, stamp: Time::ZERO, blob: Arc::new(vec![k as u8]) });
            team.put(key, k as u64 + 1, body);
            team.identify_goal(Point2::new(50.0 * k as f64, 0.0), GoalOrigin::Detected, Time::ZERO).unwrap();
        }
        let expected: Vec<&RobotId> = team
            .records()
            .filter_map(|r| match &r.key {
                RecordKey::Map(robot) => Some(robot),
                _ => None,
            })
            .collect();
        assert_eq!(team.map_writers().collect::<Vec<_>>(), expected);
        assert_eq!(expected.len(), 4);
    }

    /// The claim walk sees every claim (others' and released ones too) and nothing else, with
    /// goal, visit, scan, pose and map records around it.
    #[test]
    fn claim_records_are_the_claims_in_order() {
        let mut team = TeamState::new(RobotId::new("ugv1"), 1, TeamStateParams::default()).unwrap();
        let mut goals = Vec::new();
        for k in 0..4 {
            let outcome = team.identify_goal(Point2::new(100.0 * k as f64, 0.0), GoalOrigin::Detected, Time::ZERO);
            goals.push(outcome.unwrap().id().clone());
        }
        team.claim(&goals[1], Time::ZERO).unwrap();
        team.claim(&goals[3], Time::ZERO).unwrap();
        team.release(&goals[3], Time::ZERO).unwrap();
        team.mark_visited(&goals[2], Time::ZERO).unwrap();
        team.set_pose(Pose2::new(1.0, 2.0, 0.0), Time::ZERO).unwrap();
        let other = RecordKey::Claim { goal: goals[0].clone(), claimant: RobotId::new("") };
        team.put(other, 99, RecordBody::Claim(ClaimRecord { active: true, priority: 7, stamp: Time::ZERO }));
        team.put(
            RecordKey::Map(RobotId::new("uav1")),
            100,
            RecordBody::Map(MapVersion { version: 1, stamp: Time::ZERO, blob: Arc::new(vec![1]) }),
        );
        let expected: Vec<&RecordKey> =
            team.records().map(|r| &r.key).filter(|k| matches!(k, RecordKey::Claim { .. })).collect();
        assert_eq!(team.claim_records().map(|r| &r.key).collect::<Vec<_>>(), expected);
        assert_eq!(expected.len(), 3);
    }
}
