//! The radio's sync round: each link that is up carries one team-state message each way,
//! within the tiers and bytes its range and bandwidth allow, unused bytes carried over while it
//! stays up.

use super::*;

/// Most bytes a link can bank for later (a few full map versions).
const MAX_LINK_CREDIT_BYTES: u64 = 32 * 1024 * 1024;

impl Simulation {
    pub(super) fn sync_radio(&mut self, observer: &mut dyn SimObserver) {
        let nodes: Vec<RadioNode> =
            self.robots.iter().map(|r| RadioNode { position: r.truth().position(), alive: r.alive() }).collect();
        let mut links = std::mem::take(&mut self.links);
        self.radio.links_into(self.now, &nodes, self.options.sync_period_s, &mut links);
        if !self.ugv_to_ugv {
            let robots = &self.robots;
            links.retain(|(i, j, _)| !(robots[*i].kind == RobotKind::Ugv && robots[*j].kind == RobotKind::Ugv));
        }
        let n = self.robots.len();
        // Unused bytes of a link carry over while it stays up, so an item larger than one
        // period's budget (a map version) goes through after enough periods, as on a real
        // link; the credit is lost when the link drops.
        let mut credit = vec![0u64; n * n];
        for &(i, j, link) in &links {
            let tiers = match link.tier {
                LinkTier::All => TierSet::ALL,
                LinkTier::Small => TierSet::only(Tier::Coordination),
            };
            for (a, b) in [(i, j), (j, i)] {
                let k = a * n + b;
                let was_up = self.last_link.get(k).copied().flatten() == Some(self.last_sync);
                let carried = if was_up { self.link_credit.get(k).copied().unwrap_or(0) } else { 0 };
                if let Some(c) = credit.get_mut(k) {
                    *c = carried.saturating_add(link.budget_bytes).min(MAX_LINK_CREDIT_BYTES);
                }
                if let Some(slot) = self.last_link.get_mut(k) {
                    *slot = Some(self.now);
                }
            }
            for (a, b) in [(i, j), (j, i)] {
                let k = a * n + b;
                let budget = credit.get(k).copied().unwrap_or(0);
                let from = self.robots[a].id.clone();
                let to = self.robots[b].id.clone();
                // Over the wire: encoded, decoded and checked by the receiver. A driven robot's
                // messages were sent already; the link carries those it has room for (a small
                // link, coordination only, cannot tell tiers apart in them: it carries none).
                let lockstep = self.drivers.as_ref().is_some_and(|d| d.lockstep());
                let messages: Vec<Vec<u8>> = if self.robots[a].external && lockstep {
                    let budget_bytes = usize::try_from(budget).unwrap_or(usize::MAX);
                    match self.drivers.as_mut() {
                        Some(d) => d.team_message_for(&from, &to, tiers, budget_bytes).into_iter().collect(),
                        None => Vec::new(),
                    }
                } else if self.robots[a].external {
                    let mut budget = if link.tier == LinkTier::All { budget } else { 0 };
                    let mut out = Vec::new();
                    self.driven_outbox.retain(|m| {
                        if m.from != from || m.to != to {
                            return true;
                        }
                        if (m.bytes.len() as u64) <= budget {
                            budget -= m.bytes.len() as u64;
                            out.push(m.bytes.clone());
                        }
                        false
                    });
                    out
                } else {
                    let budget_bytes = usize::try_from(budget).unwrap_or(usize::MAX);
                    let sent = self.robots[a].robot.team_message_for(self.now, &to, tiers, budget_bytes);
                    self.robots[a].robot.deliver_recorded(observer);
                    sent.into_iter().collect()
                };
                for bytes in messages {
                    if let Some(c) = credit.get_mut(k) {
                        *c = c.saturating_sub(bytes.len() as u64);
                    }
                    match self.drivers.as_mut().filter(|_| self.robots[b].external) {
                        Some(d) => d.deliver_team_message(&to, &from, &bytes),
                        None => {
                            let _ = self.robots[b].robot.on_team_message(self.now, &from, bytes);
                            self.robots[b].robot.deliver_recorded(observer);
                        }
                    }
                }
            }
        }
        // What driven robots sent over links that are down is lost, as on a radio.
        self.driven_outbox.clear();
        self.link_credit = credit;
        self.last_sync = self.now;
        self.links = links;
    }
}
