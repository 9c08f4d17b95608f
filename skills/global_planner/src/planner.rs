//! The global planner: traversability graph over the aerial map, learned traversability, edge
//! states from experience, and graph search.

use std::collections::{HashMap, HashSet};

use petgraph::Undirected;
use petgraph::stable_graph::{EdgeIndex, NodeIndex, StableGraph};
use petgraph::visit::EdgeRef;
use rand::Rng;
use serde::Serialize;
use spomp_core::{AerialMap, Cell, ClassId, ClassTable, Point2, ReachabilityScan, Time, UNKNOWN_CLASS};

use crate::coverage::{Coverage, CoverageInput, NO_NODE};
use crate::error::{PlanError, ScanError, SetupError};
use crate::experience::{EdgeExperience, EdgeState, Transition, Votes};
use crate::features::{ClassChange, Features};
use crate::mlp::{Mlp, TrainSettings};
use crate::params::GlobalPlannerParams;
use crate::routing::EdgeRouter;
use crate::star::{EdgeObservation, Judging, StarRegion, polyline_point_distance};
use spomp_raster::SquaredEdt;

/// Stable id of a graph node.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize)]
pub struct NodeId(pub u32);

/// Id of a graph edge. Ids of removed edges may be reused, so paths also keep the end nodes.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize)]
pub struct EdgeId(pub u32);

#[derive(Clone, Debug)]
struct NodeData {
    position: Point2,
    class: ClassId,
}

#[derive(Clone, Debug)]
struct EdgeData {
    /// Interior vertices of the edge's route, from its source node to its target node; empty
    /// for a straight edge (see [`crate::routing`]).
    via: Vec<Point2>,
    /// Length along the route, metres.
    length_m: f64,
    /// Row-major cells sampled along the route, every `edge_sample_spacing_m`, ends included.
    samples: Vec<u32>,
    /// Normalised features of the mapped samples, `channels` per sample (learning only):
    /// reweighting after a training round only runs the network.
    features: Vec<f32>,
    /// Cost from the map alone (learned or class-rank).
    base_cost: f64,
    /// Cost used by the search (base cost overridden by experience).
    cost: f64,
    experience: EdgeExperience,
}

/// A planned path.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct GlobalPath {
    /// Map-frame waypoints: the start, the graph nodes (with the interior vertices of edges
    /// routed around elevation steps between them), the goal.
    pub waypoints: Vec<Point2>,
    /// Total cost (−log probability of success, or class-rank weight with learning off).
    pub cost: f64,
    /// Length along the waypoints, metres.
    pub length_m: f64,
    /// Graph edges in order.
    pub edges: Vec<EdgeId>,
    /// Graph nodes in order.
    pub nodes: Vec<NodeId>,
    /// Index in `waypoints` of each of `nodes`.
    pub node_waypoints: Vec<usize>,
    /// Cost of the graph edges alone when planned (compared by [`GlobalPlanner::path_status`]).
    pub graph_cost: f64,
    /// Leading waypoints that come before the graph path's own start: a caller's route to
    /// where the graph path begins, such as the robot's own trail (0 from the planner). A caller
    /// that prepends waypoints shifts `node_waypoints` with them.
    pub lead_in: usize,
}

/// How far around a start or goal the planner looks for other nodes to attach to when the
/// covering nodes have no path between them, metres.
pub const DETOUR_ATTACH_M: f64 = 15.0;

/// A path found around the covering nodes: start node, goal node, graph cost, nodes.
type Detour = (NodeIndex<u32>, NodeIndex<u32>, f64, Vec<NodeIndex<u32>>);

/// At most this many nodes around a start or goal are tried besides the covering node.
const MAX_DETOUR_LEGS: usize = 6;

/// Whether a planned path is still good.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub enum PathStatus {
    /// Nothing relevant changed.
    Valid,
    /// The edges' cost rose by more than the replanning ratio.
    CostRose {
        /// Graph cost when planned.
        planned: f64,
        /// Graph cost now.
        current: f64,
    },
    /// An edge of the path has been removed.
    Blocked,
}

/// One edge, for drawing and inspection.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct EdgeView {
    /// Edge id.
    pub id: EdgeId,
    /// One end.
    pub from: Point2,
    /// The other end.
    pub to: Point2,
    /// Interior vertices from `from` to `to` of an edge routed around elevation steps; empty
    /// for a straight edge.
    pub via: Vec<Point2>,
    /// Search cost.
    pub cost: f64,
    /// Experience state.
    pub state: EdgeState,
}

/// Size of the graph and of the learning state.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize)]
pub struct GraphStats {
    /// Nodes.
    pub nodes: usize,
    /// Live edges.
    pub edges: usize,
    /// Edges removed for good (locked not_trav).
    pub removed_edges: usize,
    /// Edges marked trav.
    pub trav_edges: usize,
    /// Edges marked not_trav (removed or not).
    pub not_trav_edges: usize,
    /// Cells covered by some node's region.
    pub covered_cells: usize,
    /// Cells with enough votes to be training labels.
    pub labelled_cells: usize,
    /// Edges routed around elevation steps instead of straight (ever made, removed or not).
    pub routed_edges: usize,
    /// Training rounds run.
    pub training_rounds: usize,
}

/// What a map update did.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize)]
pub struct MapUpdate {
    /// Nodes added.
    pub nodes_added: usize,
    /// Edges added.
    pub edges_added: usize,
}

/// What a scan did.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize)]
pub struct ScanUpdate {
    /// Cells that received a vote.
    pub cells_voted: usize,
    /// Edges judged trav / not_trav / unk_trav by this scan (near the scan only).
    pub observed: [usize; 3],
    /// Edges whose state changed.
    pub edges_changed: usize,
    /// Edges removed for good.
    pub edges_removed: usize,
}

/// Result of [`GlobalPlanner::train`].
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub enum TrainOutcome {
    /// Learning is off.
    Disabled,
    /// Less than the training period since the last round.
    TooSoon,
    /// Not enough labelled cells yet.
    NotEnoughLabels {
        /// Labels available.
        labels: usize,
    },
    /// A round ran and the edge costs were refreshed.
    Trained {
        /// Labels trained on.
        labels: usize,
        /// Mean cross-entropy over the last batches.
        loss: f32,
    },
}

/// The global ground planner of one robot.
#[derive(Debug)]
pub struct GlobalPlanner {
    params: GlobalPlannerParams,
    classes: ClassTable,
    /// Coverage stage of each class (`u8::MAX`: never covered).
    stage_of_class: [u8; 256],
    stages: usize,
    /// Rank of each class (unknown = impassable).
    rank_of_class: [u8; 256],
    map: Option<AerialMap>,
    graph: StableGraph<NodeData, EdgeData, Undirected, u32>,
    owner: Vec<u32>,
    edge_of_pair: HashMap<(u32, u32), EdgeIndex<u32>>,
    removed_pairs: HashSet<(u32, u32)>,
    coverage: Coverage,
    edt: SquaredEdt,
    features: Features,
    model: Mlp,
    votes: Votes,
    last_train: Option<Time>,
    training_rounds: usize,
    min_cost_per_m: f64,
    feature_scratch: Vec<f32>,
    train_x: Vec<f32>,
    train_y: Vec<bool>,
    region: StarRegion,
    judged: Vec<(EdgeIndex<u32>, EdgeObservation)>,
    edge_ids: Vec<EdgeIndex<u32>>,
    segment_features: Vec<f32>,
    router: EdgeRouter,
    /// Edges routed around elevation steps (see [`crate::routing`]).
    routed_edges: usize,
}

/// Inclusive cell box `(col0, row0, col1, row1)` of the cells whose class differs between two
/// maps on the same grid; `None` when no class changed.
fn changed_class_box(old: &AerialMap, new: &AerialMap) -> Option<[usize; 4]> {
    let w = new.spec.width as usize;
    let mut b: Option<[usize; 4]> = None;
    for (i, (a, c)) in old.class.iter().zip(&new.class).enumerate() {
        if a != c {
            let (col, row) = (i % w.max(1), i / w.max(1));
            b = Some(match b {
                None => [col, row, col, row],
                Some([c0, r0, c1, r1]) => [c0.min(col), r0.min(row), c1.max(col), r1.max(row)],
            });
        }
    }
    b
}

/// Length of a polyline.
fn polyline_length(points: &[Point2]) -> f64 {
    points.windows(2).map(|w| w[0].distance(w[1])).sum()
}

/// Row-major cells under samples along a polyline, about `spacing` apart on each piece, the
/// vertices included once each.
fn polyline_samples(map: &AerialMap, points: &[Point2], spacing: f64) -> Vec<u32> {
    let mut samples = Vec::new();
    for (k, w) in points.windows(2).enumerate() {
        let (pa, pb) = (w[0], w[1]);
        let steps = ((pa.distance(pb) / spacing).ceil() as usize).max(1);
        let first = if k == 0 { 0 } else { 1 };
        samples.extend((first..=steps).filter_map(|i| {
            let p = pa + (pb - pa) * (i as f64 / steps as f64);
            map.spec.cell_at(p).map(|c| map.spec.index(c) as u32)
        }));
    }
    samples
}

fn pair(a: NodeIndex<u32>, b: NodeIndex<u32>) -> (u32, u32) {
    let (a, b) = (a.index() as u32, b.index() as u32);
    if a < b { (a, b) } else { (b, a) }
}

impl GlobalPlanner {
    /// A planner with no map yet.
    pub fn new(params: GlobalPlannerParams, classes: ClassTable) -> Result<Self, SetupError> {
        params.validate()?;
        let g = &params.graph;
        let order: Vec<ClassId> = if g.class_order.is_empty() {
            let ranks = classes.rank_lut();
            classes.easiest_first().into_iter().filter(|&c| ranks[c as usize] <= g.max_class_rank).collect()
        } else {
            g.class_order
                .iter()
                .map(|name| {
                    classes.by_name(name).map(|c| c.index).ok_or_else(|| SetupError::UnknownClass {
                        name: name.clone(),
                        known: classes.names().join(", "),
                    })
                })
                .collect::<Result<_, _>>()?
        };
        let mut stage_of_class = [u8::MAX; 256];
        let mut stages = 0;
        for &c in &order {
            if stage_of_class[c as usize] == u8::MAX && stages < u8::MAX as usize {
                stage_of_class[c as usize] = stages as u8;
                stages += 1;
            }
        }
        let resolution = 0.5;
        let features = Features::new(&classes);
        let model = Mlp::new(features.channels(), params.learning.hidden_units);
        Ok(GlobalPlanner {
            coverage: Coverage::new((g.visibility_range_m / resolution).round() as i32),
            rank_of_class: classes.rank_lut(),
            feature_scratch: vec![0.0; features.channels()],
            features,
            model,
            stage_of_class,
            stages,
            classes,
            params,
            map: None,
            graph: StableGraph::default(),
            owner: Vec::new(),
            edge_of_pair: HashMap::new(),
            removed_pairs: HashSet::new(),
            edt: SquaredEdt::default(),
            votes: Votes::default(),
            last_train: None,
            training_rounds: 0,
            min_cost_per_m: 0.0,
            train_x: Vec::new(),
            train_y: Vec::new(),
            region: StarRegion::default(),
            judged: Vec::new(),
            edge_ids: Vec::new(),
            segment_features: Vec::new(),
            router: EdgeRouter::default(),
            routed_edges: 0,
        })
    }

    /// The parameters.
    pub fn params(&self) -> &GlobalPlannerParams {
        &self.params
    }

    /// The class table.
    pub fn classes(&self) -> &ClassTable {
        &self.classes
    }

    /// Takes in the current aerial map (the first map, or the same grid grown by tiles): covers
    /// newly mapped cells with new nodes, connects them, refreshes features and edge costs. Edge
    /// states, removed edges and votes are kept.
    pub fn update_map(&mut self, map: &AerialMap) -> Result<MapUpdate, SetupError> {
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
            && old.version == map.version
            && old.class == map.class
            && old.rgb == map.rgb
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
        let changed_box = self.map.as_ref().map(|old| changed_class_box(old, map));
        match &mut self.map {
            Some(m) => m.clone_from(map),
            None => self.map = Some(map.clone()),
        }
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
        Ok(MapUpdate { nodes_added: self.graph.node_count() - nodes_before, edges_added })
    }

    fn cover_new_cells(&mut self) {
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
    fn connect_touching_regions(&mut self) -> usize {
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
        // The router's clearance and components are computed once per update, when first needed.
        let mut router_ready = false;
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
            let via = match (max_step, map.spec.cell_at(pa), map.spec.cell_at(pb)) {
                (Some(step), Some(ca), Some(cb)) if EdgeRouter::crosses_step(map, ca, cb, step) => {
                    if !router_ready {
                        self.router.prepare(map, &self.owner, step);
                        router_ready = true;
                    }
                    self.router.route(map, &self.owner, ca, cb, reach, step).unwrap_or_default()
                }
                _ => Vec::new(),
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
            };
            let e = self.graph.add_edge(na, nb, data);
            self.edge_of_pair.insert((a, b), e);
            added += 1;
        }
        added
    }

    /// Cost of the cells sampled along a segment from the map alone.
    fn base_cost(&mut self, samples: &[u32]) -> f64 {
        let Some(map) = &self.map else { return 0.0 };
        if !self.params.learning.enabled {
            return self.class_rank_cost(map, samples);
        }
        let channels = self.features.channels();
        let mut feats = std::mem::take(&mut self.segment_features);
        feats.clear();
        for &s in samples {
            feats.resize(feats.len() + channels, 0.0);
            let start = feats.len() - channels;
            if !self.features.fill(map, s as usize, &mut feats[start..]) {
                feats.truncate(start);
            }
        }
        let cost = self.learned_cost(&feats, samples.len());
        self.segment_features = feats;
        cost
    }

    /// Σ −log T over `n_samples` samples, of which the rows of `features` are the mapped ones:
    /// the mean over mapped samples × `n_samples` (paper); −log 0.5 per sample when nothing is
    /// mapped or the model is untrained.
    fn learned_cost(&mut self, features: &[f32], n_samples: usize) -> f64 {
        let n = n_samples.max(1) as f64;
        let channels = self.features.channels();
        let known = features.len() / channels.max(1);
        if !self.model.is_trained() || known == 0 {
            return n * std::f64::consts::LN_2;
        }
        let floor = self.params.learning.probability_floor.clamp(1e-12, 0.5);
        let mut sum = 0.0;
        for row in features.chunks_exact(channels) {
            let t = self.model.probability(row) as f64;
            let t = if t.is_finite() { t.clamp(floor, 1.0) } else { floor };
            sum -= t.ln();
        }
        sum / known as f64 * n
    }

    /// The learning-off ablation: W = 100^T_cls − 1 + D, T_cls the rank of the hardest class on
    /// the edge, D the least distance from a sample to the next harder class present.
    fn class_rank_cost(&self, map: &AerialMap, samples: &[u32]) -> f64 {
        let mut hardest: Option<u8> = None;
        for &s in samples {
            let c = map.class.get(s as usize).copied().unwrap_or(UNKNOWN_CLASS);
            if c != UNKNOWN_CLASS {
                let r = self.rank_of_class[c as usize];
                hardest = Some(hardest.map_or(r, |h: u8| h.max(r)));
            }
        }
        let t_cls = hardest.unwrap_or(self.params.graph.max_class_rank);
        let next_rank = self.classes.classes.iter().map(|c| c.rank).filter(|&r| r > t_cls).min();
        let mut d = self.params.learning.class_distance_cap_m;
        if let Some(next) = next_rank {
            for &s in samples {
                for c in self.classes.classes.iter().filter(|c| c.rank == next) {
                    d = d.min(self.features.class_distance_m(s as usize, c.index) as f64);
                }
            }
        }
        100f64.powi(t_cls as i32) - 1.0 + d
    }

    fn experienced_cost(&self, base: f64, n_samples: usize, exp: &EdgeExperience) -> f64 {
        let p = &self.params.experience;
        let n = n_samples.max(1) as f64;
        let nll = |prob: f64| -prob.clamp(1e-12, 1.0).ln();
        match exp.state {
            EdgeState::Unknown => base,
            EdgeState::Trav => base.min(n * nll(p.trav_sample_probability)),
            EdgeState::NotTrav => base + n * nll(p.not_trav_sample_probability),
        }
    }

    /// Recomputes every edge's cost; `map_changed` also refreshes the cached sample features.
    fn refresh_all_costs(&mut self, map_changed: bool) {
        let mut ids = std::mem::take(&mut self.edge_ids);
        ids.clear();
        ids.extend(self.graph.edge_indices());
        let learning = self.params.learning.enabled;
        for &e in &ids {
            let Some(d) = self.graph.edge_weight_mut(e) else { continue };
            let mut samples = std::mem::take(&mut d.samples);
            let mut feats = std::mem::take(&mut d.features);
            let base = if !learning {
                self.base_cost(&samples)
            } else {
                if map_changed || (feats.is_empty() && !samples.is_empty()) {
                    self.base_cost(&samples);
                    std::mem::swap(&mut feats, &mut self.segment_features);
                }
                self.learned_cost(&feats, samples.len())
            };
            if let Some(d) = self.graph.edge_weight_mut(e) {
                std::mem::swap(&mut d.samples, &mut samples);
                std::mem::swap(&mut d.features, &mut feats);
                d.base_cost = base;
            }
            self.refresh_edge_cost(e);
        }
        self.edge_ids = ids;
        self.refresh_heuristic_rate();
    }

    fn refresh_edge_cost(&mut self, e: EdgeIndex<u32>) {
        let Some(d) = self.graph.edge_weight(e) else {
            return;
        };
        let cost = self.experienced_cost(d.base_cost, d.samples.len(), &d.experience);
        if let Some(d) = self.graph.edge_weight_mut(e) {
            d.cost = cost;
        }
    }

    /// Least cost per metre over all edges: A*'s heuristic rate, admissible by construction.
    fn refresh_heuristic_rate(&mut self) {
        let mut rate = f64::INFINITY;
        for d in self.graph.edge_weights() {
            if d.length_m > 1e-9 {
                rate = rate.min(d.cost / d.length_m);
            } else {
                rate = rate.min(0.0);
            }
        }
        self.min_cost_per_m = if rate.is_finite() { rate.max(0.0) } else { 0.0 };
    }

    /// Takes in a reachability scan: its cells vote for training labels, and (with graph updates
    /// on) every edge near it is judged trav / not_trav / unk_trav. `own` is true for the robot's
    /// own scans; other robots' scans can never remove an edge.
    pub fn add_scan(&mut self, scan: &ReachabilityScan, own: bool) -> Result<ScanUpdate, ScanError> {
        let mut region = std::mem::take(&mut self.region);
        let loaded = region.load(scan, self.params.learning.max_scan_range_m);
        let mut update = ScanUpdate::default();
        if loaded.is_ok() && self.map.is_some() {
            if self.params.learning.enabled {
                update.cells_voted = self.vote(&region);
            }
            if self.params.experience.graph_updates {
                self.judge_edges(&region, own, &mut update);
            }
        }
        self.region = region;
        loaded.map(|()| update)
    }

    fn vote(&mut self, region: &StarRegion) -> usize {
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

    fn judge_edges(&mut self, region: &StarRegion, own: bool, update: &mut ScanUpdate) {
        let x = &self.params.experience;
        let judging = Judging {
            window_rad: x.crossing_window_rad,
            on_edge_radius_m: x.on_edge_radius_m,
            min_crossing_range_m: x.min_crossing_range_m,
        };
        let mut changed = std::mem::take(&mut self.judged);
        changed.clear();
        let mut points = Vec::new();
        for e in self.graph.edge_indices() {
            if !self.edge_points(e, &mut points) {
                continue;
            }
            if polyline_point_distance(&points, region.origin) > region.max_range_m {
                continue;
            }
            let obs = region.classify_polyline(&points, &judging);
            update.observed[match obs {
                EdgeObservation::Trav => 0,
                EdgeObservation::NotTrav => 1,
                EdgeObservation::UnkTrav => 2,
            }] += 1;
            if obs != EdgeObservation::UnkTrav {
                changed.push((e, obs));
            }
        }
        let params = self.params.experience.clone();
        for &(e, obs) in &changed {
            let Some(d) = self.graph.edge_weight_mut(e) else {
                continue;
            };
            // An edge routed through a passage the aerial elevation shows (a curb ramp) is
            // marked, never removed, by the robot's own not_trav observations, as by other
            // robots': seen from beside the passage, a scan's safe region ends at the corner of
            // the curb, whatever the passage holds. Being stuck on it still blocks it for the
            // robot (the navigation's own record).
            let removable = own && d.via.is_empty();
            match d.experience.observe(obs, removable, &params) {
                Transition::None => {}
                Transition::Changed => {
                    update.edges_changed += 1;
                    self.refresh_edge_cost(e);
                }
                Transition::Removed => {
                    update.edges_changed += 1;
                    update.edges_removed += 1;
                    if let Some((a, b)) = self.graph.edge_endpoints(e) {
                        let key = pair(a, b);
                        self.removed_pairs.insert(key);
                        self.edge_of_pair.remove(&key);
                    }
                    self.graph.remove_edge(e);
                }
            }
        }
        self.judged = changed;
        if update.edges_changed > 0 {
            self.refresh_heuristic_rate();
        }
    }

    /// Runs a training round if learning is on, at least the training period passed since the
    /// last round and enough cells are labelled; then refreshes every edge's cost.
    pub fn train(&mut self, now: Time, rng: &mut impl Rng) -> TrainOutcome {
        let l = &self.params.learning;
        if !l.enabled {
            return TrainOutcome::Disabled;
        }
        if let Some(last) = self.last_train
            && now.secs_since(last) < l.train_period_s
        {
            return TrainOutcome::TooSoon;
        }
        let Some(map) = &self.map else {
            return TrainOutcome::NotEnoughLabels { labels: 0 };
        };
        let channels = self.features.channels();
        self.train_x.clear();
        self.train_y.clear();
        self.feature_scratch.resize(channels, 0.0);
        for (cell, label) in self.votes.labels(l.votes_to_label) {
            if self.features.fill(map, cell, &mut self.feature_scratch) {
                self.train_x.extend_from_slice(&self.feature_scratch);
                self.train_y.push(label);
            }
        }
        let labels = self.train_y.len();
        if labels < l.min_labels.max(1) {
            return TrainOutcome::NotEnoughLabels { labels };
        }
        let settings = TrainSettings {
            l2: l.l2_regularization as f32,
            step_size: l.step_size as f32,
            decay: l.rmsprop_decay as f32,
            epsilon: l.rmsprop_epsilon as f32,
            batch_size: l.batch_size.max(1),
            samples: l.samples_per_round,
        };
        let loss = self.model.train(&self.train_x, &self.train_y, settings, rng);
        self.last_train = Some(now);
        self.training_rounds += 1;
        self.refresh_all_costs(false);
        TrainOutcome::Trained { labels, loss }
    }

    /// Learned probability that the cell under `p` is traversable (0.5 before training); `None`
    /// off the map or on unmapped cells.
    pub fn traversability_at(&mut self, p: Point2) -> Option<f64> {
        if !(p.x.is_finite() && p.y.is_finite()) {
            return None;
        }
        let map = self.map.as_ref()?;
        let cell = map.spec.cell_at(p)?;
        let i = map.spec.index(cell);
        if !self.features.fill(map, i, &mut self.feature_scratch) {
            return None;
        }
        Some(self.model.probability(&self.feature_scratch) as f64)
    }

    /// The node whose region covers the cell under `p`, or the nearest covered cell's within
    /// the attach radius; without one, [`PlanError::Unmapped`] when the map has no data at `p`,
    /// else [`PlanError::NotOnGraph`].
    fn attach(&self, p: Point2, which: &'static str) -> Result<NodeIndex<u32>, PlanError> {
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
    fn edge_points(&self, e: EdgeIndex<u32>, out: &mut Vec<Point2>) -> bool {
        out.clear();
        let (Some((a, b)), Some(d)) = (self.graph.edge_endpoints(e), self.graph.edge_weight(e)) else {
            return false;
        };
        out.push(self.graph[a].position);
        out.extend_from_slice(&d.via);
        out.push(self.graph[b].position);
        true
    }

    fn segment_samples(&self, a: Point2, b: Point2) -> Vec<u32> {
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
    /// The start and the goal attach to the nodes whose regions cover them. When no path joins
    /// those two, the search is tried again from and to the nodes around each point (the nearest
    /// within [`DETOUR_ATTACH_M`], by a straight leg over covered ground that the scans have not
    /// voted untraversable), and the cheapest path wins. Without this, a robot whose covering
    /// node lost all its edges (a parking lot whose straight edges the scans saw through parked
    /// vehicles) could plan nowhere, although it can drive to the next node.
    pub fn plan_avoiding(
        &mut self,
        from: Point2,
        to: Point2,
        avoid: &[(NodeId, NodeId)],
    ) -> Result<GlobalPath, PlanError> {
        let start = self.attach(from, "start")?;
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

    /// A* between two nodes over the live edges minus the avoided pairs: the graph cost and
    /// the nodes.
    fn search(
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
    fn detour_search(
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
    fn detour_legs(&mut self, p: Point2, home: NodeIndex<u32>) -> Vec<(NodeIndex<u32>, f64)> {
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
    fn leg_is_open(&self, p: Point2, node_at: Point2) -> bool {
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

    /// Whether the straight line from `a` to `b` crosses an elevation step higher than
    /// `graph.max_step_m` on the aerial map (a curb); false without a map, off the map, or with
    /// the step limit off.
    pub fn crosses_step(&self, a: Point2, b: Point2) -> bool {
        let (Some(map), Some(step)) = (&self.map, self.params.graph.max_step_m) else { return false };
        match (map.spec.cell_at(a), map.spec.cell_at(b)) {
            (Some(ca), Some(cb)) => EdgeRouter::crosses_step(map, ca, cb, step as f32),
            _ => false,
        }
    }

    /// Current cost of a path's graph edges; `None` when one of them has been removed.
    pub fn path_graph_cost(&self, path: &GlobalPath) -> Option<f64> {
        if path.nodes.len() != path.edges.len() + 1 {
            return None;
        }
        let mut cost = 0.0;
        for (k, e) in path.edges.iter().enumerate() {
            let idx = EdgeIndex::new(e.0 as usize);
            let (a, b) = self.graph.edge_endpoints(idx)?;
            let want = (path.nodes[k].0, path.nodes[k + 1].0);
            let got = (a.index() as u32, b.index() as u32);
            if got != want && got != (want.1, want.0) {
                return None;
            }
            cost += self.graph.edge_weight(idx)?.cost;
        }
        Some(cost)
    }

    /// Whether a planned path is still valid, its cost rose past the replanning ratio, or an
    /// edge on it was removed.
    pub fn path_status(&self, path: &GlobalPath) -> PathStatus {
        match self.path_graph_cost(path) {
            None => PathStatus::Blocked,
            Some(current) => {
                let ratio = self.params.search.replan_cost_rise_ratio.max(0.0);
                if current > path.graph_cost * (1.0 + ratio) + 1e-9 {
                    PathStatus::CostRose { planned: path.graph_cost, current }
                } else {
                    PathStatus::Valid
                }
            }
        }
    }

    /// Shorthand: `path_status(path) == PathStatus::Valid`.
    pub fn path_still_valid(&self, path: &GlobalPath) -> bool {
        self.path_status(path) == PathStatus::Valid
    }

    /// Every live edge.
    pub fn edges(&self) -> impl Iterator<Item = EdgeView> + '_ {
        self.graph.edge_indices().filter_map(move |e| {
            let (a, b) = self.graph.edge_endpoints(e)?;
            let d = self.graph.edge_weight(e)?;
            Some(EdgeView {
                id: EdgeId(e.index() as u32),
                from: self.graph[a].position,
                to: self.graph[b].position,
                via: d.via.clone(),
                cost: d.cost,
                state: d.experience.state,
            })
        })
    }

    /// Positions of every node with the class it was placed on.
    pub fn nodes(&self) -> impl Iterator<Item = (NodeId, Point2, ClassId)> + '_ {
        self.graph.node_indices().map(move |n| (NodeId(n.index() as u32), self.graph[n].position, self.graph[n].class))
    }

    /// The node whose region covers the cell under `p`, if any.
    pub fn covering_node(&self, p: Point2) -> Option<NodeId> {
        if !(p.x.is_finite() && p.y.is_finite()) {
            return None;
        }
        let map = self.map.as_ref()?;
        let c = map.spec.cell_at(p)?;
        let o = *self.owner.get(map.spec.index(c))?;
        (o != NO_NODE).then_some(NodeId(o))
    }

    /// Id of the live edge between two nodes.
    pub fn edge_between(&self, a: NodeId, b: NodeId) -> Option<EdgeId> {
        let key = if a.0 < b.0 { (a.0, b.0) } else { (b.0, a.0) };
        self.edge_of_pair.get(&key).map(|e| EdgeId(e.index() as u32))
    }

    /// State of an edge; `None` for ids that are not live edges.
    pub fn edge_state(&self, e: EdgeId) -> Option<EdgeState> {
        self.graph.edge_weight(EdgeIndex::new(e.0 as usize)).map(|d| d.experience.state)
    }

    /// Net training votes of the cell under `p` (positive: traversable).
    pub fn votes_at(&self, p: Point2) -> i8 {
        self.map.as_ref().and_then(|m| m.spec.cell_at(p).map(|c| m.spec.index(c))).map_or(0, |i| self.votes.net(i))
    }

    /// Sizes of the graph and the learning state.
    pub fn graph_stats(&self) -> GraphStats {
        let mut s = GraphStats {
            nodes: self.graph.node_count(),
            edges: self.graph.edge_count(),
            removed_edges: self.removed_pairs.len(),
            covered_cells: self.owner.iter().filter(|&&o| o != NO_NODE).count(),
            labelled_cells: self.votes.labels(self.params.learning.votes_to_label).count(),
            training_rounds: self.training_rounds,
            routed_edges: self.routed_edges,
            ..Default::default()
        };
        for d in self.graph.edge_weights() {
            match d.experience.state {
                EdgeState::Trav => s.trav_edges += 1,
                EdgeState::NotTrav => s.not_trav_edges += 1,
                EdgeState::Unknown => {}
            }
        }
        s.not_trav_edges += s.removed_edges;
        s
    }
}
