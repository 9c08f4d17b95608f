//! One round of a robot's side of the sync over the link: per reachable peer, a message per
//! tier, highest first, within the link's byte budget for the round.

use std::collections::BTreeSet;

use spomp_core::RobotId;
use spomp_teamstate::{Tier, TierSet};

use crate::link::TeamLink;

/// Sends one round: for each peer in `peers` that is reachable now, asks `make(peer, tier,
/// budget left)` for a message of each tier in turn (coordination, scans, maps) and sends what
/// it gives, until the peer's `budget_bytes` for the round is spent. Returns the bytes sent.
pub fn send_round(
    link: &TeamLink,
    peers: &[RobotId],
    budget_bytes: usize,
    mut make: impl FnMut(&RobotId, TierSet, usize) -> Option<Vec<u8>>,
) -> usize {
    let reachable: BTreeSet<RobotId> = link.reachable();
    let mut total = 0;
    for peer in peers.iter().filter(|p| reachable.contains(*p)) {
        let mut left = budget_bytes;
        for tier in Tier::ALL {
            let Some(bytes) = make(peer, TierSet::only(tier), left) else { continue };
            left = left.saturating_sub(bytes.len());
            total += bytes.len();
            link.send(peer, tier, bytes);
        }
    }
    total
}
