//! Greedy coverage of a class region by ray-traced visibility regions (paper §Graph Construction).
//!
//! Repeatedly: take the not-yet-covered cell farthest from the boundary of the uncovered region
//! (a distance transform), place a node there, ray trace the cells visible from it within the
//! visibility range (rays stop at cells outside the current class set), mark them covered by
//! that node. The distance transform is updated locally after each node: a covered region can
//! only shrink distances within the current maximum distance of it.

use spomp_raster::{FAR, SquaredEdt};

/// Bucket of a squared distance (cells²): quarter-cell steps of the distance.
fn bucket_of(dist_sq: f32) -> usize {
    (dist_sq.max(0.0).sqrt() * 4.0) as usize
}

/// Owner value of a cell no node covers.
pub(crate) const NO_NODE: u32 = u32::MAX;

/// Cell offsets of rays from the origin to the rim of a disc, stored flat.
#[derive(Clone, Debug, Default)]
struct RayTable {
    radius_cells: i32,
    offsets: Vec<(i32, i32)>,
    starts: Vec<usize>,
}

impl RayTable {
    fn build(radius_cells: i32) -> Self {
        let mut table = RayTable { radius_cells, offsets: Vec::new(), starts: vec![0] };
        let r = radius_cells.max(1);
        // Enough rays that neighbouring rim points are less than a cell apart.
        let rays = (8 * r).max(8);
        let mut last_end = None;
        for k in 0..rays {
            let a = k as f64 * std::f64::consts::TAU / rays as f64;
            let end = ((r as f64 * a.cos()).round() as i32, (r as f64 * a.sin()).round() as i32);
            if last_end == Some(end) {
                continue;
            }
            last_end = Some(end);
            bresenham((0, 0), end, |x, y| {
                if (x, y) != (0, 0) {
                    table.offsets.push((x, y));
                }
            });
            table.starts.push(table.offsets.len());
        }
        table
    }

    fn rays(&self) -> impl Iterator<Item = &[(i32, i32)]> + '_ {
        self.starts.windows(2).map(|w| &self.offsets[w[0]..w[1]])
    }
}

/// Visits the cells of the digital line from `a` to `b`, both included.
pub(crate) fn bresenham(a: (i32, i32), b: (i32, i32), mut visit: impl FnMut(i32, i32)) {
    let (mut x, mut y) = a;
    let dx = (b.0 - a.0).abs();
    let dy = -(b.1 - a.1).abs();
    let sx = if a.0 < b.0 { 1 } else { -1 };
    let sy = if a.1 < b.1 { 1 } else { -1 };
    let mut err = dx + dy;
    loop {
        visit(x, y);
        if (x, y) == b {
            break;
        }
        let e2 = 2 * err;
        if e2 >= dy {
            err += dy;
            x += sx;
        }
        if e2 <= dx {
            err += dx;
            y += sy;
        }
    }
}

/// The raster being covered.
pub(crate) struct CoverageInput<'a> {
    /// Class per cell (row-major).
    pub class: &'a [u8],
    /// Grid width, cells.
    pub width: usize,
    /// Grid height, cells.
    pub height: usize,
    /// Which classes belong to the region being covered.
    pub in_set: &'a [bool; 256],
}

/// Scratch state of the coverage, reused across stages and map updates.
#[derive(Clone, Debug, Default)]
pub(crate) struct Coverage {
    rays: RayTable,
    edt: SquaredEdt,
    dist: Vec<f32>,
    window: Vec<f32>,
    /// Bucket queue of region cells by distance (quarter-cell buckets): far cheaper than a
    /// binary heap for millions of cells, and ties within a quarter cell do not matter.
    buckets: Vec<Vec<u32>>,
    newly: Vec<u32>,
}

impl Coverage {
    /// Coverage with rays of `radius_cells`.
    pub fn new(radius_cells: i32) -> Self {
        Coverage { rays: RayTable::build(radius_cells), ..Default::default() }
    }

    /// Gives back the map-sized scratch (distances, window, buckets: about 9 bytes a cell).
    /// Coverage runs only when the map grows, while every UGV of a team holds a planner.
    pub fn release_scratch(&mut self) {
        let rays = std::mem::take(&mut self.rays);
        *self = Coverage { rays, ..Default::default() };
    }

    /// Covers every cell of the class set that `owner` does not cover yet. `place_node(cell)`
    /// creates a node at a cell and returns its id, which is written into `owner` for the cells
    /// it covers. Returns the number of nodes placed.
    pub fn cover(
        &mut self,
        input: &CoverageInput<'_>,
        owner: &mut [u32],
        mut place_node: impl FnMut(usize) -> u32,
    ) -> usize {
        let (w, h) = (input.width, input.height);
        let n = w * h;
        if n == 0 || input.class.len() < n || owner.len() < n {
            return 0;
        }
        let in_region = |i: usize, owner: &[u32]| owner[i] == NO_NODE && input.in_set[input.class[i] as usize];
        // Bounding box of the region: when the map grows by a tile, only the tile is uncovered,
        // and the distance transform need not look further than one cell around it.
        let (mut x0, mut y0, mut x1, mut y1) = (usize::MAX, usize::MAX, 0usize, 0usize);
        for row in 0..h {
            for col in 0..w {
                if in_region(row * w + col, owner) {
                    x0 = x0.min(col);
                    x1 = x1.max(col);
                    y0 = y0.min(row);
                    y1 = y1.max(row);
                }
            }
        }
        if x0 == usize::MAX {
            return 0;
        }
        let (x0, y0) = (x0.saturating_sub(1), y0.saturating_sub(1));
        let (x1, y1) = ((x1 + 1).min(w - 1), (y1 + 1).min(h - 1));
        let (ww, wh) = (x1 - x0 + 1, y1 - y0 + 1);
        self.window.clear();
        for row in y0..=y1 {
            self.window.extend((x0..=x1).map(|col| if in_region(row * w + col, owner) { FAR } else { 0.0 }));
        }
        self.edt.in_place(&mut self.window, ww, wh);
        // Only region cells are ever read from `dist`; the others keep stale values.
        self.dist.resize(n, 0.0);
        for b in &mut self.buckets {
            b.clear();
        }
        let mut top = 0usize;
        for row in y0..=y1 {
            // The map edge bounds the region too.
            let dy = (row + 1).min(h - row) as f32;
            for col in x0..=x1 {
                let i = row * w + col;
                if !in_region(i, owner) {
                    continue;
                }
                let dx = (col + 1).min(w - col) as f32;
                let d = self.window[(row - y0) * ww + (col - x0)].min(dx * dx).min(dy * dy);
                self.dist[i] = d;
                let k = bucket_of(d);
                if k >= self.buckets.len() {
                    self.buckets.resize_with(k + 1, Vec::new);
                }
                self.buckets[k].push(i as u32);
                top = top.max(k);
            }
        }

        let mut placed = 0;
        loop {
            while top > 0 && self.buckets[top].is_empty() {
                top -= 1;
            }
            let Some(cell) = self.buckets.get_mut(top).and_then(Vec::pop) else {
                break;
            };
            let i = cell as usize;
            if !in_region(i, owner) {
                continue;
            }
            let current = self.dist[i];
            let k = bucket_of(current);
            if k < top {
                // Stale: the distance shrank since this cell was filed.
                self.buckets[k].push(cell);
                continue;
            }
            let node = place_node(i);
            placed += 1;
            self.trace(input, owner, i, node);
            self.shrink_distances(input, owner, current);
        }
        placed
    }

    /// Marks the cells visible from `center` as covered by `node`, collecting them in `newly`.
    fn trace(&mut self, input: &CoverageInput<'_>, owner: &mut [u32], center: usize, node: u32) {
        let (w, h) = (input.width as i64, input.height as i64);
        let (cx, cy) = ((center % input.width) as i64, (center / input.width) as i64);
        self.newly.clear();
        owner[center] = node;
        self.newly.push(center as u32);
        for ray in self.rays.rays() {
            for &(dx, dy) in ray {
                let (x, y) = (cx + dx as i64, cy + dy as i64);
                if x < 0 || y < 0 || x >= w || y >= h {
                    break;
                }
                let i = (y * w + x) as usize;
                if !input.in_set[input.class[i] as usize] {
                    break;
                }
                if owner[i] == NO_NODE {
                    owner[i] = node;
                    self.newly.push(i as u32);
                }
            }
        }
    }

    /// Lowers the distances of uncovered cells near the newly covered ones. Only cells closer to
    /// them than `max_sq` (the largest squared distance left) can change.
    fn shrink_distances(&mut self, input: &CoverageInput<'_>, owner: &[u32], max_sq: f32) {
        let w = input.width;
        let (mut x0, mut y0, mut x1, mut y1) = (usize::MAX, usize::MAX, 0usize, 0usize);
        for &c in &self.newly {
            let (x, y) = (c as usize % w, c as usize / w);
            x0 = x0.min(x);
            y0 = y0.min(y);
            x1 = x1.max(x);
            y1 = y1.max(y);
        }
        if x0 == usize::MAX {
            return;
        }
        let reach = max_sq.max(0.0).sqrt().ceil() as usize + 1;
        let (x0, y0) = (x0.saturating_sub(reach), y0.saturating_sub(reach));
        let x1 = (x1 + reach).min(input.width - 1);
        let y1 = (y1 + reach).min(input.height - 1);
        let (ww, wh) = (x1 - x0 + 1, y1 - y0 + 1);
        self.window.clear();
        self.window.resize(ww * wh, FAR);
        for &c in &self.newly {
            let (x, y) = (c as usize % w, c as usize / w);
            self.window[(y - y0) * ww + (x - x0)] = 0.0;
        }
        self.edt.in_place(&mut self.window, ww, wh);
        for wy in 0..wh {
            let row = (y0 + wy) * w;
            for wx in 0..ww {
                let i = row + x0 + wx;
                if owner[i] == NO_NODE && input.in_set[input.class[i] as usize] {
                    let d = &mut self.dist[i];
                    *d = d.min(self.window[wy * ww + wx]);
                }
            }
        }
    }

    /// Radius of the rays, cells.
    pub fn radius_cells(&self) -> i32 {
        self.rays.radius_cells
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn set(classes: &[u8]) -> [bool; 256] {
        let mut s = [false; 256];
        for &c in classes {
            s[c as usize] = true;
        }
        s
    }

    #[test]
    fn bresenham_visits_both_ends_contiguously() {
        let mut cells = Vec::new();
        bresenham((0, 0), (5, -2), |x, y| cells.push((x, y)));
        assert_eq!(cells.first(), Some(&(0, 0)));
        assert_eq!(cells.last(), Some(&(5, -2)));
        assert_eq!(cells.len(), 6);
    }

    #[test]
    fn open_square_is_covered_by_first_node_at_its_centre() {
        let (w, h) = (21, 21);
        let class = vec![0u8; w * h];
        let mut owner = vec![NO_NODE; w * h];
        let mut nodes = Vec::new();
        let mut cov = Coverage::new(30);
        let n = cov.cover(&CoverageInput { class: &class, width: w, height: h, in_set: &set(&[0]) }, &mut owner, |c| {
            nodes.push(c);
            nodes.len() as u32 - 1
        });
        assert_eq!(n, 1);
        assert_eq!(nodes, vec![10 * w + 10], "farthest from the map edge is the centre");
        assert!(owner.iter().all(|&o| o == 0));
    }

    #[test]
    fn rays_stop_at_other_classes_and_every_cell_gets_covered() {
        // Two rooms joined by a door in a wall of class 2.
        let (w, h) = (30, 11);
        let mut class = vec![0u8; w * h];
        for y in 0..h {
            if y != 5 {
                class[y * w + 15] = 2;
            }
        }
        let mut owner = vec![NO_NODE; w * h];
        let mut count = 0u32;
        let placed = Coverage::new(40).cover(
            &CoverageInput { class: &class, width: w, height: h, in_set: &set(&[0]) },
            &mut owner,
            |_| {
                count += 1;
                count - 1
            },
        );
        assert!(placed >= 2, "one node cannot see both rooms through the door");
        for i in 0..w * h {
            assert_eq!(owner[i] == NO_NODE, class[i] == 2, "cell {i}");
        }
    }
}
