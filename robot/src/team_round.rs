//! The team link's send round and the background work's modelled latency, written once for
//! every adapter.
//!
//! Every sync period a link that is up gives each direction `bandwidth × period` bytes
//! ([`LinkCredit::begin_round`]); what a round leaves unused is carried over while the link
//! stays up (an item larger than one period's budget, a map version, goes out after enough
//! periods, as on a real link) and lost when it drops. Within that credit the robot fills its
//! message to each peer highest priority first ([`Robot::team_round`]): one message holding every
//! tier the link allows ([`RoundShape::OneMessage`]: the simulator's radio, the farm's topics)
//! or one message per tier, coordination first ([`RoundShape::PerTier`]: a link with a channel
//! per tier, Zenoh). The adapters only move the bytes.
//!
//! [`ModelledWork`] is the simulator's latency model of the background skills (also run by a
//! farm robot in lockstep, which must give the simulator's results bit for bit): each work
//! taken comes back after its modelled time, in the order taken.

use std::collections::BTreeMap;

use spomp_core::{RobotId, Time};
use spomp_teamstate::{Tier, TierSet};

use crate::Robot;
use crate::runtime::{SkillWork, WorkKind};

/// Most bytes a link banks for later (a few full map versions); a single period's budget
/// larger than this is kept whole.
pub const MAX_LINK_CREDIT_BYTES: u64 = 32 * 1024 * 1024;

/// How a link carries one round to one peer.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RoundShape {
    /// One message holding every tier the link allows, filled highest priority first.
    OneMessage,
    /// One message per allowed tier, coordination first, each within what the ones before it
    /// left of the credit.
    PerTier,
}

/// The byte credit of one robot's links, per peer: what the robot may still send each peer
/// this round.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct LinkCredit {
    left: BTreeMap<RobotId, u64>,
}

impl LinkCredit {
    /// Starts a round over the links up now, `(peer, budget_bytes)` each: a peer gets its
    /// budget on top of what it had left if its link was up last round too (at most
    /// [`MAX_LINK_CREDIT_BYTES`], or the budget when larger); the credit of a peer not in `up`
    /// is lost. Call it every round, with no links when none is up.
    pub fn begin_round<'a>(&mut self, up: impl IntoIterator<Item = (&'a RobotId, u64)>) {
        let mut next = BTreeMap::new();
        for (peer, budget) in up {
            let carried = self.left.get(peer).copied().unwrap_or(0);
            next.insert(peer.clone(), carried.saturating_add(budget).min(MAX_LINK_CREDIT_BYTES.max(budget)));
        }
        self.left = next;
    }

    /// Bytes `peer` may still be sent this round (0: its link is down).
    pub fn left(&self, peer: &RobotId) -> u64 {
        self.left.get(peer).copied().unwrap_or(0)
    }

    /// Takes `bytes` sent to `peer` off its credit.
    pub fn spend(&mut self, peer: &RobotId, bytes: usize) {
        if let Some(left) = self.left.get_mut(peer) {
            *left = left.saturating_sub(bytes as u64);
        }
    }

    /// The peers whose links are up this round, in id order.
    pub fn peers(&self) -> impl Iterator<Item = &RobotId> {
        self.left.keys()
    }
}

/// One round of messages to one peer within `budget_bytes`: `make(tiers, bytes left)` gives
/// each message (its encoding; `None`: nothing to send), shaped as `shape` over `tiers`.
/// Returns the messages with the tiers each was limited to, in sending order.
pub fn round(
    shape: RoundShape,
    tiers: TierSet,
    budget_bytes: u64,
    mut make: impl FnMut(TierSet, usize) -> Option<Vec<u8>>,
) -> Vec<(TierSet, Vec<u8>)> {
    let mut left = budget_bytes;
    let mut out = Vec::new();
    let mut send = |only: TierSet, left: &mut u64| {
        if let Some(bytes) = make(only, usize::try_from(*left).unwrap_or(usize::MAX)) {
            *left = left.saturating_sub(bytes.len() as u64);
            out.push((only, bytes));
        }
    };
    match shape {
        RoundShape::OneMessage => send(tiers, &mut left),
        RoundShape::PerTier => {
            for tier in Tier::ALL.into_iter().filter(|t| tiers.contains(*t)) {
                send(TierSet::only(tier), &mut left);
            }
        }
    }
    out
}

/// The one tier of a set holding exactly one (a message of a [`RoundShape::PerTier`] round),
/// for a link that carries each tier on its own channel.
pub fn single_tier(tiers: TierSet) -> Option<Tier> {
    let mut only = Tier::ALL.into_iter().filter(|t| tiers.contains(*t));
    match (only.next(), only.next()) {
        (Some(t), None) => Some(t),
        _ => None,
    }
}

impl Robot {
    /// This round's team-state messages to `to` over a link allowing `tiers`, within the
    /// credit `credit` holds for it (spent by what is sent), shaped as `shape`. Each message is
    /// one [`crate::SeamCall::TeamOut`]; the adapter sends them, in order.
    pub fn team_round(
        &mut self,
        now: Time,
        to: &RobotId,
        tiers: TierSet,
        shape: RoundShape,
        credit: &mut LinkCredit,
    ) -> Vec<(TierSet, Vec<u8>)> {
        let sent = round(shape, tiers, credit.left(to), |only, budget| self.team_message_for(now, to, only, budget));
        for (_, bytes) in &sent {
            credit.spend(to, bytes.len());
        }
        sent
    }
}

/// How long the background skills' work takes, modelled: the simulator's latency, which a
/// farm robot in lockstep applies too.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct WorkLatency {
    /// A panorama's localization and terrain analysis, seconds.
    pub perception_s: f64,
    /// The global planner's graph growth and training, seconds.
    pub planner_s: f64,
}

impl WorkLatency {
    /// The modelled time of work of `kind`, seconds.
    pub fn of(&self, kind: WorkKind) -> f64 {
        match kind {
            WorkKind::Perception => self.perception_s,
            WorkKind::Planner => self.planner_s,
        }
    }
}

/// Work taken from a robot under a [`WorkLatency`], not yet handed back: `T` is what the
/// adapter keeps of each (the finished work when it ran at once, a ticket for a worker thread).
#[derive(Debug)]
pub struct ModelledWork<T> {
    latency: WorkLatency,
    out: Vec<(Time, T)>,
}

impl<T> ModelledWork<T> {
    /// Nothing in flight yet.
    pub fn new(latency: WorkLatency) -> Self {
        Self { latency, out: Vec::new() }
    }

    /// The latency modelled.
    pub fn latency(&self) -> WorkLatency {
        self.latency
    }

    /// The work whose modelled time has come at `now`, in the order taken: hand each back
    /// with [`Robot::finish_work`] at `now`, in this order, before [`Self::take`].
    pub fn due(&mut self, now: Time) -> Vec<T> {
        self.out.extract_if(.., |(at, _)| *at <= now).map(|(_, work)| work).collect()
    }

    /// Takes the work `robot` has due at `now`; `start` sets each going (runs it, or hands it
    /// to a thread) and gives what to keep until its modelled time has passed.
    pub fn take(&mut self, robot: &mut Robot, now: Time, mut start: impl FnMut(SkillWork) -> T) {
        for w in robot.take_work(now) {
            let due = Time::from_nanos(now.nanos + Time::from_secs_f64(self.latency.of(w.kind())).nanos);
            self.out.push((due, start(w)));
        }
    }

    /// Whether any work is in flight.
    pub fn is_empty(&self) -> bool {
        self.out.is_empty()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn id(s: &str) -> RobotId {
        RobotId::new(s)
    }

    #[test]
    fn credit_is_carried_while_the_link_stays_up_and_lost_when_it_drops() {
        let (a, b) = (id("a"), id("b"));
        let mut c = LinkCredit::default();
        c.begin_round([(&a, 100), (&b, 50)]);
        c.spend(&a, 30);
        assert_eq!((c.left(&a), c.left(&b)), (70, 50));
        c.begin_round([(&a, 100)]);
        assert_eq!((c.left(&a), c.left(&b)), (170, 0), "b's link dropped: its credit is gone");
        c.begin_round([(&a, 100), (&b, 50)]);
        assert_eq!((c.left(&a), c.left(&b)), (270, 50), "b starts afresh");
        // Capped, but a budget above the cap is kept whole.
        c.begin_round([(&a, MAX_LINK_CREDIT_BYTES)]);
        assert_eq!(c.left(&a), MAX_LINK_CREDIT_BYTES);
        c.begin_round([(&a, 2 * MAX_LINK_CREDIT_BYTES)]);
        assert_eq!(c.left(&a), 2 * MAX_LINK_CREDIT_BYTES);
        c.spend(&a, usize::MAX);
        assert_eq!(c.left(&a), 0);
    }

    #[test]
    fn a_round_per_tier_goes_coordination_first_within_what_is_left() {
        let mut asked = Vec::new();
        let sent = round(RoundShape::PerTier, TierSet::ALL, 100, |tiers, left| {
            asked.push((tiers, left));
            Some(vec![0; 40])
        });
        let only = |t| TierSet::only(t);
        assert_eq!(asked, vec![(only(Tier::Coordination), 100), (only(Tier::Scans), 60), (only(Tier::Maps), 20)]);
        assert_eq!(sent.len(), 3);
        // A tier the link does not allow is not asked for; one message over the allowed tiers.
        let mut asked = Vec::new();
        round(RoundShape::PerTier, only(Tier::Coordination).with(Tier::Maps), 10, |t, _| {
            asked.push(t);
            None
        });
        assert_eq!(asked, vec![only(Tier::Coordination), only(Tier::Maps)]);
        let sent = round(RoundShape::OneMessage, only(Tier::Coordination), 10, |t, left| Some(vec![t.bits(); left]));
        assert_eq!(sent, vec![(only(Tier::Coordination), vec![1; 10])]);
        assert_eq!(single_tier(only(Tier::Scans)), Some(Tier::Scans));
        assert_eq!(single_tier(TierSet::ALL), None);
        assert_eq!(single_tier(TierSet::NONE), None);
    }

    #[test]
    fn modelled_work_comes_back_in_the_order_taken_after_its_latency() {
        let mut m: ModelledWork<u32> = ModelledWork::new(WorkLatency { perception_s: 0.5, planner_s: 2.0 });
        let t = |s: f64| Time::from_secs_f64(s);
        m.out.push((t(2.0), 1));
        m.out.push((t(0.5), 2));
        m.out.push((t(0.4), 3));
        assert!(m.due(t(0.3)).is_empty());
        assert_eq!(m.due(t(0.5)), vec![2, 3]);
        assert_eq!(m.due(t(2.0)), vec![1]);
        assert!(m.is_empty());
    }
}
