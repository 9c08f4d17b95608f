//! The radio's sync round: each link that is up carries one team-state message each way,
//! within the tiers and bytes its range and bandwidth allow. The round itself (the credit
//! carried while a link stays up, what fills the message) is the robot layer's
//! (`spomp_robot::team_round`); here the radio decides which links are up and moves the bytes.

use super::*;

impl Simulation {
    pub(super) fn sync_radio(&mut self, observer: &mut dyn SimObserver) {
        let mut nodes: Vec<RadioNode> =
            self.robots.iter().map(|r| RadioNode { position: r.truth().position(), alive: r.alive() }).collect();
        // The operator (issue 37) is the last node, when there is one.
        if let Some(op) = &self.operator {
            nodes.push(RadioNode { position: op.position, alive: true });
        }
        let mut links = std::mem::take(&mut self.links);
        self.radio.links_into(self.now, &nodes, self.options.sync_period_s, &mut links);
        let n = self.robots.len();
        let operator_links: Vec<(usize, Link)> =
            links.iter().filter(|(_, j, _)| *j == n).map(|&(i, _, l)| (i, l)).collect();
        links.retain(|(_, j, _)| *j < n);
        if !self.ugv_to_ugv {
            let robots = &self.robots;
            links.retain(|(i, j, _)| !(robots[*i].kind == RobotKind::Ugv && robots[*j].kind == RobotKind::Ugv));
        }
        // This round's credit of every robot's links (robots without a link lose theirs).
        let mut up: Vec<Vec<(RobotId, u64)>> = vec![Vec::new(); self.robots.len()];
        for &(i, j, link) in &links {
            up[i].push((self.robots[j].id.clone(), link.budget_bytes));
            up[j].push((self.robots[i].id.clone(), link.budget_bytes));
        }
        if let Some(op) = &self.operator {
            for &(i, link) in &operator_links {
                up[i].push((op.id.clone(), link.budget_bytes));
            }
        }
        for (r, up) in self.robots.iter_mut().zip(&up) {
            r.link_credit.begin_round(up.iter().map(|(peer, budget)| (peer, *budget)));
        }
        for &(i, j, link) in &links {
            let tiers = match link.tier {
                LinkTier::All => TierSet::ALL,
                LinkTier::Small => TierSet::only(Tier::Coordination),
            };
            for (a, b) in [(i, j), (j, i)] {
                if let Some(slot) = self.last_link.get_mut(a * n + b) {
                    *slot = Some(self.now);
                }
            }
            for (a, b) in [(i, j), (j, i)] {
                let from = self.robots[a].id.clone();
                let to = self.robots[b].id.clone();
                let budget = self.robots[a].link_credit.left(&to);
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
                    let r = &mut self.robots[a];
                    let sent = r.robot.team_round(self.now, &to, tiers, RoundShape::OneMessage, &mut r.link_credit);
                    r.robot.deliver_recorded(observer);
                    sent.into_iter().map(|(_, bytes)| bytes).collect()
                };
                for bytes in messages {
                    if self.robots[a].external {
                        self.robots[a].link_credit.spend(&to, bytes.len());
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
        self.sync_operator(&operator_links, observer);
        // What driven robots sent over links that are down is lost, as on a radio.
        self.driven_outbox.clear();
        self.links = links;
    }

    /// The operator's links (issue 37): one message each way per link that is up, within the
    /// link's tiers and bytes, as between robots (robots driven from outside are not reached).
    fn sync_operator(&mut self, operator_links: &[(usize, Link)], observer: &mut dyn SimObserver) {
        let Some(op) = self.operator.as_mut() else { return };
        for &(i, link) in operator_links {
            let tiers = match link.tier {
                LinkTier::All => TierSet::ALL,
                LinkTier::Small => TierSet::only(Tier::Coordination),
            };
            let r = &mut self.robots[i];
            if r.external {
                continue;
            }
            let budget = usize::try_from(link.budget_bytes).unwrap_or(usize::MAX);
            if let Some(msg) = op.team.make_sync(&r.id, tiers, budget) {
                let bytes = msg.encode();
                op.traffic.sent_messages += 1;
                op.traffic.sent_bytes += bytes.len() as u64;
                let _ = r.robot.on_team_message(self.now, &op.id, bytes);
                r.robot.deliver_recorded(observer);
            }
            // The robot's team state sends the operator the tiers it takes (coordination only),
            // whatever the link allows.
            let sent = r.robot.team_round(self.now, &op.id, tiers, RoundShape::OneMessage, &mut r.link_credit);
            r.robot.deliver_recorded(observer);
            for (_, bytes) in sent {
                op.traffic.count_received(&bytes);
                let _ = op.team.apply_bytes(&r.id, &bytes);
            }
        }
    }
}
