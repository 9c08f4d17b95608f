//! The terrain stages as straightforward scalar loops: the readable specification that the
//! optimised `spomp_local_planner::stages` must match bit for bit. First written before the
//! optimisations; the rules decided for issue 20 (the local planner README's table) are written
//! here the plain way too.

#![allow(dead_code, clippy::all)]

/// Per-row and per-column trigonometry and windows, computed once per panorama geometry.
#[derive(Clone, Debug, Default)]
pub struct Tables {
    /// Panorama width A.
    pub cols: usize,
    /// Angle between columns, 2π/A, radians.
    pub col_step_rad: f32,
    /// sin θ per row (θ: elevation, positive up).
    pub row_sin: Vec<f32>,
    /// cos θ per row.
    pub row_cos: Vec<f32>,
    /// cos φ per column (φ: azimuth, robot frame).
    pub col_cos: Vec<f32>,
    /// sin φ per column.
    pub col_sin: Vec<f32>,
    /// Elevation gradient window w_e per row: below the horizon the flat-ground rule, at and
    /// above it 1; 0 for row 0 (no elevation term).
    pub elevation_window: Vec<u32>,
    /// |η_z| = η·|sin θ| per row, metres.
    pub noise_z_m: Vec<f32>,
    /// η_xy = η·cos θ per row, metres.
    pub noise_xy_m: Vec<f32>,
}

impl Tables {
    /// Tables for a geometry (`rows`, `cols`, elevation of each row), the flat-ground sensor
    /// height `h_s`, the window `W` and the range noise `η`.
    pub fn new(
        rows: usize,
        cols: usize,
        elevation_of_row: impl Fn(usize) -> f64,
        sensor_height_m: f64,
        window_m: f64,
        noise_m: f64,
    ) -> Self {
        let col_step = std::f64::consts::TAU / cols.max(1) as f64;
        let elevations: Vec<f64> = (0..rows).map(&elevation_of_row).collect();
        let cot: Vec<f64> = elevations.iter().map(|t| t.cos() / t.sin()).collect();
        let elevation_window = (0..rows)
            .map(|row| {
                // At and above the horizon: the next row up (row 0 has none).
                if elevations[row] >= 0.0 || elevations[row].is_nan() {
                    return row.min(1) as u32;
                }
                // Smallest δ whose flat-ground ranges h_s/tan θ differ by at least W. Without
                // one inside the field of view, use the top row, the farthest available.
                let found = (1..=row).find(|&delta| {
                    let gap = sensor_height_m * (cot[row] - cot[row - delta]).abs();
                    gap >= window_m || gap.is_nan()
                });
                found.unwrap_or(row) as u32
            })
            .collect();
        Tables {
            cols,
            col_step_rad: col_step as f32,
            row_sin: elevations.iter().map(|t| t.sin() as f32).collect(),
            row_cos: elevations.iter().map(|t| t.cos() as f32).collect(),
            col_cos: (0..cols).map(|c| (-(c as f64) * col_step).cos() as f32).collect(),
            col_sin: (0..cols).map(|c| (-(c as f64) * col_step).sin() as f32).collect(),
            elevation_window,
            noise_z_m: elevations.iter().map(|t| (noise_m * t.sin().abs()) as f32).collect(),
            noise_xy_m: elevations.iter().map(|t| (noise_m * t.cos()) as f32).collect(),
        }
    }
}

#[inline]
fn sanitize(range: f32) -> f32 {
    // `&` rather than `&&`: no short-circuit branch, so the loops using it vectorise.
    if range.is_finite() & (range > 0.0) { range } else { 0.0 }
}

/// Stage 1: copies `input` to `out` (non-finite and non-positive ranges become 0 = no return)
/// and fills, along each row with wrap in azimuth, every run of missing pixels whose arc length
/// is at most `max_gap_m` (the paper's D_m; D_px = D_m / s with s = (2π/A)·ρ, ρ the larger of the
/// two ranges bounding the run) by linear interpolation between its ends.
pub fn fill_holes(input: &[f32], out: &mut [f32], cols: usize, max_gap_m: f32) {
    if cols == 0 {
        return;
    }
    let col_step = std::f32::consts::TAU / cols as f32;
    for (row_in, row) in input.chunks_exact(cols).zip(out.chunks_exact_mut(cols)) {
        for (o, &i) in row.iter_mut().zip(row_in) {
            *o = sanitize(i);
        }
        let (Some(first), Some(last)) = (row.iter().position(|&r| r > 0.0), row.iter().rposition(|&r| r > 0.0)) else {
            continue;
        };
        // The hole across the seam, from `last` around to `first`.
        fill_gap(row, last, first + cols, col_step, max_gap_m);
        let mut c = first;
        while c < last {
            // `c` holds a return; find the next hole and the return that ends it.
            let Some(offset) = row[c..last].iter().position(|&r| r <= 0.0) else { break };
            let start = c + offset;
            let end = row[start..=last].iter().position(|&r| r > 0.0).map_or(last, |o| start + o);
            fill_gap(row, start - 1, end, col_step, max_gap_m);
            c = end;
        }
    }
}

/// Fills the pixels strictly between returns at unwrapped columns `from` and `to` (`to` may be
/// ≥ `row.len()`, meaning across the seam) if the hole spans at most `max_gap_m` of arc.
#[inline]
fn fill_gap(row: &mut [f32], from: usize, to: usize, col_step: f32, max_gap_m: f32) {
    let cols = row.len();
    let gap = to.saturating_sub(from + 1);
    if gap == 0 || gap >= cols {
        return;
    }
    let wrap = |k: usize| if k >= cols { k - cols } else { k };
    let (start, end) = (row[wrap(from)], row[wrap(to)]);
    if gap as f32 * col_step * start.max(end) > max_gap_m {
        return;
    }
    let inv = 1.0 / (gap + 1) as f32;
    for j in 1..=gap {
        row[wrap(from + j)] = start + (end - start) * (j as f32 * inv);
    }
}

/// Stage 2: projects ranges to height z (sensor frame, z up) and horizontal range r, from
/// per-row trigonometry. Pixels without a return get NaN. (x and y = r·cos φ, r·sin φ are not
/// stored — no stage needs them; `TerrainOutput::point_m` gives them per pixel.)
pub fn project(ranges: &[f32], tables: &Tables, z: &mut [f32], r: &mut [f32]) {
    let cols = tables.cols;
    if cols == 0 {
        return;
    }
    let rows = ranges
        .chunks_exact(cols)
        .zip(z.chunks_exact_mut(cols))
        .zip(r.chunks_exact_mut(cols))
        .zip(tables.row_sin.iter().zip(&tables.row_cos));
    for (((rho, z), r), (&sin_e, &cos_e)) in rows {
        project_row(rho, sin_e, cos_e, z, r);
    }
}

/// [`project`] for one row of elevation θ (`sin_e`, `cos_e`).
#[inline]
pub fn project_row(rho: &[f32], sin_e: f32, cos_e: f32, z: &mut [f32], r: &mut [f32]) {
    for ((&rho, z), r) in rho.iter().zip(z.iter_mut()).zip(r.iter_mut()) {
        // No return: NaN, so that later differences with it are NaN and drop out.
        let range = if rho > 0.0 { rho } else { f32::NAN };
        *r = range * cos_e;
        *z = range * sin_e;
    }
}

/// Gradient window parameters in the units the inner loop uses.
#[derive(Clone, Copy, Debug)]
pub struct GradientWindow {
    /// W, metres.
    pub window_m: f32,
    /// W_max, pixels.
    pub max_window_px: f32,
}

/// Per-row scratch of [`gradients`].
#[derive(Clone, Debug, Default)]
pub struct GradientScratch {
    half_window: Vec<u32>,
    rise_a: Vec<f32>,
    run_a: Vec<f32>,
}

/// Stage 3: gradient magnitude |∇| = sqrt(∇_a² + ∇_e²) per pixel, with the paper's metric
/// windows w_a = ⌊min(W/s_xy, W_max)/2⌋ + 1 (azimuth, wrapping) and w_e (per row, from
/// [`Tables`]), and the noise η_z subtracted from height differences and η_xy added to the
/// horizontal-range difference. `z` and `r` come from [`project`] (NaN without a return); a term
/// whose neighbour has no return is 0, and so is the gradient of a pixel without a return.
pub fn gradients(
    z: &[f32],
    r: &[f32],
    tables: &Tables,
    window: GradientWindow,
    scratch: &mut GradientScratch,
    gradient: &mut [f32],
) {
    let cols = tables.cols;
    if cols < 3 {
        gradient.iter_mut().for_each(|g| *g = 0.0);
        return;
    }
    let rows = z.len().min(r.len()).min(gradient.len()) / cols;
    for (row, out) in gradient.chunks_exact_mut(cols).take(rows).enumerate() {
        gradient_row(row, z, r, tables, window, scratch, out);
    }
}

/// [`gradients`] for one row: `z` and `r` are whole panoramas, of which this row and the row
/// w_e above it are read; `out` is the row's gradient.
pub fn gradient_row(
    row: usize,
    z: &[f32],
    r: &[f32],
    tables: &Tables,
    window: GradientWindow,
    scratch: &mut GradientScratch,
    out: &mut [f32],
) {
    let cols = tables.cols;
    if cols < 3 || out.len() != cols || z.len() < (row + 1) * cols || r.len() < (row + 1) * cols {
        out.iter_mut().for_each(|g| *g = 0.0);
        return;
    }
    let step = tables.col_step_rad;
    let max_half = ((cols - 1) / 2) as f32;
    let max_px = window.max_window_px.max(0.0);
    let w_over_step = window.window_m / step;
    scratch.half_window.resize(cols, 1);
    scratch.rise_a.resize(cols, 0.0);
    scratch.run_a.resize(cols, 0.0);
    {
        let base = row * cols;
        let z_row = &z[base..base + cols];
        let r_row = &r[base..base + cols];
        let noise_z = tables.noise_z_m.get(row).copied().unwrap_or(0.0);
        let noise_xy = tables.noise_xy_m.get(row).copied().unwrap_or(0.0);
        let half = &mut scratch.half_window[..cols];
        let rise_a = &mut scratch.rise_a[..cols];
        let run_a = &mut scratch.run_a[..cols];
        // w_a from the arc length on the x–y plane, s_xy = (2π/A)·r, so W/s_xy = (W/step)/r;
        // the denominator s·(2w_a + 1) uses the arc length s = (2π/A)·ρ = (2π/A)·r / cos θ.
        let cos_e = tables.row_cos.get(row).copied().unwrap_or(1.0).max(1e-6);
        let arc_per_r = step / cos_e;
        for c in 0..cols {
            // Without a return r is NaN and `min` yields W_max; that pixel's gradient is 0 anyway.
            let px = (w_over_step / r_row[c]).min(max_px).max(0.0);
            let h = (floor_small(px * 0.5) + 1.0).min(max_half);
            half[c] = small_to_u32(h);
            run_a[c] = arc_per_r * r_row[c] * (2.0 * h + 1.0);
        }
        for c in 0..cols {
            let h = half[c] as usize;
            let left = if c >= h { c - h } else { c + cols - h };
            let right = if c + h < cols { c + h } else { c + h - cols };
            rise_a[c] = (z_row[left] - z_row[right]).abs();
        }
        let w_e = tables.elevation_window.get(row).copied().unwrap_or(0) as usize;
        let above = (w_e > 0 && w_e <= row).then(|| (row - w_e) * cols);
        match above {
            Some(b) => {
                let z_up = &z[b..b + cols];
                let r_up = &r[b..b + cols];
                for c in 0..cols {
                    // sqrt(∇_a² + ∇_e²) with one division: sqrt((a·n_e)² + (e·n_a)²) / (n_a·n_e).
                    let (rise_a, run_a) = positive_part(rise_a[c] - noise_z, run_a[c]);
                    // No return one window up: no elevation term (rise 0 over any run, here 1).
                    let (rise_e, run_e) = if r_up[c].is_nan() {
                        (0.0, 1.0)
                    } else {
                        let rise_e = (z_row[c] - z_up[c]).abs() - noise_z;
                        positive_part(rise_e, (r_row[c] - r_up[c]).abs() + noise_xy)
                    };
                    let (ta, te) = (rise_a * run_e, rise_e * run_a);
                    let g = (ta * ta + te * te).sqrt() / (run_a * run_e);
                    out[c] = if g >= 0.0 { g } else { 0.0 };
                }
            }
            None => {
                for c in 0..cols {
                    let (rise, run) = positive_part(rise_a[c] - noise_z, run_a[c]);
                    let g = rise / run;
                    out[c] = if g >= 0.0 { g } else { 0.0 };
                }
            }
        }
    }
}

/// ⌊v⌋ for 0 ≤ v < 2²², in float arithmetic only (vectorises without SSE4.1 and without the
/// saturating float-to-int conversion): adding and removing 2²³ rounds to the nearest integer,
/// then one is taken off where that rounded up.
#[inline(always)]
fn floor_small(v: f32) -> f32 {
    const SHIFT: f32 = 8_388_608.0; // 2²³
    let rounded = (v + SHIFT) - SHIFT;
    if rounded > v { rounded - 1.0 } else { rounded }
}

/// An integer-valued float in [0, 2²³) as an integer, through its bits (adding 2²³ puts the
/// value in the mantissa): vectorises, unlike the saturating `as` conversion.
#[inline(always)]
fn small_to_u32(v: f32) -> u32 {
    const SHIFT: f32 = 8_388_608.0; // 2²³
    (v + SHIFT).to_bits().wrapping_sub(SHIFT.to_bits())
}

/// (max(rise, 0), run clamped away from 0); a NaN rise (a neighbour without a return) gives
/// rise 0, a NaN run (the pixel has no return) stays NaN so that the caller yields 0.
#[inline(always)]
fn positive_part(rise: f32, run: f32) -> (f32, f32) {
    (if rise > 0.0 { rise } else { 0.0 }, if run >= 0.0 { run.max(1e-12) } else { run })
}

/// Stage 4: obstacle = gradient above `slope_threshold` (pixels with a return only); then,
/// along each row with wrap, runs of fewer than `min_run_px` obstacle pixels, or (when
/// `min_run_m` > 0) of arc length (Σρ)·2π/A below `min_run_m`, are cleared.
pub fn obstacles(
    gradient: &[f32],
    ranges: &[f32],
    cols: usize,
    slope_threshold: f32,
    (min_run_px, min_run_m): (u32, f32),
    obstacle: &mut [bool],
) {
    if cols == 0 {
        return;
    }
    let min_run = min_run_px as usize;
    let step = std::f32::consts::TAU / cols as f32;
    let rows = gradient.chunks_exact(cols).zip(ranges.chunks_exact(cols));
    for ((grad, rho), obs) in rows.zip(obstacle.chunks_exact_mut(cols)) {
        for c in 0..cols {
            obs[c] = grad[c] > slope_threshold && rho[c] > 0.0;
        }
        // A row that is all obstacle is one closed ring: kept.
        let Some(first_free) = obs.iter().position(|&o| !o) else { continue };
        // Walk the ring once from a free pixel, measuring each run of obstacle pixels.
        let mut run_start = None;
        for k in 1..=cols {
            let c = (first_free + k) % cols;
            match (obs[c], run_start) {
                (true, None) => run_start = Some(k),
                (false, Some(start)) => {
                    // Summed in walk order: the same float sum as the optimised stage's.
                    let arc = (start..k).map(|j| rho[(first_free + j) % cols]).sum::<f32>() * step;
                    if k - start < min_run || (min_run_m > 0.0 && arc < min_run_m) {
                        for j in start..k {
                            obs[(first_free + j) % cols] = false;
                        }
                    }
                    run_start = None;
                }
                _ => {}
            }
        }
    }
}

/// Scratch space for [`distance_transform`]: one value per column and the row pass state.
#[derive(Clone, Debug, Default)]
pub struct DistanceScratch {
    nearest_obstacle: Vec<f32>,
}

/// Stage 5: Algorithm 1, the distance-transform approximation, capped at `max_distance_m`.
///
/// Column pass, top row to bottom (far to near on the ground): `along_column` D_a gets |ρ − D_obs|
/// with D_obs the smallest range of an obstacle met so far in the column (0 on obstacles).
/// Then two passes along each row, forwards and backwards, propagate D_a(p_last) +
/// |p_a − p_last|·s(p_last), where p_last is the last column whose own D_a beat the propagated
/// value; the passes wrap around in azimuth: after a pass reaches the end of a row it continues
/// from the other end for as long as the propagated distance stays below `max_distance_m`.
pub fn distance_transform(
    ranges: &[f32],
    obstacle: &[bool],
    cols: usize,
    max_distance_m: f32,
    scratch: &mut DistanceScratch,
    along_column: &mut [f32],
    distance: &mut [f32],
) {
    if cols == 0 {
        return;
    }
    let step = std::f32::consts::TAU / cols as f32;
    let d_max = max_distance_m;
    let nearest = scratch.reset(cols);
    let rows = ranges.chunks_exact(cols).zip(obstacle.chunks_exact(cols));
    for ((rho, obs), d_a) in rows.zip(along_column.chunks_exact_mut(cols)) {
        column_pass_row(rho, obs, nearest, d_max, d_a);
    }
    let rows = ranges.chunks_exact(cols).zip(along_column.chunks_exact(cols));
    for ((rho, d_a), d) in rows.zip(distance.chunks_exact_mut(cols)) {
        row_passes(rho, d_a, d, step, d_max);
    }
}

/// The column pass of Algorithm 1 for one row: `nearest` holds, per column, the smallest range
/// of an obstacle in the rows above (∞ before any).
#[inline]
pub fn column_pass_row(rho: &[f32], obs: &[bool], nearest: &mut [f32], d_max: f32, d_a: &mut [f32]) {
    let n = rho.len().min(obs.len()).min(d_a.len()).min(nearest.len());
    for c in 0..n {
        let (is_obstacle, range, near) = (obs[c], rho[c], nearest[c]);
        nearest[c] = if is_obstacle { near.min(range) } else { near };
        let free = if range > 0.0 { (range - near).abs().min(d_max) } else { d_max };
        d_a[c] = if is_obstacle { 0.0 } else { free };
    }
}

impl DistanceScratch {
    /// Resets the column-pass state for a new panorama of `cols` columns.
    pub fn reset(&mut self, cols: usize) -> &mut [f32] {
        self.nearest_obstacle.clear();
        self.nearest_obstacle.resize(cols, f32::INFINITY);
        &mut self.nearest_obstacle
    }
}

/// The forward and backward `UpdateAz` passes of Algorithm 1 over one row.
///
/// Wherever the propagated distance has reached D_max and the columns ahead have D_a = D_max,
/// the result is D_max and the state that follows is decided by the next column with
/// D_a < D_max alone (it beats any propagated value ≥ D_max): such stretches are skipped.
pub fn row_passes(rho: &[f32], d_a: &[f32], d: &mut [f32], step: f32, d_max: f32) {
    let cols = d.len().min(d_a.len()).min(rho.len());
    let (rho, d_a, d) = (&rho[..cols], &d_a[..cols], &mut d[..cols]);
    d.iter_mut().for_each(|v| *v = d_max);
    row_pass::<true>(rho, d_a, d, step, d_max);
    row_pass::<false>(rho, d_a, d, step, d_max);
}

/// One direction of [`row_passes`] (slices of equal length).
#[inline(always)]
fn row_pass<const FORWARD: bool>(rho: &[f32], d_a: &[f32], d: &mut [f32], step: f32, d_max: f32) {
    let cols = d.len();
    let col = |k: usize| {
        let k = if k >= cols { k - cols } else { k };
        if FORWARD { k } else { cols - 1 - k }
    };
    // p_last as an unwrapped position, its D_a and its arc length per column s(p_last): the
    // propagated value at k is D_a(p_last) + (k − p_last)·s(p_last), computed directly rather
    // than accumulated so that successive columns do not wait on each other.
    let mut anchor = 0usize;
    let mut anchor_value = f32::INFINITY;
    let mut arc = 0.0f32;
    // Unwrapped position k ∈ [0, 2·cols): the second lap is the wrap-around continuation.
    let mut k = 0;
    while k < 2 * cols {
        // Through u32: an unsigned 64-bit integer-to-float conversion is a branchy sequence.
        let mut candidate = anchor_value + (k - anchor) as u32 as f32 * arc;
        if candidate >= d_max {
            if k >= cols {
                break;
            }
            // Skip to the next column whose own D_a is below D_max.
            let next = if FORWARD {
                d_a[k..].iter().position(|&v| v < d_max)
            } else {
                d_a[..cols - k].iter().rev().position(|&v| v < d_max)
            };
            match next {
                Some(offset) => k += offset,
                None => break,
            }
            candidate = f32::INFINITY;
        }
        let c = col(k);
        let own = d_a[c];
        let value = if candidate > own {
            anchor = k;
            anchor_value = own;
            arc = step * rho[c];
            own
        } else {
            candidate
        };
        d[c] = d[c].min(value);
        k += 1;
    }
}

/// Traversable: a return, not an obstacle, and at least `inflation_m` from the nearest obstacle.
pub fn traversable(ranges: &[f32], distance: &[f32], inflation_m: f32, out: &mut [bool]) {
    for ((o, &rho), &d) in out.iter_mut().zip(ranges).zip(distance) {
        // `&` rather than `&&`: no short-circuit branch, so the loop vectorises.
        *o = (rho > 0.0) & (d >= inflation_m);
    }
}

/// Per-column state of the reachability walk.
#[derive(Clone, Debug, Default)]
pub struct ReachScratch {
    last_r: Vec<f32>,
    active: Vec<bool>,
}

/// Stage 6: the reachability scan S(φ). Each column is walked up from the bottom row (nearest
/// ground) over pixels with a return. The walk stops at the first non-traversable pixel (a known
/// obstacle ends the safe stretch) or when the horizontal range jumps by more than `gap_m`
/// between successive returns onto traversable ground (the unknown begins); a non-traversable
/// pixel beyond a gap is still a known obstacle. `range_m` gets the largest horizontal range of
/// the safe pixels walked, at least `min_range_m`, `obstacle` whether an obstacle ended the walk,
/// and `last_row` the last safe row (`rows` if none).
#[allow(clippy::too_many_arguments)]
pub fn reachability(
    r: &[f32],
    ranges: &[f32],
    traversable: &[bool],
    cols: usize,
    gap_m: f32,
    min_range_m: f32,
    scratch: &mut ReachScratch,
    range_m: &mut [f32],
    obstacle: &mut [bool],
    last_row: &mut [u32],
) {
    if cols == 0 {
        return;
    }
    let width = cols;
    let rows = r.len().min(ranges.len()).min(traversable.len()) / width;
    let cols = width.min(range_m.len()).min(obstacle.len()).min(last_row.len());
    scratch.last_r.clear();
    scratch.last_r.resize(cols, -1.0);
    scratch.active.clear();
    scratch.active.resize(cols, true);
    range_m[..cols].iter_mut().for_each(|v| *v = 0.0);
    obstacle[..cols].iter_mut().for_each(|v| *v = false);
    last_row[..cols].iter_mut().for_each(|v| *v = rows as u32);
    let mut active = cols;
    for row in (0..rows).rev() {
        if active == 0 {
            break;
        }
        let base = row * width;
        let (r_row, rho_row, trav_row) =
            (&r[base..base + cols], &ranges[base..base + cols], &traversable[base..base + cols]);
        let (last_r, is_active) = (&mut scratch.last_r[..cols], &mut scratch.active[..cols]);
        let mut still = 0;
        for c in 0..cols {
            let live = is_active[c] & (rho_row[c] > 0.0);
            let horizontal = r_row[c];
            let jump = (last_r[c] >= 0.0) & ((horizontal - last_r[c]).abs() > gap_m);
            // A non-traversable pixel ends the walk as a known obstacle, also beyond a gap; a
            // jump onto traversable ground ends it as unknown.
            let blocked = live & !trav_row[c];
            let accept = live & !jump & trav_row[c];
            is_active[c] &= !live | accept;
            obstacle[c] |= blocked;
            last_r[c] = if accept { horizontal } else { last_r[c] };
            range_m[c] = if accept { range_m[c].max(horizontal) } else { range_m[c] };
            last_row[c] = if accept { row as u32 } else { last_row[c] };
            still += is_active[c] as usize;
        }
        active = still;
    }
    for range in &mut range_m[..cols] {
        *range = range.max(min_range_m);
    }
}
