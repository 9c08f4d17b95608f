//! The known-safe region: the star polygon a reachability scan S(φ) draws around the robot,
//! optionally with a polar table of the distance transform D for the controller's Φ lookup.

use std::f64::consts::{FRAC_PI_2, FRAC_PI_4, PI, TAU};
use std::sync::{Arc, Mutex, OnceLock};

use spomp_core::{Point2, ReachabilityScan};

use crate::error::{RegionError, positive};
use crate::stages::min_ps;
use crate::terrain::{TerrainOutput, TerrainParams};

/// Ranges above this are treated as this (keeps areas and sampling finite on garbage input).
const MAX_REGION_RANGE_M: f64 = 1.0e4;

/// Range cells per bin of the clearance table at most (beyond, the last cell's value applies):
/// bounds the table for garbage ranges (1024 bins × 1024 cells × 4 B = 4 MiB at worst).
const MAX_CLEARANCE_CELLS: usize = 1024;

/// Neighbouring columns whose safe stretches [`SafeRegion::from_terrain`] reads together.
const CLEARANCE_BLOCK: usize = 16;

/// Bin counts whose direction tables [`bin_directions`] keeps (a team uses one or two: the
/// panorama's columns and a downsampled scan's); other counts are computed each time.
const KEPT_DIRECTION_TABLES: usize = 8;

/// (sin, cos) of each bin's azimuth −i·2π/`bins`, one table per bin count for the process: a
/// region is built for every panorama and every shared scan, and its 1024 `sin_cos` were about
/// 1 % of a simulated team's run. The same calls as computing them in place, so the same bits.
fn bin_directions(bins: usize) -> Arc<[(f64, f64)]> {
    type Tables = Vec<(usize, Arc<[(f64, f64)]>)>;
    static TABLES: OnceLock<Mutex<Tables>> = OnceLock::new();
    let tables = TABLES.get_or_init(|| Mutex::new(Vec::new()));
    if let Ok(kept) = tables.lock()
        && let Some((_, table)) = kept.iter().find(|(n, _)| *n == bins)
    {
        return Arc::clone(table);
    }
    let step = TAU / bins as f64;
    let table: Arc<[(f64, f64)]> = (0..bins).map(|i| (-(i as f64) * step).sin_cos()).collect();
    if let Ok(mut kept) = tables.lock()
        && kept.len() < KEPT_DIRECTION_TABLES
        && !kept.iter().any(|(n, _)| *n == bins)
    {
        kept.push((bins, Arc::clone(&table)));
    }
    table
}

/// tan(π/8): atan arguments above it are reduced through atan(t) = π/4 + atan((t − 1)/(t + 1)).
const TAN_PI_8: f64 = 0.414_213_562_373_095_03;

/// atan2 to about 1e-5 rad without a libm call: octant reduction to |u| ≤ tan(π/8), then the
/// Taylor series of atan to u⁹ (remainder below u¹¹/11 ≈ 6e-6).
#[inline]
pub(crate) fn fast_atan2(y: f64, x: f64) -> f64 {
    let ax = x.abs();
    let ay = y.abs();
    let (num, den, swapped) = if ay > ax { (ax, ay, true) } else { (ay, ax, false) };
    if den == 0.0 {
        return 0.0;
    }
    let t = num / den; // in [0, 1]
    let (u, offset) = if t > TAN_PI_8 { ((t - 1.0) / (t + 1.0), FRAC_PI_4) } else { (t, 0.0) };
    let u2 = u * u;
    let series = u * (1.0 + u2 * (-1.0 / 3.0 + u2 * (1.0 / 5.0 + u2 * (-1.0 / 7.0 + u2 * (1.0 / 9.0)))));
    let mut a = offset + series; // atan(t) in [0, π/4]
    if swapped {
        a = FRAC_PI_2 - a;
    }
    if x < 0.0 {
        a = PI - a;
    }
    if y < 0.0 { -a } else { a }
}

/// Distance to the nearest obstacle on a polar grid (bin = scan column, cell = horizontal
/// range / cell size), built from the terrain distance transform D. Bin b holds its first
/// `bin_cells[b]` cells (up to its own safe range), stored bin after bin from `start[b]`: a
/// table as long as the bins' ranges together, where a cell-major table as deep as the longest
/// bin for every bin was 2 MB to fill and copy for one far-seeing column.
#[derive(Clone, Debug, PartialEq)]
struct Clearance {
    inv_cell_m: f64,
    bin_cells: Vec<u32>,
    /// Where each bin's cells start in `values`.
    start: Vec<u32>,
    values: Vec<f32>,
}

/// The safe star polygon of a reachability scan, in the scan's robot frame (x forward, y left):
/// vertex i lies at range S(φ_i) along azimuth φ_i = −i·2π/bins (the panorama convention).
#[derive(Clone, Debug, PartialEq)]
pub struct SafeRegion {
    /// bins / 2π: a multiplication in the hot bin lookup instead of a division.
    bins_per_rad: f64,
    range_m: Vec<f64>,
    obstacle: Vec<bool>,
    vertices: Vec<Point2>,
    /// Cumulative area of the fan triangles (origin, v_i, v_{i+1}), for uniform sampling.
    cumulative_area: Vec<f64>,
    /// Shared: a region is cloned every control tick, the table is built once per panorama.
    clearance: Option<Arc<Clearance>>,
    default_clearance_m: f32,
}

/// The clearance cell of a pixel at `cells` = r / cell size (r ≥ 0 finite for a pixel with a
/// return: never NaN), at most `max_cell` (< [`MAX_CLEARANCE_CELLS`]): ⌊cells⌋ clamped, as
/// `(cells as u32).min(max_cell)` gives, with the clamp first (`max_cell` is exact in f32), which
/// leaves the conversion little to saturate (17 % fewer instructions in the table's build).
#[inline(always)]
fn clearance_cell(cells: f32, max_cell: u32) -> u32 {
    min_ps(cells, max_cell as f32) as u32
}

impl SafeRegion {
    /// A region from per-bin safe ranges and obstacle flags. Non-finite or negative ranges count
    /// as 0. Without a clearance table, every safe point has clearance `default_clearance_m`.
    pub fn from_ranges(range_m: &[f32], obstacle: &[bool], default_clearance_m: f64) -> Result<Self, RegionError> {
        if range_m.is_empty() || range_m.len() != obstacle.len() {
            return Err(RegionError::Inconsistent { ranges: range_m.len(), obstacles: obstacle.len() });
        }
        let bins = range_m.len();
        let bin_step_rad = TAU / bins as f64;
        let ranges: Vec<f64> = range_m
            .iter()
            .map(|&r| {
                let r = r as f64;
                if r.is_finite() && r > 0.0 { r.min(MAX_REGION_RANGE_M) } else { 0.0 }
            })
            .collect();
        let directions = bin_directions(bins);
        let vertices: Vec<Point2> =
            ranges.iter().zip(directions.iter()).map(|(&r, &(s, c))| Point2::new(r * c, r * s)).collect();
        let half_sin = 0.5 * bin_step_rad.sin();
        let mut total = 0.0;
        let cumulative_area = (0..bins)
            .map(|i| {
                total += half_sin * ranges[i] * ranges[(i + 1) % bins];
                total
            })
            .collect();
        Ok(SafeRegion {
            bins_per_rad: bins as f64 / TAU,
            range_m: ranges,
            obstacle: obstacle.to_vec(),
            vertices,
            cumulative_area,
            clearance: None,
            default_clearance_m: if default_clearance_m.is_finite() {
                default_clearance_m.max(0.0) as f32
            } else {
                0.0
            },
        })
    }

    /// A region from a shared reachability scan (no clearance table: clearance inside is
    /// `default_clearance_m`, e.g. the terrain D_max).
    pub fn from_scan(scan: &ReachabilityScan, default_clearance_m: f64) -> Result<Self, RegionError> {
        Self::from_ranges(&scan.range_m, &scan.obstacle, default_clearance_m)
    }

    /// The region of a terrain analysis, with a polar clearance table sampled from the distance
    /// transform D along each column's safe stretch (cells of `params.clearance_cell_m`).
    pub fn from_terrain(output: &TerrainOutput, params: &TerrainParams) -> Result<Self, RegionError> {
        positive("clearance_cell_m", params.clearance_cell_m)?;
        let mut region =
            Self::from_ranges(output.reach_range_m(), output.reach_obstacle(), params.max_obstacle_distance_m)?;
        let geometry = output.geometry();
        let cols = geometry.cols;
        let rows = geometry.rows;
        let cell_m = params.clearance_cell_m;
        let bin_cells: Vec<u32> = (0..cols)
            .map(|c| {
                let range = region.range_m.get(c).copied().unwrap_or(0.0);
                (((range / cell_m) as u32).min(MAX_CLEARANCE_CELLS as u32 - 1)) + 1
            })
            .collect();
        let mut start = Vec::with_capacity(cols);
        let mut total = 0u32;
        for &n in &bin_cells {
            start.push(total);
            total += n;
        }
        let mut values = vec![f32::NAN; total as usize];
        let inv_cell = (1.0 / cell_m) as f32;
        let last_row = output.reach_last_row();
        let (r_m, rho, d) = (output.r_m(), output.ranges_m(), output.distance_m());
        // Each column's safe stretch, bottom row up to its last safe row, visited in blocks of
        // neighbouring columns (whose stretches are alike): a block's rows are read a cache line
        // at a time and its table cells stay in L1, where whole-panorama rows down to the highest
        // stretch of all visited many pixels above their own column's stretch. (Taking the
        // minimum does not depend on the order the pixels come in.)
        let ncols = cols.min(last_row.len());
        // Each bin's last cell, kept apart from `bin_cells`: `n − 1` in the pixel loop measured
        // 10 % slower (209 → 228 µs on the street panorama).
        let last_cell: Vec<u32> = bin_cells[..ncols].iter().map(|&n| n - 1).collect();
        for block in (0..ncols).step_by(CLEARANCE_BLOCK) {
            let block = block..(block + CLEARANCE_BLOCK).min(ncols);
            let (last_row, last_cell, start) =
                (&last_row[block.clone()], &last_cell[block.clone()], &start[block.clone()]);
            let top = last_row.iter().copied().min().unwrap_or(rows as u32) as usize;
            for row in (top..rows).rev() {
                let span = row * cols + block.start..row * cols + block.end;
                let (Some(rho_row), Some(r_row), Some(d_row)) =
                    (rho.get(span.clone()), r_m.get(span.clone()), d.get(span))
                else {
                    continue;
                };
                let row_u32 = row as u32;
                let pixels = rho_row.iter().zip(r_row).zip(d_row).zip(last_row).zip(last_cell).zip(start);
                for (((((&rho_px, &r_px), &d_px), &last), &max_cell), &first) in pixels {
                    if (row_u32 < last) | (rho_px <= 0.0) {
                        continue;
                    }
                    let cell = clearance_cell(r_px * inv_cell, max_cell);
                    if let Some(slot) = values.get_mut((first + cell) as usize) {
                        // An empty slot (NaN) takes the pixel's D, else the smaller: one `minss`
                        // (its second operand where the first is NaN). The same as `f32::min`
                        // here, whose NaN test cost 7 instructions a pixel: D is never NaN nor
                        // −0 (Algorithm 1 only adds and takes minima of values ≥ +0).
                        *slot = min_ps(*slot, d_px);
                    }
                }
            }
        }
        // Empty cells take the value of the nearest filled cell towards the robot, cells before
        // the first filled one take its value, a bin with none the default: every lookup inside
        // the polygon is defined.
        fill_empty_clearance_cells(&mut values, &start, &bin_cells, region.default_clearance_m);
        region.clearance = Some(Arc::new(Clearance { inv_cell_m: 1.0 / cell_m, bin_cells, start, values }));
        Ok(region)
    }

    /// Number of bins (vertices).
    pub fn bins(&self) -> usize {
        self.range_m.len()
    }

    /// Safe range of bin `i`, metres (0 when out of range).
    pub fn range_of_bin(&self, i: usize) -> f64 {
        self.range_m.get(i).copied().unwrap_or(0.0)
    }

    /// Whether a known obstacle ends bin `i`.
    pub fn obstacle_at_bin(&self, i: usize) -> bool {
        self.obstacle.get(i).copied().unwrap_or(false)
    }

    /// The polygon's vertices, bin order (clockwise seen from above).
    pub fn vertices(&self) -> &[Point2] {
        &self.vertices
    }

    /// Area of the polygon, m².
    pub fn area_m2(&self) -> f64 {
        self.cumulative_area.last().copied().unwrap_or(0.0)
    }

    /// Continuous bin coordinate of a direction, in [0, bins).
    #[inline]
    fn bin_coordinate(&self, p: Point2) -> f64 {
        let bins = self.range_m.len() as f64;
        let t = -fast_atan2(p.y, p.x) * self.bins_per_rad;
        let t = if t < 0.0 { t + bins } else { t };
        if t >= bins || t.is_nan() { 0.0 } else { t }
    }

    /// Whether `p` lies in the fan triangle (origin, v_i, v_{i+1}) of the sector at bin
    /// coordinate `t`.
    #[inline]
    fn in_sector(&self, p: Point2, t: f64) -> bool {
        let bins = self.range_m.len();
        // Through u32: a float-to-u64 conversion is a branchy sequence on x86-64.
        let i0 = (t as u32 as usize).min(bins - 1);
        let i1 = if i0 + 1 == bins { 0 } else { i0 + 1 };
        let (v0, v1) = (self.vertices[i0], self.vertices[i1]);
        let edge = v1 - v0;
        let origin_side = edge.cross(Point2::new(-v0.x, -v0.y));
        if origin_side == 0.0 {
            return false;
        }
        let point_side = edge.cross(p - v0);
        point_side * origin_side >= 0.0
    }

    /// Whether `p` (robot frame of the scan) lies in the star polygon: inside the fan triangle
    /// (origin, v_i, v_{i+1}) of the sector its direction falls in.
    #[inline]
    pub fn contains(&self, p: Point2) -> bool {
        if !(p.x.is_finite() && p.y.is_finite()) {
            return false;
        }
        if p.x == 0.0 && p.y == 0.0 {
            return self.cumulative_area.last().is_some_and(|&a| a > 0.0);
        }
        self.in_sector(p, self.bin_coordinate(p))
    }

    /// Distance to the nearest obstacle at `p` (Φ: the nearest bin and range cell of the polar
    /// clearance table), or `None` outside the polygon.
    #[inline]
    pub fn clearance_at(&self, p: Point2) -> Option<f32> {
        if !(p.x.is_finite() && p.y.is_finite()) {
            return None;
        }
        let t = self.bin_coordinate(p);
        let at_origin = p.x == 0.0 && p.y == 0.0;
        if !(at_origin && self.area_m2() > 0.0 || self.in_sector(p, t)) {
            return None;
        }
        let Some(table) = &self.clearance else { return Some(self.default_clearance_m) };
        let bins = self.range_m.len();
        let bin = (t + 0.5) as u32 as usize;
        let bin = if bin >= bins { bin - bins } else { bin };
        let (bin_cells, first) = (*table.bin_cells.get(bin)?, *table.start.get(bin)?);
        let distance = (p.x * p.x + p.y * p.y).sqrt();
        let cell = ((distance * table.inv_cell_m) as u32).min(bin_cells.saturating_sub(1));
        table.values.get((first + cell) as usize).copied()
    }

    /// A point drawn uniformly from the polygon (fan triangle by area, then uniform in it), or
    /// `None` if the polygon has no area.
    pub fn sample_uniform(&self, rng: &mut impl rand::Rng) -> Option<Point2> {
        let total = self.area_m2();
        if !(total > 0.0 && total.is_finite()) {
            return None;
        }
        let target = rng.random::<f64>() * total;
        let bins = self.range_m.len();
        let i = self.cumulative_area.partition_point(|&a| a <= target).min(bins - 1);
        let (v0, v1) = (self.vertices[i], self.vertices[(i + 1) % bins]);
        let (mut a, mut b) = (rng.random::<f64>(), rng.random::<f64>());
        if a + b > 1.0 {
            a = 1.0 - a;
            b = 1.0 - b;
        }
        Some(v0 * a + v1 * b)
    }
}

/// Fills the empty (NaN) cells of each bin of a clearance table (`start`, `bin_cells`: each bin's
/// first cell and cell count): with the nearest filled cell's value towards the robot, cells
/// before the first filled one with its value, a bin with none with `fallback`.
fn fill_empty_clearance_cells(values: &mut [f32], start: &[u32], bin_cells: &[u32], fallback: f32) {
    for (&first, &n) in start.iter().zip(bin_cells) {
        let Some(bin) = values.get_mut(first as usize..(first + n) as usize) else { continue };
        let Some(first_filled) = bin.iter().position(|v| !v.is_nan()) else {
            bin.fill(fallback);
            continue;
        };
        let mut last = bin[first_filled];
        for v in bin.iter_mut() {
            if v.is_nan() {
                *v = last;
            } else {
                last = *v;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn vertices_lie_on_each_bins_azimuth_for_kept_and_unkept_bin_counts() {
        // More bin counts than the process keeps tables of, each asked twice (built, then kept
        // or rebuilt): every vertex is r·(cos, sin) of −i·2π/bins, bit for bit.
        for round in 0..2 {
            for bins in (3..3 + 2 * KEPT_DIRECTION_TABLES).chain([1024]) {
                let ranges: Vec<f32> = (0..bins).map(|i| 1.0 + (i * 7 % 5) as f32 + round as f32).collect();
                let region = SafeRegion::from_ranges(&ranges, &vec![false; bins], 1.0).expect("valid ranges");
                let step = TAU / bins as f64;
                for (i, v) in region.vertices().iter().enumerate() {
                    let (s, c) = (-(i as f64) * step).sin_cos();
                    let r = f64::from(ranges[i]);
                    assert_eq!(
                        (v.x.to_bits(), v.y.to_bits()),
                        ((r * c).to_bits(), (r * s).to_bits()),
                        "bins {bins}, vertex {i}"
                    );
                }
            }
        }
    }

    #[test]
    fn fast_atan2_matches_std() {
        let mut worst = 0.0f64;
        for i in 0..3600 {
            let a = (i as f64 / 3600.0) * TAU - PI;
            for r in [0.01, 1.0, 250.0] {
                let (y, x) = (r * a.sin(), r * a.cos());
                let err = spomp_core::normalize_angle(fast_atan2(y, x) - y.atan2(x)).abs();
                worst = worst.max(err);
            }
        }
        assert!(worst < 1e-5, "worst error {worst}");
    }

    #[test]
    fn square_like_region_contains_and_area() {
        // 4 bins of 1 m: a diamond with vertices on the axes, area 2 m².
        let r = SafeRegion::from_ranges(&[1.0; 4], &[false; 4], 2.0).unwrap();
        assert!((r.area_m2() - 2.0).abs() < 1e-12);
        assert!(r.contains(Point2::new(0.4, 0.4)));
        assert!(!r.contains(Point2::new(0.6, 0.6)));
        assert!(r.contains(Point2::new(0.0, -0.99)));
        assert!(!r.contains(Point2::new(0.0, 1.01)));
        assert!(r.contains(Point2::new(0.0, 0.0)));
        assert!(!r.contains(Point2::new(f64::NAN, 0.0)));
        assert_eq!(r.clearance_at(Point2::new(0.1, 0.1)), Some(2.0));
        assert_eq!(r.clearance_at(Point2::new(3.0, 0.1)), None);
    }

    #[test]
    fn inconsistent_scans_are_errors() {
        assert!(SafeRegion::from_ranges(&[], &[], 1.0).is_err());
        assert!(SafeRegion::from_ranges(&[1.0, 2.0], &[false], 1.0).is_err());
    }

    /// The clearance table of [`SafeRegion::from_terrain`] as it was first written (a saturating
    /// conversion and `f32::min` per pixel): the reference for the cheaper pixel loop.
    fn reference_clearance_values(output: &TerrainOutput, params: &TerrainParams) -> Vec<f32> {
        let region = SafeRegion::from_ranges(output.reach_range_m(), output.reach_obstacle(), 2.0).unwrap();
        let (cols, rows) = (output.geometry().cols, output.geometry().rows);
        let cell_m = params.clearance_cell_m;
        let bin_cells: Vec<u32> = (0..cols)
            .map(|c| (((region.range_m[c] / cell_m) as u32).min(MAX_CLEARANCE_CELLS as u32 - 1)) + 1)
            .collect();
        let mut start = vec![0u32; cols];
        for c in 1..cols {
            start[c] = start[c - 1] + bin_cells[c - 1];
        }
        let mut values = vec![f32::NAN; (start[cols - 1] + bin_cells[cols - 1]) as usize];
        let inv_cell = (1.0 / cell_m) as f32;
        for c in 0..cols {
            for row in (output.reach_last_row()[c] as usize..rows).rev() {
                let i = row * cols + c;
                if output.ranges_m()[i] <= 0.0 {
                    continue;
                }
                let cell = ((output.r_m()[i] * inv_cell) as u32).min(bin_cells[c] - 1);
                let slot = &mut values[(start[c] + cell) as usize];
                *slot = slot.min(output.distance_m()[i]);
            }
        }
        // Empty cells as the table fills them (that step is not what the test is about).
        fill_empty_clearance_cells(&mut values, &start, &bin_cells, 2.0);
        values
    }

    /// The whole clearance table, bit for bit, on streets with few and many missing returns,
    /// both profiles.
    #[test]
    fn clearance_table_matches_the_reference_loop_bit_for_bit() {
        use rand::SeedableRng;
        let geometry = spomp_core::PanoramaGeometry::default_lidar();
        for (dropout, seed) in [(0.02, 7u64), (0.2, 11), (0.4, 3)] {
            let mut pano = crate::synthetic::Scene::street(0.4).render(geometry);
            crate::synthetic::add_noise(&mut pano, 0.01, dropout, &mut rand_chacha::ChaCha8Rng::seed_from_u64(seed));
            for params in [TerrainParams::default(), TerrainParams::simulation()] {
                let mut analyzer = crate::TerrainAnalyzer::new(geometry, params.clone()).unwrap();
                let output = analyzer.analyze(&pano).unwrap();
                let region = SafeRegion::from_terrain(output, &params).unwrap();
                let table = region.clearance.as_ref().unwrap();
                let want = reference_clearance_values(output, &params);
                assert_eq!(table.values.len(), want.len());
                assert!(want.len() > 5000, "{}", want.len());
                for (i, (got, want)) in table.values.iter().zip(&want).enumerate() {
                    assert_eq!(got.to_bits(), want.to_bits(), "cell {i}, dropout {dropout}");
                }
            }
        }
    }
}
