//! Experience from reachability scans: training labels (votes) and edge states
//! (trav / not_trav / unk_trav) per the paper's rules.

#[allow(clippy::wildcard_imports)]
use super::*;

/// Slack of the box test that rules out edges far from a scan, metres: far more than the
/// rounding of a point-to-polyline distance on any map, far less than any scan range.
const FAR_EDGE_MARGIN_M: f64 = 1e-6;

impl GlobalPlanner {
    /// Whether edge `e`'s bounding box (its ends and interior vertices) lies more than `reach`
    /// from `p` along x or along y: then every point of the edge is farther than `reach` from
    /// `p`. False for edges that are not live and for a `p` or `reach` that is not a number
    /// (vertices are cell centres, always finite).
    fn edge_box_beyond(&self, e: EdgeIndex<u32>, p: Point2, reach: f64) -> bool {
        let (Some((a, b)), Some(d)) = (self.graph.edge_endpoints(e), self.graph.edge_weight(e)) else {
            return false;
        };
        let (pa, pb) = (self.graph[a].position, self.graph[b].position);
        let (mut x0, mut x1) = (pa.x.min(pb.x), pa.x.max(pb.x));
        let (mut y0, mut y1) = (pa.y.min(pb.y), pa.y.max(pb.y));
        for v in &d.via {
            x0 = x0.min(v.x);
            x1 = x1.max(v.x);
            y0 = y0.min(v.y);
            y1 = y1.max(v.y);
        }
        p.x < x0 - reach || p.x > x1 + reach || p.y < y0 - reach || p.y > y1 + reach
    }

    /// Takes in a reachability scan: its cells vote for training labels, and (with graph updates
    /// on) every edge near it is judged trav / not_trav / unk_trav. `own` is true for the robot's
    /// own scans; other robots' scans can never remove an edge.
    pub fn add_scan(&mut self, scan: &ReachabilityScan, own: bool) -> Result<ScanUpdate, ScanError> {
        self.take_scan(scan, own, &[])
    }

    /// Takes in the robot's own `scan`, taken while its ground teammates stood at `teammates`
    /// (last known positions, map frame), as [`Self::add_scan`] does with `own`, except for
    /// the edges a teammate blocks: a not_trav edge whose boundary crossing is a bin ending
    /// within `experience.teammate_clearance_m` of a teammate is marked, never removed (a
    /// teammate standing in the road is not terrain; see [`crate::bins_ending_at_teammates`]).
    /// Every other edge of the scan is judged as the robot's own experience.
    pub fn add_own_scan_among(
        &mut self,
        scan: &ReachabilityScan,
        teammates: &[Point2],
    ) -> Result<ScanUpdate, ScanError> {
        self.take_scan(scan, true, teammates)
    }

    fn take_scan(&mut self, scan: &ReachabilityScan, own: bool, teammates: &[Point2]) -> Result<ScanUpdate, ScanError> {
        let mut region = std::mem::take(&mut self.region);
        let loaded = region.load(scan, self.params.learning.max_scan_range_m);
        let mut update = ScanUpdate::default();
        if loaded.is_ok() && self.map.is_some() {
            if self.params.learning.enabled {
                update.cells_voted = self.vote(&region);
            }
            if self.params.experience.graph_updates {
                if own {
                    region.mark_teammates(teammates, self.params.experience.teammate_clearance_m);
                }
                self.judge_edges(&region, own, &mut update);
            }
        }
        self.region = region;
        loaded.map(|()| update)
    }

    pub(super) fn vote(&mut self, region: &StarRegion) -> usize {
        let Some(map) = &self.map else { return 0 };
        let spec = map.spec;
        let res = spec.resolution_m;
        let depth = self.params.learning.not_trav_depth_m.max(0.0);
        let reach = region.max_range_m + depth;
        let o = region.origin;
        let c0 = ((o.x - reach - spec.origin.x) / res).floor().max(0.0) as i64;
        let r0 = ((o.y - reach - spec.origin.y) / res).floor().max(0.0) as i64;
        let c1 = (((o.x + reach - spec.origin.x) / res).ceil() as i64).min(spec.width as i64 - 1);
        let r1 = (((o.y + reach - spec.origin.y) / res).ceil() as i64).min(spec.height as i64 - 1);
        self.votes.begin_scan();
        let n = region.range_m.len();
        let mut voted = 0;
        for row in r0..=r1 {
            for col in c0..=c1 {
                let cell = Cell::new(col as u32, row as u32);
                let p = spec.center(cell);
                let dist = p.distance(o);
                if dist > reach {
                    continue;
                }
                let label = if region.contains(p) {
                    Some(true)
                } else {
                    let bin = (region.bin_position(p).round() as usize) % n;
                    let r = region.range_m[bin];
                    (region.obstacle[bin] && dist > r && dist <= r + depth).then_some(false)
                };
                if let Some(t) = label
                    && self.votes.vote(spec.index(cell), t)
                {
                    voted += 1;
                }
            }
        }
        voted
    }

    /// Removes edge `e` for good: a map update never brings the pair back.
    fn remove_for_good(&mut self, e: EdgeIndex<u32>) {
        if let Some((a, b)) = self.graph.edge_endpoints(e) {
            let key = pair(a, b);
            self.removed_pairs.insert(key);
            self.edge_of_pair.remove(&key);
        }
        self.graph.remove_edge(e);
    }

    /// Records that this robot failed to drive the edge between `a` and `b` (its navigation
    /// made no progress along it): its own experience, so the edge is marked not_trav and
    /// locked, removed for good as the robot's own not_trav scans remove an edge, and no later
    /// plan sends the robot back the same way. Other robots' scans cannot bring it back (only
    /// own observations lock, and a locked edge never changes). Routed edges (through a curb
    /// ramp) too: the scans cannot judge those, but a drive along one can. Off with graph
    /// updates off (`experience.graph_updates`, the paper's ablation). Returns whether an edge
    /// was removed (false when the pair is no live edge).
    pub fn mark_failed_edge(&mut self, a: NodeId, b: NodeId) -> bool {
        if !self.params.experience.graph_updates {
            return false;
        }
        let key = if a.0 < b.0 { (a.0, b.0) } else { (b.0, a.0) };
        let Some(&e) = self.edge_of_pair.get(&key) else { return false };
        let Some(d) = self.graph.edge_weight_mut(e) else { return false };
        if d.experience.failed_drive() != Transition::Removed {
            return false;
        }
        self.remove_for_good(e);
        self.refresh_heuristic_rate();
        true
    }

    pub(super) fn judge_edges(&mut self, region: &StarRegion, own: bool, update: &mut ScanUpdate) {
        let x = &self.params.experience;
        let judging = Judging {
            window_rad: x.crossing_window_rad,
            on_edge_radius_m: x.on_edge_radius_m,
            min_crossing_range_m: x.min_crossing_range_m,
        };
        let mut changed = std::mem::take(&mut self.judged);
        changed.clear();
        let mut points = Vec::new();
        // Every scan (the robot's own and each one a peer shares) meets every edge: most edges
        // lie far away, and a box test rules them out before the exact distance (a square root
        // per piece). The margin covers the rounding of that distance, so the same edges are
        // judged as without the test.
        let reach = region.max_range_m + FAR_EDGE_MARGIN_M;
        for e in self.graph.edge_indices() {
            if self.edge_box_beyond(e, region.origin, reach) {
                continue;
            }
            if !self.edge_points(e, &mut points) {
                continue;
            }
            if polyline_point_distance(&points, region.origin) > region.max_range_m {
                continue;
            }
            let Verdict { obs, at_teammate } = region.classify_polyline(&points, &judging);
            update.observed[match obs {
                EdgeObservation::Trav => 0,
                EdgeObservation::NotTrav => 1,
                EdgeObservation::UnkTrav => 2,
            }] += 1;
            if at_teammate {
                update.at_teammates += 1;
            }
            if obs != EdgeObservation::UnkTrav {
                changed.push((e, obs, at_teammate));
            }
        }
        let params = self.params.experience.clone();
        for &(e, obs, at_teammate) in &changed {
            let Some(d) = self.graph.edge_weight_mut(e) else {
                continue;
            };
            // An edge routed through a passage the aerial elevation shows (a curb ramp) is
            // marked, never removed, by the robot's own not_trav observations, as by other
            // robots': seen from beside the passage, a scan's safe region ends at the corner of
            // the curb, whatever the passage holds. Being stuck on it still blocks it for the
            // robot (the navigation's own record). An edge a teammate blocks is marked, never
            // removed: the teammate moves on.
            let removable = own && d.via.is_empty() && !at_teammate;
            match d.experience.observe(obs, removable, &params) {
                Transition::None => {}
                Transition::Changed => {
                    update.edges_changed += 1;
                    self.refresh_edge_cost(e);
                }
                Transition::Removed => {
                    update.edges_changed += 1;
                    update.edges_removed += 1;
                    self.remove_for_good(e);
                }
            }
        }
        self.judged = changed;
        if update.edges_changed > 0 {
            self.refresh_heuristic_rate();
        }
    }
}
