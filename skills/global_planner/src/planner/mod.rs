//! The global planner: traversability graph over the aerial map, learned traversability, edge
//! states from experience, and graph search.

use std::collections::{HashMap, HashSet};
use std::sync::Arc;

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
use crate::star::{EdgeObservation, Judging, StarRegion, Verdict, polyline_point_distance};
use spomp_raster::SquaredEdt;

mod costs;
mod experience;
mod graph;
mod search;

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
    /// Raw features of the mapped samples, packed ([`Features::pack`], learning only):
    /// reweighting after a training round only unpacks them and runs the network.
    features: Vec<u8>,
    /// Cost from the map alone (learned or class-rank).
    base_cost: f64,
    /// Cost used by the search (base cost overridden by experience).
    cost: f64,
    experience: EdgeExperience,
    /// A straight edge up a curb: it crosses a low step (above the climb limit, at most
    /// [`CURB_MAX_RISE_M`]) that no route within the two regions avoids. With
    /// `graph.curbs_last_resort`, until a scan finds it traversable it is a last resort
    /// ([`LAST_RESORT_COST`]).
    up_curb: bool,
}

/// Steps up to this rise are curbs: low enough that terrain analysis cannot judge them from
/// afar (a scan sees a 0.15 m curb only near), unlike a parked vehicle's side or a wall, which
/// the scans judge like any obstacle. Metres.
pub const CURB_MAX_RISE_M: f32 = 0.5;

/// Added to the cost of an edge straight up a curb ([`EdgeData::up_curb`]) while no scan found
/// it traversable, with `graph.curbs_last_resort` and graph updates on: a path takes one only
/// when nothing else joins its two sides. Such an edge's scans mostly say unk_trav (the
/// crossing is seen from afar, or is too near), so without it a robot is sent to the foot of a
/// curb it cannot climb.
pub const LAST_RESORT_COST: f64 = 1e9;

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
    /// Live edges straight up a curb no route avoids (the last resorts of a search).
    pub edges_up_curbs: usize,
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
    /// Not_trav observations of the robot's own scan whose crossing was a ground teammate's
    /// body ([`GlobalPlanner::add_own_scan_among`]): marks only, never removals.
    pub at_teammates: usize,
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
#[derive(Clone, Debug)]
pub struct GlobalPlanner {
    params: GlobalPlannerParams,
    classes: ClassTable,
    /// Coverage stage of each class (`u8::MAX`: never covered).
    stage_of_class: [u8; 256],
    stages: usize,
    /// Rank of each class (unknown = impassable).
    rank_of_class: [u8; 256],
    /// The map the graph was built on: shared with the robot's own copy (and, for a prior
    /// map, with the whole team), never copied here.
    map: Option<Arc<AerialMap>>,
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
    /// A training round's labelled cells (cell index, traversable).
    train_cells: Vec<(usize, bool)>,
    /// The processor's widest instruction set, detected once (see [`Self::learned_cost_packed`]).
    simd: pulp::Arch,
    region: StarRegion,
    judged: Vec<(EdgeIndex<u32>, EdgeObservation, bool)>,
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
            train_cells: Vec::new(),
            simd: pulp::Arch::new(),
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
            s.edges_up_curbs += usize::from(d.up_curb);
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
