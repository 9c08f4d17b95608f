//! Team-level goal bookkeeping: each goal's earliest identification, claim and visit over all
//! robots, ids the robots merged folded together, and the vehicle clusters found.

use super::*;

impl Simulation {
    /// Team-level goal bookkeeping (earliest identification, claim and visit over all robots).
    pub(super) fn track_goals(&mut self, observer: &mut dyn SimObserver) {
        let now = self.now;
        let mut own_visits = Vec::new();
        for (ri, r) in self.robots.iter().enumerate() {
            let goals = match self.drivers.as_ref().filter(|_| r.external) {
                Some(d) => d.goals(&r.id),
                None => r.robot.team().goals(),
            };
            for g in goals {
                for a in &g.aliases {
                    self.aliases.insert(a.clone(), g.id.clone());
                }
                let entry = match self.goals.get_mut(&g.id) {
                    Some(e) => e,
                    None => {
                        let summary = GoalSummary {
                            id: g.id.to_string(),
                            position: [g.position.x, g.position.y],
                            origin: match g.origin {
                                GoalOrigin::Detected => "detected",
                                GoalOrigin::Mission => "mission",
                                GoalOrigin::Basestation => "basestation",
                                GoalOrigin::Operator => "operator",
                            }
                            .to_string(),
                            identified_s: g.identified_at.as_secs_f64(),
                            identified_by: g.identified_by.to_string(),
                            claimed_s: None,
                            claimed_by: None,
                            visited_s: None,
                            visited_by: None,
                            revisits_in_contact: 0,
                            cancelled_s: None,
                        };
                        observer.on_event(
                            now,
                            &SimEvent::GoalIdentified {
                                goal: summary.id.clone(),
                                by: summary.identified_by.clone(),
                                position: summary.position,
                            },
                        );
                        self.goal_order.push(g.id.clone());
                        self.goals.entry(g.id.clone()).or_insert(summary)
                    }
                };
                for c in &g.claims {
                    let t = c.stamp.as_secs_f64();
                    if entry.claimed_s.is_none_or(|s| t < s) {
                        entry.claimed_s = Some(t);
                        entry.claimed_by = Some(c.robot.to_string());
                    }
                }
                if let Some((t, by)) = &g.visited
                    && by == &r.id
                {
                    own_visits.push((g.id.clone(), ri, *t));
                }
                if let Some(by) = &g.cancelled
                    && entry.cancelled_s.is_none()
                {
                    entry.cancelled_s = Some(now.as_secs_f64());
                    observer.on_event(now, &SimEvent::GoalCancelled { goal: entry.id.clone(), by: by.to_string() });
                }
                if let Some((t, by)) = &g.visited {
                    let t = t.as_secs_f64();
                    if entry.visited_s.is_none() {
                        observer.on_event(now, &SimEvent::GoalVisited { goal: entry.id.clone(), by: by.to_string() });
                    }
                    if entry.visited_s.is_none_or(|s| t < s) {
                        entry.visited_s = Some(t);
                        entry.visited_by = Some(by.to_string());
                    }
                }
            }
        }
        self.record_own_visits(own_visits);
    }

    /// Records visits robots made themselves; a visit to a goal another robot visited earlier
    /// counts as a revisit in contact when the two had a direct link after the first visit
    /// (the team state should have told the second robot in time).
    pub(super) fn record_own_visits(&mut self, visits: Vec<(GoalId, usize, Time)>) {
        let n = self.robots.len();
        for (goal, robot, t2) in visits {
            let canonical = self.aliases.get(&goal).cloned().unwrap_or_else(|| goal.clone());
            if self.own_visits.contains_key(&(canonical.clone(), robot)) {
                continue;
            }
            let in_contact = self.own_visits.iter().any(|((g, other), t1)| {
                *g == canonical
                    && *other != robot
                    && *t1 < t2
                    && self.last_link.get(*other * n + robot).copied().flatten().is_some_and(|l| l > *t1)
            });
            self.own_visits.insert((canonical, robot), t2);
            if in_contact && let Some(entry) = self.goals.get_mut(&goal) {
                entry.revisits_in_contact += 1;
            }
        }
    }

    /// The goals with the ids robots merged (identified twice within the deconfliction radius)
    /// folded into their canonical goal: earliest identification, claim and visit win.
    pub(super) fn merged_goals(&self) -> Vec<GoalSummary> {
        let canonical = |id: &GoalId| {
            let mut c = id;
            // Alias chains are short; the bound guards against a cycle in bad data.
            for _ in 0..8 {
                match self.aliases.get(c) {
                    Some(next) if next != c => c = next,
                    _ => break,
                }
            }
            c.clone()
        };
        let mut merged: BTreeMap<GoalId, GoalSummary> = BTreeMap::new();
        let mut order = Vec::new();
        for id in &self.goal_order {
            let Some(g) = self.goals.get(id) else { continue };
            let c = canonical(id);
            match merged.get_mut(&c) {
                None => {
                    let mut first = g.clone();
                    if let Some(cg) = self.goals.get(&c) {
                        first.id = cg.id.clone();
                        first.position = cg.position;
                    }
                    merged.insert(c.clone(), first);
                    order.push(c);
                }
                Some(m) => {
                    m.revisits_in_contact += g.revisits_in_contact;
                    if g.identified_s < m.identified_s {
                        m.identified_s = g.identified_s;
                        m.identified_by = g.identified_by.clone();
                    }
                    if let Some(t) = g.claimed_s
                        && m.claimed_s.is_none_or(|s| t < s)
                    {
                        m.claimed_s = Some(t);
                        m.claimed_by = g.claimed_by.clone();
                    }
                    if let Some(t) = g.visited_s
                        && m.visited_s.is_none_or(|s| t < s)
                    {
                        m.visited_s = Some(t);
                        m.visited_by = g.visited_by.clone();
                    }
                }
            }
        }
        order.into_iter().filter_map(|c| merged.remove(&c)).collect()
    }

    pub(super) fn all_goals_visited(&self) -> bool {
        let goals = self.merged_goals();
        if goals.is_empty() || goals.iter().any(|g| g.visited_s.is_none()) {
            return false;
        }
        // With detection in a generated world, every vehicle cluster must have been found too.
        match self.cluster_summary(&goals) {
            Some(c) => c.visited >= c.total,
            None => true,
        }
    }

    pub(super) fn cluster_summary(&self, goals: &[GoalSummary]) -> Option<ClusterSummary> {
        let detect = self.mission.goals.as_ref()?.detect.as_ref()?;
        let clusters = &self.world.meta.vehicle_clusters;
        if clusters.is_empty() {
            return None;
        }
        // The detector's own defaults for what the mission leaves unset.
        let defaults = spomp_mapping::GoalDetectionParams::default();
        let match_radius_m = detect.merge_distance_m.unwrap_or(defaults.merge_distance_m)
            + detect.placement_region_m.unwrap_or(defaults.placement_region_m);
        let near =
            |c: &Point2, g: &GoalSummary| Point2::new(g.position[0], g.position[1]).distance(*c) <= match_radius_m;
        let found = clusters.iter().filter(|c| goals.iter().any(|g| near(c, g))).count();
        let visited = clusters.iter().filter(|c| goals.iter().any(|g| g.visited_s.is_some() && near(c, g))).count();
        Some(ClusterSummary { total: clusters.len(), found, visited, match_radius_m })
    }
}
