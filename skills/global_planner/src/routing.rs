//! Routing an edge around elevation steps: where the straight line between two nodes crosses a
//! step a UGV cannot drive over (a curb, a parked vehicle's side, a pole), the edge follows a
//! step-free route through the two nodes' regions instead, when there is one (a curb ramp).
//!
//! The paper connects nodes whose regions touch with straight edges and lets experience prune
//! the ones that cannot be driven. Between a road region and a sidewalk region that touch along
//! a whole curb, the straight edge crosses the curb almost always, and a ramp that the aerial
//! map shows (its elevation rises gently where the curb is a step) would never be on any edge.
//! Following the ramp keeps the graph's topology (one edge per touching pair) and its costs
//! (sampled along the route), and experience still judges the route as it judges any edge.

use std::cmp::Reverse;
use std::collections::BinaryHeap;

use spomp_core::{AerialMap, Cell, Point2};
use spomp_raster::{SharedMemo, fingerprint};

use crate::coverage::{NO_NODE, bresenham};

/// Routes searched by any planner of the process, by what the search read: a 72-byte key and
/// the route's few vertices an answer (a 5-UGV bench run asks 1 869 distinct questions, 5 230
/// in all).
static ROUTES: SharedMemo<RouteKey, Option<Vec<Point2>>> = SharedMemo::new(16_384);

/// Forgets the routes every planner of the process searched: the next map update searches its
/// routes anew (for benchmarks of a planner on its own; results never depend on it).
pub fn forget_shared_routes() {
    ROUTES.clear();
}

/// Everything a route search reads (see [`EdgeRouter::route_key`]).
#[derive(Clone, Debug, PartialEq, Eq, Hash)]
struct RouteKey {
    cells: [u32; 4],
    reach: i32,
    max_step_bits: u32,
    grid: [u64; 4],
    contents: [u64; 2],
}

/// One route asked for: from node cell `a` to node cell `b` within `reach` cells of the two,
/// over steps of at most `max_step_m`.
#[derive(Clone, Copy, Debug)]
struct Question {
    a: Cell,
    b: Cell,
    reach: i32,
    max_step_m: f32,
}

impl Question {
    /// The cells the route may use (first and last column and row): within `reach` of either
    /// end, inside the map.
    fn search_box(&self, map: &AerialMap) -> (i32, i32, i32, i32) {
        let (a, b, reach) = (self.a, self.b, self.reach);
        let (w, h) = (map.spec.width as i32, map.spec.height as i32);
        let c0 = (a.col.min(b.col) as i32 - reach).max(0);
        let r0 = (a.row.min(b.row) as i32 - reach).max(0);
        let c1 = (a.col.max(b.col) as i32 + reach).min(w - 1);
        let r1 = (a.row.max(b.row) as i32 + reach).min(h - 1);
        (c0, r0, c1, r1)
    }
}

/// Whether the step between two cells' elevations can be driven: unknown elevations are no
/// evidence of a step.
fn step_ok(a: f32, b: f32, max_step_m: f32) -> bool {
    !(a.is_finite() && b.is_finite()) || (a - b).abs() <= max_step_m
}

/// Visits the cells under the straight line between the centres of cells `p` and `q`, in order,
/// sampled a quarter cell apart (a cell may be visited several times in a row).
fn walk_cells(p: (i32, i32), q: (i32, i32), mut visit: impl FnMut((i32, i32))) {
    let (dx, dy) = ((q.0 - p.0) as f64, (q.1 - p.1) as f64);
    let steps = (4.0 * dx.abs().max(dy.abs())).ceil().max(1.0) as i32;
    for k in 0..=steps {
        let t = k as f64 / steps as f64;
        let (x, y) = (p.0 as f64 + dx * t, p.1 as f64 + dy * t);
        visit(((x + 0.5).floor() as i32, (y + 0.5).floor() as i32));
    }
}

/// Scratch buffers for routing, reused across the edges of one map update and dropped after it
/// (the planner replaces the router: clearance and components are map-sized).
#[derive(Clone, Debug, Default)]
pub(crate) struct EdgeRouter {
    /// Distance in cells (Chebyshev) from each map cell to the nearest cell beside a step,
    /// capped at [`CLEARANCE_CELLS`] (see [`EdgeRouter::prepare`]).
    clearance: Vec<u8>,
    /// Each covered cell's component of step-free 4-connected covered ground ([`NO_NODE`]
    /// for uncovered cells): two cells in different components have no route between them.
    component: Vec<u32>,
    stack: Vec<u32>,
    cost: Vec<u32>,
    parent: Vec<u32>,
    heap: BinaryHeap<Reverse<(u32, u32)>>,
    cells: Vec<(i32, i32)>,
    /// The search box with a one-cell border, row-major (`bw + 2` wide): whether each cell is
    /// covered (the border never is), so the search's neighbour tests need no bounds checks.
    box_owned: Vec<bool>,
    /// The elevations of the same padded box (NaN on the border, never read there).
    box_elev: Vec<f32>,
    /// The bytes a route's key is fingerprinted from.
    key_bytes: Vec<u8>,
    /// The step limit (bits) the clearance and components were computed for, once computed: a
    /// router serves one map and coverage (the planner replaces it after each update).
    prepared_for: Option<u32>,
}

/// Octile move costs in tenths of a cell.
const ORTHOGONAL: u32 = 10;
const DIAGONAL: u32 = 14;
const UNSEEN: u32 = u32::MAX;
/// Cells (0.5 m each) a route keeps from a step when it can: about the reach of a UGV's
/// reachability scan on flat ground, so a route crosses this band straight on (a ramp is met
/// head-on) and runs up a ramp's middle.
const CLEARANCE_CELLS: u8 = 6;
/// Extra cost per cell of missing clearance, in the units of [`ORTHOGONAL`].
const CLEARANCE_PENALTY: u32 = 15;
/// Inside the band near a step, a route keeps a vertex every this many chain cells.
const TIGHT_VERTEX_CELLS: usize = 2;
/// A route moves only between cells whose elevations differ by at most this share of the step
/// limit: terrain analysis flags a rise above half the limit as an obstacle when near (the
/// clearance's "noticeable" rise), although the robot could climb it, so a route up a ramp's
/// side flank, within the limit, was one the local planner would not drive (a UGV stood at a
/// ramp's foot with its look-ahead over the flank). A ramp rises a few centimetres a cell.
const PASSABLE_STEP_SHARE: f32 = 0.5;

impl EdgeRouter {
    /// The largest elevation difference between two cells consecutive on the digital line from
    /// `a` to `b` (cells without an elevation are skipped), metres.
    pub fn largest_step(map: &AerialMap, a: Cell, b: Cell) -> f32 {
        let w = map.spec.width as usize;
        let mut prev: Option<f32> = None;
        let mut largest = 0.0f32;
        bresenham((a.col as i32, a.row as i32), (b.col as i32, b.row as i32), |c, r| {
            let e = map.elevation[r as usize * w + c as usize];
            if let Some(p) = prev
                && p.is_finite()
                && e.is_finite()
            {
                largest = largest.max((p - e).abs());
            }
            prev = Some(e);
        });
        largest
    }

    /// Whether the digital line from `a` to `b` passes between two cells (consecutive on the
    /// line) whose elevations differ by more than `max_step_m` (positive).
    pub fn crosses_step(map: &AerialMap, a: Cell, b: Cell, max_step_m: f32) -> bool {
        Self::largest_step(map, a, b) > max_step_m
    }

    /// Computes the clearance and the step-free components of the covered ground for the map
    /// and coverage `owner` as they are now. [`EdgeRouter::route`] calls it when it first needs
    /// them; call it again (or take a fresh router) after the map or the coverage changed.
    pub fn prepare(&mut self, map: &AerialMap, owner: &[u32], max_step_m: f32) {
        self.prepared_for = Some(max_step_m.to_bits());
        let (w, h) = (map.spec.width as usize, map.spec.height as usize);
        let n = w * h;
        let elev = &map.elevation;
        // Clearance: cells beside a rise of more than half the step limit are 0 (terrain
        // analysis flags such a rise when near, although the robot could climb it), then a
        // Chebyshev distance by two chamfer passes.
        let noticeable = PASSABLE_STEP_SHARE * max_step_m;
        self.clearance.clear();
        self.clearance.resize(n, CLEARANCE_CELLS);
        for r in 0..h {
            for c in 0..w {
                let i = r * w + c;
                let right = c + 1 < w && !step_ok(elev[i], elev[i + 1], noticeable);
                let up = r + 1 < h && !step_ok(elev[i], elev[i + w], noticeable);
                if right {
                    self.clearance[i] = 0;
                    self.clearance[i + 1] = 0;
                }
                if up {
                    self.clearance[i] = 0;
                    self.clearance[i + w] = 0;
                }
            }
        }
        // Forward pass (left, up-left, up, up-right), then backward (right, down-right, down,
        // down-left), each in index order: row by row with the borders tested once per row,
        // not four neighbours' bounds per cell (the same minima in the same order).
        let cl = &mut self.clearance;
        for r in 0..h {
            let row = r * w;
            for c in 0..w {
                let i = row + c;
                let mut best = cl[i];
                if c > 0 {
                    best = best.min(cl[i - 1].saturating_add(1));
                }
                if r > 0 {
                    let up = i - w;
                    best = best.min(cl[up].saturating_add(1));
                    if c > 0 {
                        best = best.min(cl[up - 1].saturating_add(1));
                    }
                    if c + 1 < w {
                        best = best.min(cl[up + 1].saturating_add(1));
                    }
                }
                cl[i] = best;
            }
        }
        for r in (0..h).rev() {
            let row = r * w;
            for c in (0..w).rev() {
                let i = row + c;
                let mut best = cl[i];
                if c + 1 < w {
                    best = best.min(cl[i + 1].saturating_add(1));
                }
                if r + 1 < h {
                    let down = i + w;
                    best = best.min(cl[down].saturating_add(1));
                    if c + 1 < w {
                        best = best.min(cl[down + 1].saturating_add(1));
                    }
                    if c > 0 {
                        best = best.min(cl[down - 1].saturating_add(1));
                    }
                }
                cl[i] = best;
            }
        }
        // Components by flood fill over 4-neighbours and the rises a route may take (a diagonal
        // move needs both cells beside it, so 8-connected routes join 4-connected cells only).
        self.component.clear();
        self.component.resize(n, NO_NODE);
        let (component, stack) = (&mut self.component, &mut self.stack);
        let mut next = 0u32;
        for seed in 0..n {
            if owner[seed] == NO_NODE || component[seed] != NO_NODE {
                continue;
            }
            component[seed] = next;
            stack.clear();
            stack.push(seed as u32);
            while let Some(i) = stack.pop() {
                let i = i as usize;
                let (c, r) = (i % w, i / w);
                let mut visit = |j: usize| {
                    if owner[j] != NO_NODE && component[j] == NO_NODE && step_ok(elev[i], elev[j], noticeable) {
                        component[j] = next;
                        stack.push(j as u32);
                    }
                };
                if c + 1 < w {
                    visit(i + 1);
                }
                if c > 0 {
                    visit(i - 1);
                }
                if r + 1 < h {
                    visit(i + w);
                }
                if r > 0 {
                    visit(i - w);
                }
            }
            next += 1;
        }
    }

    /// A step-free route from node cell `a` to node cell `b` over covered cells (`owner[i] !=
    /// NO_NODE`: ground the graph covers, so not a building), searched within `reach` cells of
    /// the two, keeping clear of steps where it can: the interior vertices of the route after
    /// string pulling (each straight piece stays on covered cells, crosses no step and keeps as
    /// far from steps as the cells it replaces), or `None` when the two cells are not joined
    /// that way. The route may pass through other nodes' regions: a ramp is often covered by a
    /// third node, or split between two.
    pub fn route(
        &mut self,
        map: &AerialMap,
        owner: &[u32],
        a: Cell,
        b: Cell,
        reach: i32,
        max_step_m: f32,
    ) -> Option<Vec<Point2>> {
        let question = Question { a, b, reach, max_step_m };
        let w = map.spec.width as i32;
        let (c0, r0, c1, r1) = question.search_box(map);
        let owned = |c: i32, r: i32| {
            (c0..=c1).contains(&c) && (r0..=r1).contains(&r) && owner[r as usize * w as usize + c as usize] != NO_NODE
        };
        let (ac, ar, bc, br) = (a.col as i32, a.row as i32, b.col as i32, b.row as i32);
        if !owned(ac, ar) || !owned(bc, br) {
            return None;
        }
        if self.prepared_for != Some(max_step_m.to_bits()) {
            self.prepare(map, owner, max_step_m);
        }
        let component_of = |c: i32, r: i32| self.component.get(r as usize * w as usize + c as usize).copied();
        if component_of(ac, ar).is_none_or(|k| k == NO_NODE) || component_of(ac, ar) != component_of(bc, br) {
            return None;
        }
        // Past the components, the search reads only the box: robots that grew their graphs
        // over the same map ask the same questions, and each answer is searched once. (Keyed
        // after the components test, which is nearly free: a planner alone pays for a key only
        // where it searches anyway.)
        let key = self.route_key(map, owner, &question);
        if let Some(known) = ROUTES.get(&key) {
            return known;
        }
        let found = self.search(map, owner, &question);
        ROUTES.remember(key, found.clone());
        found
    }

    /// What [`Self::route`]'s search reads, as a key: the two cells, the box, the grid, and
    /// fingerprints of the box's coverage and of the elevations the search and the clearance
    /// inside the box depend on (the box widened by the clearance band and the cell beside it).
    fn route_key(&mut self, map: &AerialMap, owner: &[u32], question: &Question) -> RouteKey {
        let Question { a, b, reach, max_step_m } = *question;
        let (w, h) = (map.spec.width as i32, map.spec.height as i32);
        let (c0, r0, c1, r1) = question.search_box(map);
        let bytes = &mut self.key_bytes;
        bytes.clear();
        for r in r0..=r1 {
            let start = r as usize * w as usize;
            let row = &owner[start + c0 as usize..=start + c1 as usize];
            bytes.extend(row.iter().map(|&o| u8::from(o != NO_NODE)));
        }
        let margin = CLEARANCE_CELLS as i32 + 1;
        let (mc0, mc1) = ((c0 - margin).max(0) as usize, (c1 + margin).min(w - 1) as usize);
        for r in (r0 - margin).max(0)..=(r1 + margin).min(h - 1) {
            let start = r as usize * w as usize;
            for e in &map.elevation[start + mc0..=start + mc1] {
                bytes.extend_from_slice(&e.to_bits().to_le_bytes());
            }
        }
        RouteKey {
            cells: [a.col, a.row, b.col, b.row],
            reach,
            max_step_bits: max_step_m.to_bits(),
            grid: [
                map.spec.origin.x.to_bits(),
                map.spec.origin.y.to_bits(),
                map.spec.resolution_m.to_bits(),
                (u64::from(map.spec.width) << 32) | u64::from(map.spec.height),
            ],
            contents: [fingerprint(bytes, 0), fingerprint(bytes, 1)],
        }
    }

    /// The A* and string pulling of [`Self::route`], for two covered cells of one component.
    fn search(&mut self, map: &AerialMap, owner: &[u32], question: &Question) -> Option<Vec<Point2>> {
        let Question { a, b, max_step_m, .. } = *question;
        let max_step_m = PASSABLE_STEP_SHARE * max_step_m;
        let w = map.spec.width as i32;
        let (c0, r0, c1, r1) = question.search_box(map);
        let (bw, bh) = ((c1 - c0 + 1) as usize, (r1 - r0 + 1) as usize);
        self.cost.clear();
        self.cost.resize(bw * bh, UNSEEN);
        self.parent.clear();
        self.parent.resize(bw * bh, u32::MAX);
        self.heap.clear();
        let global = |c: i32, r: i32| r as usize * w as usize + c as usize;
        let local = |c: i32, r: i32| (r - r0) as usize * bw + (c - c0) as usize;
        let owned =
            |c: i32, r: i32| (c0..=c1).contains(&c) && (r0..=r1).contains(&r) && { owner[global(c, r)] != NO_NODE };
        let elev = |c: i32, r: i32| map.elevation[global(c, r)];
        let can_step = |(c, r): (i32, i32), (d, s): (i32, i32)| step_ok(elev(c, r), elev(d, s), max_step_m);
        let (ac, ar, bc, br) = (a.col as i32, a.row as i32, b.col as i32, b.row as i32);
        let clearance = &self.clearance;
        let penalty = |c: i32, r: i32| (CLEARANCE_CELLS - clearance[global(c, r)]) as u32 * CLEARANCE_PENALTY;
        let heuristic = |c: i32, r: i32| {
            let (dx, dy) = ((c - bc).unsigned_abs(), (r - br).unsigned_abs());
            ORTHOGONAL * dx.max(dy) + (DIAGONAL - ORTHOGONAL) * dx.min(dy)
        };
        // The box copied once, padded by a cell that is never covered: the eight neighbours of
        // any covered cell are then in range, and a move is tested on two small arrays.
        let pw = bw + 2;
        self.box_owned.clear();
        self.box_owned.resize(pw * (bh + 2), false);
        self.box_elev.clear();
        self.box_elev.resize(pw * (bh + 2), f32::NAN);
        for r in r0..=r1 {
            let row_start = global(c0, r);
            let owners = &owner[row_start..row_start + bw];
            let elevations = &map.elevation[row_start..row_start + bw];
            let padded = (r - r0 + 1) as usize * pw + 1;
            for (k, (&o, &e)) in owners.iter().zip(elevations).enumerate() {
                self.box_owned[padded + k] = o != NO_NODE;
                self.box_elev[padded + k] = e;
            }
        }
        let (box_owned, box_elev) = (&self.box_owned, &self.box_elev);
        let step_between = |p: usize, q: usize| step_ok(box_elev[p], box_elev[q], max_step_m);
        self.cost[local(ac, ar)] = 0;
        self.heap.push(Reverse((heuristic(ac, ar), local(ac, ar) as u32)));
        let goal = local(bc, br) as u32;
        let mut found = false;
        while let Some(Reverse((_, i))) = self.heap.pop() {
            if i == goal {
                found = true;
                break;
            }
            let (lc, lr) = (i as usize % bw, i as usize / bw);
            let (c, r) = (lc as i32 + c0, lr as i32 + r0);
            let here = (lr + 1) * pw + lc + 1;
            let g = self.cost[i as usize];
            for (dc, dr) in [(1, 0), (-1, 0), (0, 1), (0, -1), (1, 1), (1, -1), (-1, 1), (-1, -1)] {
                // Padded index of the cell `(dc, dr)` away: `here` is inside the border.
                let at = |dc: i32, dr: i32| here.wrapping_add_signed(dr as isize * pw as isize + dc as isize);
                let there = at(dc, dr);
                if !box_owned[there] || !step_between(here, there) {
                    continue;
                }
                let step = if dc != 0 && dr != 0 {
                    // No cutting a corner: both cells beside the diagonal must be drivable too.
                    let (side_a, side_b) = (at(dc, 0), at(0, dr));
                    let clear = |s: usize| box_owned[s] && step_between(here, s) && step_between(s, there);
                    if !(clear(side_a) && clear(side_b)) {
                        continue;
                    }
                    DIAGONAL
                } else {
                    ORTHOGONAL
                };
                let (nc, nr) = (c + dc, r + dr);
                let j = local(nc, nr);
                let ng = g + step + penalty(nc, nr);
                if ng < self.cost[j] {
                    self.cost[j] = ng;
                    self.parent[j] = i;
                    self.heap.push(Reverse((ng + heuristic(nc, nr), j as u32)));
                }
            }
        }
        if !found {
            return None;
        }
        // The cell chain from a to b.
        self.cells.clear();
        let mut i = goal;
        loop {
            self.cells.push(((i as usize % bw) as i32 + c0, (i as usize / bw) as i32 + r0));
            if i as usize == local(ac, ar) {
                break;
            }
            i = self.parent[i as usize];
        }
        self.cells.reverse();
        // String pulling: from each anchor, the farthest cell of the chain a clear straight line
        // reaches.
        // A straight piece is clear when every cell it passes over (a corner passed
        // diagonally counts both cells beside it) is owned, no step lies along it, and it keeps
        // at least `keep` cells from any step.
        let clear_line = |p: (i32, i32), q: (i32, i32), keep: u8| {
            let mut prev = p;
            let mut ok = true;
            walk_cells(p, q, |cell| {
                if !ok || cell == prev {
                    return;
                }
                let diagonal = cell.0 != prev.0 && cell.1 != prev.1;
                let sides_clear = !diagonal || {
                    let (s1, s2) = ((cell.0, prev.1), (prev.0, cell.1));
                    [s1, s2].iter().all(|&s| owned(s.0, s.1) && can_step(prev, s) && can_step(s, cell))
                };
                ok = owned(cell.0, cell.1)
                    && clearance[global(cell.0, cell.1)] >= keep
                    && can_step(prev, cell)
                    && sides_clear;
                prev = cell;
            });
            ok
        };
        let mut vertices = Vec::new();
        let mut anchor = 0;
        let last = self.cells.len() - 1;
        // On open ground (full clearance) a pulled piece reaches at most the next cell of the
        // band near a step, and keeps as far from steps as the cells of the chain it replaces.
        // Inside the band the route follows the chain, which the clearance cost makes cross the
        // band straight on: a robot meets a ramp head-on, and its scans along the way look up
        // the ramp rather than at the corner of the curb beside it.
        let chain_keep: Vec<u8> = self.cells.iter().map(|&(c, r)| clearance[global(c, r)]).collect();
        let tight = |i: usize| chain_keep[i] < CLEARANCE_CELLS;
        while anchor < last {
            let next = if tight(anchor) {
                let mut j = anchor + 1;
                while j < last && j - anchor < TIGHT_VERTEX_CELLS && tight(j) {
                    j += 1;
                }
                j
            } else {
                // Forward, up to the first cell no clear line reaches (cheap, and a chain of an
                // A* over a grid is straight-ish).
                let limit = (anchor + 1..=last).find(|&k| tight(k)).unwrap_or(last);
                let mut next = anchor + 1;
                let mut keep = chain_keep[anchor].min(chain_keep[next]);
                for (j, &cell_keep) in chain_keep.iter().enumerate().take(limit + 1).skip(anchor + 2) {
                    keep = keep.min(cell_keep);
                    if !clear_line(self.cells[anchor], self.cells[j], keep) {
                        break;
                    }
                    next = j;
                }
                next
            };
            if next < last {
                let (c, r) = self.cells[next];
                vertices.push(map.spec.center(Cell::new(c as u32, r as u32)));
            }
            anchor = next;
        }
        Some(vertices)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use spomp_core::GridSpec;

    /// A 20 × 20 cell map: a 0.15 m step along row 10 (rows ≥ 10 raised) except a ramp over
    /// columns 14..17 rising across rows 10..13.
    fn curb_map() -> AerialMap {
        let spec = GridSpec::new(Point2::new(0.0, 0.0), 0.5, 20, 20);
        let mut map = AerialMap::unknown(spec);
        for row in 0..20u32 {
            for col in 0..20u32 {
                let i = spec.index(Cell::new(col, row));
                map.class[i] = 0;
                map.elevation[i] = if row < 10 {
                    0.0
                } else if (14..17).contains(&col) && row < 13 {
                    0.15 * (row - 9) as f32 / 4.0
                } else {
                    0.15
                };
            }
        }
        map
    }

    /// The coverage of [`curb_map`]: node 1 owns the low side, node 2 the raised side (ramp
    /// included).
    fn two_sides() -> Vec<u32> {
        (0..400).map(|i| if i / 20 < 10 { 1 } else { 2 }).collect()
    }

    /// A fresh router's route on `map` covered by [`two_sides`] (0.1 m step limit).
    fn route_over_two_sides(map: &AerialMap, a: Cell, b: Cell) -> Option<Vec<Point2>> {
        let owner = two_sides();
        let mut router = EdgeRouter::default();
        router.prepare(map, &owner, 0.1);
        router.route(map, &owner, a, b, 30, 0.1)
    }

    #[test]
    fn a_straight_line_over_the_curb_crosses_a_step_one_over_the_ramp_does_not() {
        let map = curb_map();
        assert!(EdgeRouter::crosses_step(&map, Cell::new(5, 5), Cell::new(5, 15), 0.1));
        assert!(!EdgeRouter::crosses_step(&map, Cell::new(15, 5), Cell::new(15, 15), 0.1));
        assert!(!EdgeRouter::crosses_step(&map, Cell::new(5, 5), Cell::new(5, 15), 0.2), "a higher limit");
    }

    #[test]
    fn the_route_goes_up_the_ramp_and_every_piece_is_step_free() {
        let map = curb_map();
        let (a, b) = (Cell::new(4, 4), Cell::new(4, 16));
        let vias = route_over_two_sides(&map, a, b).expect("a route up the ramp");
        assert!(!vias.is_empty());
        let mut points = vec![map.spec.center(a)];
        points.extend(&vias);
        points.push(map.spec.center(b));
        for w in points.windows(2) {
            let (p, q) = (map.spec.cell_at(w[0]).unwrap(), map.spec.cell_at(w[1]).unwrap());
            assert!(!EdgeRouter::crosses_step(&map, p, q, 0.1), "piece {:?} → {:?} crosses the curb", w[0], w[1]);
        }
        // It crosses row 10 on the ramp's columns.
        let on_ramp = points.windows(2).any(|w| {
            let (p, q) = (w[0], w[1]);
            (p.y < 5.0) != (q.y < 5.0) && {
                let t = (5.0 - p.y) / (q.y - p.y);
                let x = p.x + (q.x - p.x) * t;
                (7.0..8.5).contains(&x)
            }
        });
        assert!(on_ramp, "{points:?}");
    }

    /// The largest rise between consecutive cells under the route's pieces from `a` to `b`.
    fn largest_rise(map: &AerialMap, a: Cell, vias: &[Point2], b: Cell) -> f32 {
        let mut cells = vec![(a.col as i32, a.row as i32)];
        cells.extend(vias.iter().map(|&v| {
            let c = map.spec.cell_at(v).unwrap();
            (c.col as i32, c.row as i32)
        }));
        cells.push((b.col as i32, b.row as i32));
        let elev = |(c, r): (i32, i32)| map.elevation[map.spec.index(Cell::new(c as u32, r as u32))];
        let mut rise = 0.0f32;
        for w in cells.windows(2) {
            let mut prev = w[0];
            walk_cells(w[0], w[1], |cell| {
                rise = rise.max((elev(cell) - elev(prev)).abs());
                if cell.0 != prev.0 && cell.1 != prev.1 {
                    // Passing a corner: the robot's footprint covers both cells beside it.
                    for side in [(cell.0, prev.1), (prev.0, cell.1)] {
                        rise = rise.max((elev(side) - elev(prev)).abs()).max((elev(cell) - elev(side)).abs());
                    }
                }
                prev = cell;
            });
        }
        rise
    }

    #[test]
    fn a_route_leaves_a_ramp_where_it_meets_the_top_not_over_its_side() {
        // Regression: a route from the road to the raised ground just beside the ramp's foot
        // left the ramp over its side, a rise of 0.075 m: within the 0.1 m step limit, but
        // above half of it, which terrain analysis flags as an obstacle when near, so the local
        // planner would not drive it and the robot stood at the ramp's foot.
        let map = curb_map();
        let (a, b) = (Cell::new(15, 4), Cell::new(12, 10));
        let vias = route_over_two_sides(&map, a, b).expect("a route up the ramp");
        let rise = largest_rise(&map, a, &vias, b);
        assert!(rise <= 0.05 + 1e-6, "a rise of {rise} m on {vias:?}");
    }

    #[test]
    fn no_ramp_no_route_and_unknown_elevation_is_no_step() {
        let mut map = curb_map();
        for row in 10..13u32 {
            for col in 14..17u32 {
                map.elevation[map.spec.index(Cell::new(col, row))] = 0.15;
            }
        }
        assert_eq!(route_over_two_sides(&map, Cell::new(4, 4), Cell::new(4, 16)), None);
        // Cells the UAV has not measured: no evidence of a step.
        for col in 0..20u32 {
            map.elevation[map.spec.index(Cell::new(col, 10))] = f32::NAN;
        }
        assert!(!EdgeRouter::crosses_step(&map, Cell::new(5, 5), Cell::new(5, 15), 0.1));
        // Ground the graph does not cover (a building) is not used.
        let mut walled = two_sides();
        for (i, o) in walled.iter_mut().enumerate() {
            if i / 20 == 11 {
                *o = NO_NODE;
            }
        }
        let mut router = EdgeRouter::default();
        router.prepare(&map, &walled, 0.1);
        assert_eq!(router.route(&map, &walled, Cell::new(4, 4), Cell::new(4, 16), 30, 0.1), None);
    }

    #[test]
    fn a_route_is_searched_once_and_never_served_for_another_map() {
        let map = curb_map();
        let owner = two_sides();
        let (a, b) = (Cell::new(3, 4), Cell::new(3, 16));
        let mut first = EdgeRouter::default();
        first.prepare(&map, &owner, 0.1);
        let searched = first.route(&map, &owner, a, b, 30, 0.1);
        assert!(searched.is_some());
        let key = first.route_key(&map, &owner, &Question { a, b, reach: 30, max_step_m: 0.1 });
        assert_eq!(ROUTES.get(&key), Some(searched.clone()), "remembered");
        // Another planner asking the same question gets the same answer.
        let mut second = EdgeRouter::default();
        assert_eq!(second.route(&map, &owner, a, b, 30, 0.1), searched);
        // The ramp moved from columns 14..17 to 3..6: the two sides stay joined, so only the
        // memo's key tells the questions apart; a remembered answer would cross the curb at
        // the old ramp.
        let mut moved = map.clone();
        for row in 10..13u32 {
            for col in 14..17u32 {
                moved.elevation[moved.spec.index(Cell::new(col, row))] = 0.15;
            }
            for col in 3..6u32 {
                moved.elevation[moved.spec.index(Cell::new(col, row))] = 0.15 * (row - 9) as f32 / 4.0;
            }
        }
        second.prepare(&moved, &owner, 0.1);
        let vias = second.route(&moved, &owner, a, b, 30, 0.1).expect("a route up the moved ramp");
        let mut points = vec![moved.spec.center(a)];
        points.extend(&vias);
        points.push(moved.spec.center(b));
        let crossing_x = points.windows(2).find_map(|w| {
            let (p, q) = (w[0], w[1]);
            ((p.y < 5.0) != (q.y < 5.0)).then(|| p.x + (q.x - p.x) * (5.0 - p.y) / (q.y - p.y))
        });
        assert!(crossing_x.is_some_and(|x| (1.5..3.0).contains(&x)), "{points:?}");
    }

    #[test]
    fn a_route_key_covers_the_clearance_band_around_the_box_and_no_further() {
        // 60 columns; a box of reach 2 around columns 3..=5 ends at column 7.
        let spec = GridSpec::new(Point2::new(0.0, 0.0), 0.5, 60, 20);
        let mut map = AerialMap::unknown(spec);
        map.class.fill(0);
        map.elevation.fill(0.0);
        let owner = vec![1u32; 60 * 20];
        let (a, b) = (Cell::new(3, 10), Cell::new(5, 10));
        let mut router = EdgeRouter::default();
        let question = |max_step_m| Question { a, b, reach: 2, max_step_m };
        let key = router.route_key(&map, &owner, &question(0.1));
        let with_step_at = |col: u32| {
            let mut m = map.clone();
            m.elevation[spec.index(Cell::new(col, 10))] = 0.3;
            m
        };
        // A step within the clearance band (and the cell beside it) of the box may change the
        // clearance inside it: a new key.
        let near = with_step_at(7 + u32::from(CLEARANCE_CELLS) + 1);
        assert_ne!(router.route_key(&near, &owner, &question(0.1)), key);
        // Further out it cannot matter: the same key.
        let far = with_step_at(7 + u32::from(CLEARANCE_CELLS) + 3);
        assert_eq!(router.route_key(&far, &owner, &question(0.1)), key);
        // Coverage inside the box and the step limit count too.
        let mut walled = owner.clone();
        walled[10 * 60 + 4] = NO_NODE;
        assert_ne!(router.route_key(&map, &walled, &question(0.1)), key);
        assert_ne!(router.route_key(&map, &owner, &question(0.2)), key);
    }

    /// The clearance and components as first written (every cell testing its four chamfer
    /// neighbours' bounds): the row-wise passes must give the same tables.
    fn reference_prepare(map: &AerialMap, owner: &[u32], max_step_m: f32) -> (Vec<u8>, Vec<u32>) {
        let (w, h) = (map.spec.width as usize, map.spec.height as usize);
        let n = w * h;
        let elev = &map.elevation;
        let mut clearance = vec![CLEARANCE_CELLS; n];
        for r in 0..h {
            for c in 0..w {
                let i = r * w + c;
                if c + 1 < w && !step_ok(elev[i], elev[i + 1], 0.5 * max_step_m) {
                    clearance[i] = 0;
                    clearance[i + 1] = 0;
                }
                if r + 1 < h && !step_ok(elev[i], elev[i + w], 0.5 * max_step_m) {
                    clearance[i] = 0;
                    clearance[i + w] = 0;
                }
            }
        }
        let (wi, hi) = (w as i64, h as i64);
        for pass in 0..2 {
            let back: i64 = if pass == 0 { -1 } else { 1 };
            for k in 0..n {
                let i = if pass == 0 { k } else { n - 1 - k };
                let (c, r) = ((i % w) as i64, (i / w) as i64);
                let mut best = clearance[i];
                for (dc, dr) in [(back, 0), (back, back), (0, back), (-back, back)] {
                    let (nc, nr) = (c + dc, r + dr);
                    if nc >= 0 && nr >= 0 && nc < wi && nr < hi {
                        best = best.min(clearance[(nr * wi + nc) as usize].saturating_add(1));
                    }
                }
                clearance[i] = best;
            }
        }
        let mut component = vec![NO_NODE; n];
        let mut next = 0u32;
        for seed in 0..n {
            if owner[seed] == NO_NODE || component[seed] != NO_NODE {
                continue;
            }
            component[seed] = next;
            let mut stack = vec![seed];
            while let Some(i) = stack.pop() {
                let (c, r) = (i % w, i / w);
                let neighbours = [
                    (c + 1 < w).then(|| i + 1),
                    (c > 0).then(|| i - 1),
                    (r + 1 < h).then(|| i + w),
                    (r > 0).then(|| i - w),
                ];
                for j in neighbours.into_iter().flatten() {
                    if owner[j] != NO_NODE
                        && component[j] == NO_NODE
                        && step_ok(elev[i], elev[j], PASSABLE_STEP_SHARE * max_step_m)
                    {
                        component[j] = next;
                        stack.push(j);
                    }
                }
            }
            next += 1;
        }
        (clearance, component)
    }

    /// The clearance and component tables over a rough random map with holes in the coverage,
    /// unknown elevations and a non-square grid equal the per-cell reference's.
    #[test]
    fn prepared_tables_equal_the_per_cell_reference() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
        let spec = GridSpec::new(Point2::new(0.0, 0.0), 0.5, 73, 41);
        let mut map = AerialMap::unknown(spec);
        let mut owner = vec![NO_NODE; spec.len()];
        for ((class, elevation), owner) in map.class.iter_mut().zip(map.elevation.iter_mut()).zip(owner.iter_mut()) {
            *class = 0;
            *elevation = match rng.random_range(0..20) {
                0 => f32::NAN,
                1..=3 => 0.3,
                _ => rng.random_range(0.0..0.05),
            };
            if rng.random_range(0..6) > 0 {
                *owner = rng.random_range(0..9);
            }
        }
        let mut router = EdgeRouter::default();
        router.prepare(&map, &owner, 0.1);
        let (clearance, component) = reference_prepare(&map, &owner, 0.1);
        assert!(clearance.contains(&0) && clearance.iter().any(|&c| c > 1));
        assert_eq!(router.clearance, clearance);
        assert_eq!(router.component, component);
    }
}
