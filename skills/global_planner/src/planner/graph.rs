//! Graph building: nodes placed greedily over the aerial map's coverage, regions ray traced
//! around each, edges between touching regions, kept current as the map grows.

#[allow(clippy::wildcard_imports)]
use super::*;

impl GlobalPlanner {
    /// Takes in the current aerial map (the first map, or the same grid grown by tiles): covers
    /// newly mapped cells with new nodes, connects them, refreshes features and edge costs. Edge
    /// states, removed edges and votes are kept. The planner keeps a copy of the map; a caller
    /// that holds it in an [`Arc`] gives it with [`Self::update_map_shared`] instead.
    pub fn update_map(&mut self, map: &AerialMap) -> Result<MapUpdate, SetupError> {
        self.update_map_shared(Arc::new(map.clone()))
    }

    /// [`Self::update_map`] with a map the caller shares: the planner holds this one, no copy.
    pub fn update_map_shared(&mut self, map: Arc<AerialMap>) -> Result<MapUpdate, SetupError> {
        let n = map.spec.len();
        if map.class.len() != n || map.rgb.len() != n || map.elevation.len() != n {
            return Err(SetupError::InvalidMap(format!(
                "{}×{} grid but {} class, {} rgb, {} elevation values",
                map.spec.width,
                map.spec.height,
                map.class.len(),
                map.rgb.len(),
                map.elevation.len()
            )));
        }
        let spec_ok = map.spec.resolution_m.is_finite()
            && map.spec.resolution_m > 0.0
            && map.spec.origin.x.is_finite()
            && map.spec.origin.y.is_finite();
        if !spec_ok {
            return Err(SetupError::InvalidMap("resolution or origin is not a positive finite number".into()));
        }
        if let Some(old) = &self.map
            && old.spec != map.spec
        {
            return Err(SetupError::MapGridChanged {
                built: format!("{:?}", old.spec),
                got: format!("{:?}", map.spec),
            });
        }
        if let Some(old) = &self.map
            && (Arc::ptr_eq(old, &map) || (old.version == map.version && old.class == map.class && old.rgb == map.rgb))
        {
            // Nothing new: keep the graph, features and costs as they are.
            return Ok(MapUpdate::default());
        }
        let radius_cells = (self.params.graph.visibility_range_m / map.spec.resolution_m).round();
        if radius_cells > 4096.0 {
            return Err(SetupError::InvalidMap(format!(
                "{} m cells make the visibility range {radius_cells} cells; at most 4096 are supported",
                map.spec.resolution_m
            )));
        }
        if self.map.is_none() {
            let radius = radius_cells as i32;
            if radius != self.coverage.radius_cells() {
                self.coverage = Coverage::new(radius);
            }
            self.owner = vec![NO_NODE; n];
            self.votes.resize(n);
        }
        let changed_box = self.map.as_ref().map(|old| changed_class_box(old, &map));
        self.map = Some(map);
        let nodes_before = self.graph.node_count();
        self.cover_new_cells();
        let edges_added = self.connect_touching_regions();
        if let Some(m) = &self.map {
            let change = match changed_box {
                None => ClassChange::All,
                Some(None) => ClassChange::None,
                Some(Some(b)) => ClassChange::Box(b),
            };
            self.features.rebuild(m, &mut self.edt, self.params.learning.class_distance_cap_m, change);
        }
        self.refresh_all_costs(true);
        // The coverage, routing and distance-transform scratch is map-sized (≈ 15 bytes a cell)
        // and only needed during an update: give it back rather than hold it per robot.
        self.coverage.release_scratch();
        self.router = EdgeRouter::default();
        self.edt = SquaredEdt::default();
        Ok(MapUpdate { nodes_added: self.graph.node_count() - nodes_before, edges_added })
    }

    pub(super) fn cover_new_cells(&mut self) {
        let Some(map) = &self.map else { return };
        let (w, h) = (map.spec.width as usize, map.spec.height as usize);
        for stage in 0..self.stages {
            let mut in_set = [false; 256];
            for (c, &s) in self.stage_of_class.iter().enumerate() {
                in_set[c] = (s as usize) <= stage;
            }
            in_set[UNKNOWN_CLASS as usize] = false;
            let input = CoverageInput { class: &map.class, width: w, height: h, in_set: &in_set };
            let graph = &mut self.graph;
            self.coverage.cover(&input, &mut self.owner, |cell| {
                let c = Cell::new((cell % w) as u32, (cell / w) as u32);
                let idx = graph.add_node(NodeData { position: map.spec.center(c), class: map.class[cell] });
                idx.index() as u32
            });
        }
    }

    /// Adds an edge between every two nodes whose covered regions share a cell side, unless the
    /// pair already has one or had one removed.
    pub(super) fn connect_touching_regions(&mut self) -> usize {
        let Some(map) = &self.map else { return 0 };
        let (w, h) = (map.spec.width as usize, map.spec.height as usize);
        let mut pairs = Vec::new();
        for row in 0..h {
            for col in 0..w {
                let i = row * w + col;
                let a = self.owner[i];
                if a == NO_NODE {
                    continue;
                }
                if col + 1 < w {
                    let b = self.owner[i + 1];
                    if b != NO_NODE && b != a {
                        pairs.push(if a < b { (a, b) } else { (b, a) });
                    }
                }
                if row + 1 < h {
                    let b = self.owner[i + w];
                    if b != NO_NODE && b != a {
                        pairs.push(if a < b { (a, b) } else { (b, a) });
                    }
                }
            }
        }
        pairs.sort_unstable();
        pairs.dedup();
        let spacing = self.params.graph.edge_sample_spacing_m;
        let max_step = self.params.graph.max_step_m.map(|s| s as f32);
        // Regions lie within the visibility range of their nodes.
        let reach = self.coverage.radius_cells() + 1;
        // The router computes its clearance and components once per update, when a route it
        // is asked for is not remembered from another planner of the process.
        let mut added = 0;
        for (a, b) in pairs {
            if self.edge_of_pair.contains_key(&(a, b)) || self.removed_pairs.contains(&(a, b)) {
                continue;
            }
            let (na, nb) = (NodeIndex::new(a as usize), NodeIndex::new(b as usize));
            let (Some(pa), Some(pb)) = (self.graph.node_weight(na), self.graph.node_weight(nb)) else {
                continue;
            };
            let (pa, pb) = (pa.position, pb.position);
            let (via, up_curb) = match (max_step, map.spec.cell_at(pa), map.spec.cell_at(pb)) {
                (Some(step), Some(ca), Some(cb)) => {
                    let rise = EdgeRouter::largest_step(map, ca, cb);
                    if rise > step {
                        let via = self.router.route(map, &self.owner, ca, cb, reach, step).unwrap_or_default();
                        let up_curb = via.is_empty() && rise <= CURB_MAX_RISE_M;
                        (via, up_curb)
                    } else {
                        (Vec::new(), false)
                    }
                }
                _ => (Vec::new(), false),
            };
            if !via.is_empty() {
                self.routed_edges += 1;
            }
            let mut points = Vec::with_capacity(via.len() + 2);
            points.push(pa);
            points.extend_from_slice(&via);
            points.push(pb);
            let length_m = polyline_length(&points);
            let samples = polyline_samples(map, &points, spacing);
            let data = EdgeData {
                via,
                length_m,
                samples,
                features: Vec::new(),
                base_cost: 0.0,
                cost: 0.0,
                experience: EdgeExperience::default(),
                up_curb,
            };
            let e = self.graph.add_edge(na, nb, data);
            self.edge_of_pair.insert((a, b), e);
            added += 1;
        }
        added
    }
}
