//! Graph search: attach start and goal, A* over the sparse graph, detours from nearby nodes
//! when the covering nodes have no path.

#[allow(clippy::wildcard_imports)]
use super::*;

impl GlobalPlanner {
    /// The node whose region covers the cell under `p`, or the nearest covered cell's within
    /// the attach radius; without one, [`PlanError::Unmapped`] when the map has no data at `p`,
    /// else [`PlanError::NotOnGraph`].
    pub(super) fn attach(&self, p: Point2, which: &'static str) -> Result<NodeIndex<u32>, PlanError> {
        let map = self.map.as_ref().ok_or(PlanError::NoMap)?;
        if !(p.x.is_finite() && p.y.is_finite()) {
            return Err(PlanError::NonFinite { which });
        }
        let cell = map.spec.cell_at(p).ok_or(PlanError::OffMap { which, x: p.x, y: p.y })?;
        let w = map.spec.width as i64;
        let owner_at = |col: i64, row: i64| {
            map.spec.contains(col, row).then(|| self.owner[(row * w + col) as usize]).filter(|&o| o != NO_NODE)
        };
        let (c0, r0) = (cell.col as i64, cell.row as i64);
        if let Some(o) = owner_at(c0, r0) {
            return Ok(NodeIndex::new(o as usize));
        }
        let reach = (self.params.graph.attach_radius_m / map.spec.resolution_m).ceil() as i64;
        let mut best: Option<(i64, u32)> = None;
        for dr in -reach..=reach {
            for dc in -reach..=reach {
                let d2 = dr * dr + dc * dc;
                if d2 > reach * reach || best.is_some_and(|(b, _)| b <= d2) {
                    continue;
                }
                if let Some(o) = owner_at(c0 + dc, r0 + dr) {
                    best = Some((d2, o));
                }
            }
        }
        let (x, y) = (p.x, p.y);
        best.map(|(_, o)| NodeIndex::new(o as usize)).ok_or_else(|| {
            if map.is_known(cell) { PlanError::NotOnGraph { which, x, y } } else { PlanError::Unmapped { which, x, y } }
        })
    }

    /// The vertices of edge `e` from its source node to its target node (into `out`); false
    /// when `e` is not a live edge.
    pub(super) fn edge_points(&self, e: EdgeIndex<u32>, out: &mut Vec<Point2>) -> bool {
        out.clear();
        let (Some((a, b)), Some(d)) = (self.graph.edge_endpoints(e), self.graph.edge_weight(e)) else {
            return false;
        };
        out.push(self.graph[a].position);
        out.extend_from_slice(&d.via);
        out.push(self.graph[b].position);
        true
    }

    pub(super) fn segment_samples(&self, a: Point2, b: Point2) -> Vec<u32> {
        let Some(map) = &self.map else {
            return Vec::new();
        };
        let steps = ((a.distance(b) / self.params.graph.edge_sample_spacing_m).ceil() as usize).max(1);
        (0..=steps)
            .filter_map(|k| map.spec.cell_at(a + (b - a) * (k as f64 / steps as f64)).map(|c| map.spec.index(c) as u32))
            .collect()
    }

    /// Plans the most probable path from `from` to `to` (A* over the graph; the start and goal
    /// attach to the nodes whose regions cover them).
    pub fn plan(&mut self, from: Point2, to: Point2) -> Result<GlobalPath, PlanError> {
        self.plan_avoiding(from, to, &[])
    }

    /// [`GlobalPlanner::plan`] without the edges between the given node pairs (either order):
    /// for a caller's own experience the scans could not give, such as an edge the robot failed
    /// to get across. The edges stay in the graph, with their state; pairs that are not edges
    /// are ignored.
    ///
    /// The start and the goal attach to the nodes whose regions cover them (the start to a
    /// nearby node instead when the straight leg to its covering node crosses ground the scans
    /// voted untraversable: [`Self::open_attachment`]). When no path joins
    /// those two, the search is tried again from and to the nodes around each point (the nearest
    /// within 15 m (`DETOUR_ATTACH_M`), by a straight leg over covered ground that the scans have not
    /// voted untraversable), and the cheapest path wins. Without this, a robot whose covering
    /// node lost all its edges (a parking lot whose straight edges the scans saw through parked
    /// vehicles) could plan nowhere, although it can drive to the next node.
    pub fn plan_avoiding(
        &mut self,
        from: Point2,
        to: Point2,
        avoid: &[(NodeId, NodeId)],
    ) -> Result<GlobalPath, PlanError> {
        let covering = self.attach(from, "start")?;
        let start = self.open_attachment(from, covering);
        let goal = self.attach(to, "goal")?;
        let mut avoided: Vec<(u32, u32)> =
            avoid.iter().map(|&(a, b)| if a.0 <= b.0 { (a.0, b.0) } else { (b.0, a.0) }).collect();
        avoided.sort_unstable();
        let (start, goal, graph_cost, nodes) = match self.search(start, goal, &avoided) {
            Some((cost, nodes)) => (start, goal, cost, nodes),
            None => self.detour_search(from, to, start, goal, &avoided).ok_or(PlanError::NoPath)?,
        };
        let mut edges = Vec::with_capacity(nodes.len().saturating_sub(1));
        for w in nodes.windows(2) {
            let e = self.graph.find_edge(w[0], w[1]).ok_or(PlanError::NoPath)?;
            edges.push(EdgeId(e.index() as u32));
        }
        let mut waypoints = Vec::with_capacity(nodes.len() + 2);
        let mut node_waypoints = Vec::with_capacity(nodes.len());
        waypoints.push(from);
        for (k, &n) in nodes.iter().enumerate() {
            if k > 0 {
                let e = EdgeIndex::new(edges[k - 1].0 as usize);
                let forward = self.graph.edge_endpoints(e).is_some_and(|(src, _)| src == nodes[k - 1]);
                let via = &self.graph[e].via;
                if forward {
                    waypoints.extend(via.iter().copied());
                } else {
                    waypoints.extend(via.iter().rev().copied());
                }
            }
            node_waypoints.push(waypoints.len());
            waypoints.push(self.graph[n].position);
        }
        waypoints.push(to);
        let length_m = waypoints.windows(2).map(|w| w[0].distance(w[1])).sum();
        let head = self.segment_samples(from, self.graph[start].position);
        let tail = self.segment_samples(self.graph[goal].position, to);
        let attach_cost = self.base_cost(&head) + self.base_cost(&tail);
        Ok(GlobalPath {
            waypoints,
            cost: graph_cost + attach_cost,
            length_m,
            edges,
            nodes: nodes.iter().map(|n| NodeId(n.index() as u32)).collect(),
            node_waypoints,
            graph_cost,
            lead_in: 0,
        })
    }

    /// The node a path from `from` starts at: `covering`, the node whose region covers `from`,
    /// when the straight leg to it is open ([`Self::leg_is_open`]); otherwise the nearest node
    /// around `from` that a straight open leg reaches ([`Self::detour_legs`]), or `covering` when
    /// none does. Regions are grown on the aerial map, which does not show a roadblock labelled
    /// road: a robot that drove up to one stands in the region of the node beyond it, and the
    /// leg to that node is no graph edge, so no scan or failed drive can remove it. The robot's
    /// scans do vote the ground at the block untraversable, which closes the leg.
    fn open_attachment(&mut self, from: Point2, covering: NodeIndex<u32>) -> NodeIndex<u32> {
        if self.leg_is_open(from, self.graph[covering].position) {
            return covering;
        }
        self.detour_legs(from, covering).into_iter().map(|(n, _)| n).find(|&n| n != covering).unwrap_or(covering)
    }

    /// A* between two nodes over the live edges minus the avoided pairs: the graph cost and
    /// the nodes.
    pub(super) fn search(
        &self,
        start: NodeIndex<u32>,
        goal: NodeIndex<u32>,
        avoided: &[(u32, u32)],
    ) -> Option<(f64, Vec<NodeIndex<u32>>)> {
        let graph = &self.graph;
        let goal_pos = graph[goal].position;
        let rate = self.min_cost_per_m;
        let allowed = petgraph::visit::EdgeFiltered::from_fn(
            graph,
            |e: petgraph::stable_graph::EdgeReference<'_, EdgeData, u32>| {
                avoided.binary_search(&pair(e.source(), e.target())).is_err()
            },
        );
        petgraph::algo::astar(
            &allowed,
            start,
            |n| n == goal,
            |e| e.weight().cost,
            |n| rate * graph[n].position.distance(goal_pos),
        )
    }

    /// The cheapest path over the nodes around the start and the goal (see
    /// [`GlobalPlanner::plan_avoiding`]): start node, goal node, graph cost and nodes.
    pub(super) fn detour_search(
        &mut self,
        from: Point2,
        to: Point2,
        start: NodeIndex<u32>,
        goal: NodeIndex<u32>,
        avoided: &[(u32, u32)],
    ) -> Option<Detour> {
        let starts = self.detour_legs(from, start);
        let goals = self.detour_legs(to, goal);
        let mut best: Option<(f64, Detour)> = None;
        for &(s, s_cost) in &starts {
            for &(g, g_cost) in &goals {
                if (s, g) == (start, goal) || best.as_ref().is_some_and(|b| s_cost + g_cost >= b.0) {
                    continue;
                }
                if let Some((cost, nodes)) = self.search(s, g, avoided) {
                    let total = s_cost + cost + g_cost;
                    if best.as_ref().is_none_or(|b| total < b.0) {
                        best = Some((total, (s, g, cost, nodes)));
                    }
                }
            }
        }
        best.map(|(_, detour)| detour)
    }

    /// The attachment node of `p` and the nodes around it that a straight leg reaches over
    /// covered ground not voted untraversable, nearest first, with the legs' costs.
    pub(super) fn detour_legs(&mut self, p: Point2, home: NodeIndex<u32>) -> Vec<(NodeIndex<u32>, f64)> {
        let mut near: Vec<(f64, NodeIndex<u32>)> = self
            .graph
            .node_indices()
            .filter(|&n| n != home)
            .map(|n| (p.distance(self.graph[n].position), n))
            .filter(|&(d, _)| d <= DETOUR_ATTACH_M)
            .collect();
        near.sort_unstable_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
        let mut legs = vec![home];
        legs.extend(
            near.into_iter()
                .map(|(_, n)| n)
                .filter(|&n| self.graph.neighbors(n).next().is_some())
                .filter(|&n| self.leg_is_open(p, self.graph[n].position))
                .take(MAX_DETOUR_LEGS),
        );
        legs.into_iter()
            .map(|n| {
                let samples = self.segment_samples(p, self.graph[n].position);
                (n, self.base_cost(&samples))
            })
            .collect()
    }

    /// Whether every cell of the straight leg from `p` to `node_at` lies in some node's region
    /// (so it cuts through nothing the graph leaves out, such as a building), none has as
    /// many untraversable votes as a training label needs, and it crosses no elevation step
    /// higher than `graph.max_step_m` (a curb). The first metre around `p` is not
    /// judged: a robot standing next to an obstacle sits among cells voted beyond its boundary.
    pub(super) fn leg_is_open(&self, p: Point2, node_at: Point2) -> bool {
        let Some(map) = &self.map else { return false };
        if let (Some(step), Some(a), Some(b)) =
            (self.params.graph.max_step_m, map.spec.cell_at(p), map.spec.cell_at(node_at))
            && EdgeRouter::crosses_step(map, a, b, step as f32)
        {
            return false;
        }
        let judge = self.params.experience.graph_updates;
        let blocked_votes = -(self.params.learning.votes_to_label.max(1) as i8);
        let length = p.distance(node_at);
        let steps = (length / map.spec.resolution_m.max(1e-3)).ceil() as usize;
        (0..=steps).all(|k| {
            let t = if steps == 0 { 0.0 } else { k as f64 / steps as f64 };
            map.spec.cell_at(p + (node_at - p) * t).is_some_and(|c| {
                let i = map.spec.index(c);
                self.owner[i] != NO_NODE && (!judge || t * length < 1.0 || self.votes.net(i) > blocked_votes)
            })
        })
    }
}
