//! The terrain-analysis stages as plain functions over row-major `rows × cols` buffers.
//!
//! [`crate::TerrainAnalyzer`] chains them with its own tables and scratch buffers; they are public
//! so that tools can run, time or visualise one stage at a time. Every function takes the
//! panorama width `cols` and works on whole rows; a buffer whose length is not a multiple of
//! `cols` has its incomplete last row ignored. No function allocates.
//!
//! Invalid ranges (no return) are stored as 0 after [`fill_holes`]; every later stage treats a
//! pixel with range 0 as unknown: never an obstacle, never traversable.

use wide::{bytemuck, f32x4};

/// The SIMD vector (portable: two 4-lane halves on baseline x86-64): consecutive columns of a
/// row in the gradient, column pass and reachability; the rows of a block, column by column, in
/// Algorithm 1's row passes ([`row_passes_block`]).
type Lanes = wide::f32x8;
/// Lanes per [`Lanes`] vector.
const LANES: usize = 8;
/// 4-lane vectors per [`Lanes`], for the 4 × 4 transposes.
const QUADS_PER_LANES: usize = BLOCK_ROWS / 4;

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
    /// Elevation gradient window w_e per row (0: no row above is far enough, no elevation term).
    pub elevation_window: Vec<u32>,
    /// η_z = η·|sin θ| per row, metres.
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

/// Lanes checked at once by [`first_where`] and [`last_where`].
const SEARCH_CHUNK: usize = 16;

/// `values.iter().position(pred)`, testing [`SEARCH_CHUNK`] values at a time without
/// short-circuiting inside a chunk, so that the test vectorises.
#[inline(always)]
fn first_where<T: Copy>(values: &[T], pred: impl Fn(T) -> bool) -> Option<usize> {
    let chunks = values.chunks_exact(SEARCH_CHUNK);
    let tail_start = values.len() - chunks.remainder().len();
    for (i, chunk) in chunks.enumerate() {
        if chunk.iter().fold(false, |any, &v| any | pred(v)) {
            return chunk.iter().position(|&v| pred(v)).map(|o| i * SEARCH_CHUNK + o);
        }
    }
    values[tail_start..].iter().position(|&v| pred(v)).map(|o| tail_start + o)
}

/// `values.iter().rposition(pred)`, chunked like [`first_where`].
#[inline(always)]
fn last_where<T: Copy>(values: &[T], pred: impl Fn(T) -> bool) -> Option<usize> {
    let chunks = values.rchunks_exact(SEARCH_CHUNK);
    let head_len = chunks.remainder().len();
    for (i, chunk) in chunks.enumerate() {
        if chunk.iter().fold(false, |any, &v| any | pred(v)) {
            let start = values.len() - (i + 1) * SEARCH_CHUNK;
            return chunk.iter().rposition(|&v| pred(v)).map(|o| start + o);
        }
    }
    values[..head_len].iter().rposition(|&v| pred(v))
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
            let Some(offset) = first_where(&row[c..last], |r| r <= 0.0) else { break };
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
/// stored — no stage needs them; [`crate::TerrainOutput::point_m`] gives them per pixel.)
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
pub(crate) fn project_row(rho: &[f32], sin_e: f32, cos_e: f32, z: &mut [f32], r: &mut [f32]) {
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
    /// w_a per column (an integer, as f32).
    half_window: Vec<f32>,
    rise_a: Vec<f32>,
    /// The row's z padded on both sides with the largest w_a of columns from the other end.
    z_padded: Vec<f32>,
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
pub(crate) fn gradient_row(
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
    let (max_half_scalar, max_px_scalar) = (((cols - 1) / 2) as f32, window.max_window_px.max(0.0));
    let (max_half, max_px) = (Lanes::splat(max_half_scalar), Lanes::splat(max_px_scalar));
    let w_over_step = Lanes::splat(window.window_m / step);
    scratch.half_window.resize(cols, 1.0);
    scratch.rise_a.resize(cols, 0.0);
    let base = row * cols;
    let z_row = &z[base..base + cols];
    let r_row = &r[base..base + cols];
    let noise_z = Lanes::splat(tables.noise_z_m.get(row).copied().unwrap_or(0.0));
    let noise_xy = Lanes::splat(tables.noise_xy_m.get(row).copied().unwrap_or(0.0));
    let half = &mut scratch.half_window[..cols];
    let rise_a = &mut scratch.rise_a[..cols];
    let (zero, one, two) = (Lanes::ZERO, Lanes::splat(1.0), Lanes::splat(2.0));
    // w_a from the arc length on the x–y plane, s_xy = (2π/A)·r, so W/s_xy = (W/step)/r;
    // the denominator s·(2w_a + 1) uses the arc length s = (2π/A)·ρ = (2π/A)·r / cos θ.
    let cos_e = tables.row_cos.get(row).copied().unwrap_or(1.0).max(1e-6);
    let arc_per_r = Lanes::splat(step / cos_e);
    for start in (0..cols).step_by(LANES) {
        // Without a return r is NaN and `fast_min` yields W_max (its second operand); that
        // pixel's gradient is 0 anyway.
        let px = (w_over_step / load_lanes(r_row, start)).fast_min(max_px).fast_max(zero);
        store_lanes((floor_small_lanes(px * Lanes::splat(0.5)) + one).fast_min(max_half), half, start);
    }
    // The row with `pad` ≥ max w_a columns of wrap-around on both sides: column c sits at
    // c + pad, and c ± w_a needs no wrap test. (The `min`s never bind; they let the compiler
    // drop the bounds checks.)
    let pad = small_to_u32((floor_small(max_px_scalar * 0.5) + 1.0).min(max_half_scalar)) as usize;
    let padded = &mut scratch.z_padded;
    padded.clear();
    padded.extend_from_slice(&z_row[cols - pad..]);
    padded.extend_from_slice(z_row);
    padded.extend_from_slice(&z_row[..pad]);
    let last = padded.len() - 1;
    for (c, (rise, &h)) in rise_a.iter_mut().zip(half.iter()).enumerate() {
        let h = small_to_u32(h) as usize;
        let (left, right) = ((c + pad - h).min(last), (c + pad + h).min(last));
        *rise = (padded[left] - padded[right]).abs();
    }
    let w_e = tables.elevation_window.get(row).copied().unwrap_or(0) as usize;
    let above = (w_e > 0 && w_e <= row).then(|| (row - w_e) * cols);
    for start in (0..cols).step_by(LANES) {
        let r_c = load_lanes(r_row, start);
        let run_a = arc_per_r * r_c * (two * load_lanes(half, start) + one);
        let (rise_a, run_a) = positive_part_lanes(load_lanes(rise_a, start) - noise_z, run_a);
        let g = match above {
            Some(b) => {
                let (z_up, r_up) = (load_lanes(&z[b..b + cols], start), load_lanes(&r[b..b + cols], start));
                // sqrt(∇_a² + ∇_e²) with one division: sqrt((a·n_e)² + (e·n_a)²) / (n_a·n_e).
                let rise_e = (load_lanes(z_row, start) - z_up).abs() - noise_z;
                let (rise_e, run_e) = positive_part_lanes(rise_e, (r_c - r_up).abs() + noise_xy);
                let (ta, te) = (rise_a * run_e, rise_e * run_a);
                (ta * ta + te * te).sqrt() / (run_a * run_e)
            }
            None => rise_a / run_a,
        };
        // NaN (no return) becomes 0.
        store_lanes(g.simd_ge(zero) & g, out, start);
    }
}

/// [`LANES`] values of `values` from `start`, NaN past the end.
#[inline(always)]
fn load_lanes(values: &[f32], start: usize) -> Lanes {
    match values.get(start..start + LANES) {
        Some(chunk) => Lanes::new(chunk.try_into().unwrap_or([f32::NAN; LANES])),
        None => {
            let mut padded = [f32::NAN; LANES];
            padded.iter_mut().zip(values.iter().skip(start)).for_each(|(slot, &x)| *slot = x);
            Lanes::new(padded)
        }
    }
}

/// Stores the lanes of `v` to `values` from `start`, dropping those past the end.
#[inline(always)]
fn store_lanes(v: Lanes, values: &mut [f32], start: usize) {
    let lanes = v.to_array();
    match values.get_mut(start..start + LANES) {
        Some(chunk) => chunk.copy_from_slice(&lanes),
        None => values.iter_mut().skip(start).zip(lanes).for_each(|(slot, x)| *slot = x),
    }
}

/// [`floor_small`] per lane.
#[inline(always)]
fn floor_small_lanes(v: Lanes) -> Lanes {
    let shift = Lanes::splat(8_388_608.0); // 2²³
    let rounded = (v + shift) - shift;
    rounded - (rounded.simd_gt(v) & Lanes::splat(1.0))
}

/// Per lane (max(rise, 0), run clamped away from 0); a NaN rise (a neighbour without a return)
/// gives rise 0, a NaN run (the pixel has no return) stays NaN so that the caller yields 0.
#[inline(always)]
fn positive_part_lanes(rise: Lanes, run: Lanes) -> (Lanes, Lanes) {
    let rise = rise.simd_gt(Lanes::ZERO) & rise;
    // `fast_max` is `max` here: `run` is not NaN where it is kept.
    (rise, run.simd_ge(Lanes::ZERO).select(run.fast_max(Lanes::splat(1e-12)), run))
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

/// Stage 4: obstacle = gradient above `slope_threshold`; then, along each row with wrap, runs of
/// obstacle pixels whose arc length Σ(2π/A)·ρ is below `min_run_m` are cleared as noise.
pub fn obstacles(
    gradient: &[f32],
    ranges: &[f32],
    cols: usize,
    slope_threshold: f32,
    min_run_m: f32,
    obstacle: &mut [bool],
) {
    if cols == 0 {
        return;
    }
    let step = std::f32::consts::TAU / cols as f32;
    let rows = gradient.chunks_exact(cols).zip(ranges.chunks_exact(cols));
    for ((grad, rho), obs) in rows.zip(obstacle.chunks_exact_mut(cols)) {
        let mut any = false;
        for ((o, &g), &rho) in obs.iter_mut().zip(grad).zip(rho) {
            *o = (g > slope_threshold) & (rho > 0.0);
            any |= *o;
        }
        if !any {
            continue;
        }
        // A row that is all obstacle is one closed ring, at least as long as any run: kept.
        let Some(first_free) = obs.iter().position(|&o| !o) else { continue };
        let last_free = obs.iter().rposition(|&o| !o).unwrap_or(first_free);
        // The run across the seam: (last_free, cols) then [0, first_free).
        let seam = run_length(rho[last_free + 1..].iter().chain(&rho[..first_free]), step, min_run_m);
        if seam > 0.0 && seam < min_run_m {
            obs[last_free + 1..].iter_mut().for_each(|o| *o = false);
            obs[..first_free].iter_mut().for_each(|o| *o = false);
        }
        let mut c = first_free;
        while c < last_free {
            let Some(offset) = first_where(&obs[c..last_free], |o| o) else { break };
            let start = c + offset;
            let end = first_where(&obs[start..last_free], |o| !o).map_or(last_free, |o| start + o);
            if run_length(rho[start..end].iter(), step, min_run_m) < min_run_m {
                obs[start..end].iter_mut().for_each(|o| *o = false);
            }
            c = end;
        }
    }
}

/// The arc length (Σρ)·`step` of a run, summed in order, or as soon as the partial sum already
/// reaches `min_run_m` that partial length (ranges are ≥ 0, so the sum only grows: a run found
/// long stays long, and the comparison with `min_run_m` comes out as with the full sum).
#[inline]
fn run_length<'a>(ranges: impl Iterator<Item = &'a f32>, step: f32, min_run_m: f32) -> f32 {
    let mut sum = 0.0f32;
    for &rho in ranges {
        sum += rho;
        if sum * step >= min_run_m {
            break;
        }
    }
    sum * step
}

/// Scratch space for [`distance_transform`]: one value per column and the row pass state.
#[derive(Clone, Debug, Default)]
pub struct DistanceScratch {
    nearest_obstacle: Vec<f32>,
    block: RowBlockScratch,
}

/// Rows handled together by [`row_passes_block`], one per SIMD lane.
pub(crate) const BLOCK_ROWS: usize = LANES;

/// A block of [`BLOCK_ROWS`] rows transposed to column-major, one row per lane, for
/// [`row_passes_block`].
#[derive(Clone, Debug, Default)]
pub(crate) struct RowBlockScratch {
    /// D_a per column.
    own: Vec<Lanes>,
    /// s = (2π/A)·ρ per column.
    arc: Vec<Lanes>,
    /// Some row of the block has D_a < D_max in this column.
    below: Vec<bool>,
    /// D per column.
    out: Vec<Lanes>,
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
    let (nearest, block) = scratch.reset(cols);
    let rows = ranges.chunks_exact(cols).zip(obstacle.chunks_exact(cols));
    for ((rho, obs), d_a) in rows.zip(along_column.chunks_exact_mut(cols)) {
        column_pass_row(rho, obs, nearest, d_max, d_a);
    }
    let width = BLOCK_ROWS * cols;
    let blocks = ranges.chunks_exact(width).zip(along_column.chunks_exact(width));
    let full_rows = blocks.len() * BLOCK_ROWS;
    for ((rho, d_a), d) in blocks.zip(distance.chunks_exact_mut(width)) {
        row_passes_block(rho, d_a, d, cols, step, d_max, block);
    }
    let rows = ranges.chunks_exact(cols).zip(along_column.chunks_exact(cols)).skip(full_rows);
    for ((rho, d_a), d) in rows.zip(distance.chunks_exact_mut(cols).skip(full_rows)) {
        row_passes(rho, d_a, d, step, d_max);
    }
}

/// The column pass of Algorithm 1 for one row: `nearest` holds, per column, the smallest range
/// of an obstacle in the rows above (∞ before any).
#[inline]
pub(crate) fn column_pass_row(rho: &[f32], obs: &[bool], nearest: &mut [f32], d_max: f32, d_a: &mut [f32]) {
    let n = rho.len().min(obs.len()).min(d_a.len()).min(nearest.len());
    let (rho, obs, nearest, d_a) = (&rho[..n], &obs[..n], &mut nearest[..n], &mut d_a[..n]);
    let vectorised = n / BLOCK_ROWS * BLOCK_ROWS;
    // [`BLOCK_ROWS`] columns per vector with explicit selects (as plain code the compiler turns
    // the conditional update of `nearest` into a scalarised masked store). No NaN reaches the
    // `fast_min`s: ranges are finite and `nearest` is finite or ∞.
    let d_max_lanes = Lanes::splat(d_max);
    let chunks = rho[..vectorised]
        .chunks_exact(BLOCK_ROWS)
        .zip(obs[..vectorised].chunks_exact(BLOCK_ROWS))
        .zip(nearest[..vectorised].chunks_exact_mut(BLOCK_ROWS).zip(d_a[..vectorised].chunks_exact_mut(BLOCK_ROWS)));
    for ((rho, obs), (nearest, d_a)) in chunks {
        let range = Lanes::new(std::array::from_fn(|i| rho[i]));
        let is_obstacle = Lanes::new(std::array::from_fn(|i| obs[i] as u8 as f32)).simd_gt(Lanes::ZERO);
        let near = Lanes::new(std::array::from_fn(|i| nearest[i]));
        let updated = is_obstacle.select(range.fast_min(near), near);
        let free = range.simd_gt(Lanes::ZERO).select((range - near).abs().fast_min(d_max_lanes), d_max_lanes);
        let value = is_obstacle.select(Lanes::ZERO, free);
        nearest.copy_from_slice(&updated.to_array());
        d_a.copy_from_slice(&value.to_array());
    }
    for c in vectorised..n {
        let (is_obstacle, range, near) = (obs[c], rho[c], nearest[c]);
        nearest[c] = if is_obstacle { near.min(range) } else { near };
        let free = if range > 0.0 { (range - near).abs().min(d_max) } else { d_max };
        d_a[c] = if is_obstacle { 0.0 } else { free };
    }
}

impl DistanceScratch {
    /// Resets the column-pass state for a new panorama of `cols` columns.
    pub(crate) fn reset(&mut self, cols: usize) -> (&mut [f32], &mut RowBlockScratch) {
        self.nearest_obstacle.clear();
        self.nearest_obstacle.resize(cols, f32::INFINITY);
        (&mut self.nearest_obstacle, &mut self.block)
    }
}

/// The forward and backward `UpdateAz` passes of Algorithm 1 over one row.
///
/// Wherever the propagated distance has reached D_max and the columns ahead have D_a = D_max,
/// the result is D_max and the state that follows is decided by the next column with
/// D_a < D_max alone (it beats any propagated value ≥ D_max): such stretches are skipped.
pub(crate) fn row_passes(rho: &[f32], d_a: &[f32], d: &mut [f32], step: f32, d_max: f32) {
    let cols = d.len().min(d_a.len()).min(rho.len());
    let (rho, d_a, d) = (&rho[..cols], &d_a[..cols], &mut d[..cols]);
    d.iter_mut().for_each(|v| *v = d_max);
    row_pass::<true>(rho, d_a, d, step, d_max);
    row_pass::<false>(rho, d_a, d, step, d_max);
}

/// [`row_passes`] for [`BLOCK_ROWS`] consecutive rows at once (`rho`, `d_a` and `d` hold
/// `BLOCK_ROWS × cols` values), one row per SIMD lane: bit for bit the same result.
///
/// The lanes follow the scalar passes step by step, with the branches turned into selects:
/// where the scalar pass skips a stretch because the propagated value has reached D_max, a lane
/// instead restarts from each column's own D_a (≥ D_max over such a stretch), which writes
/// nothing below D_max and leaves the same state at the next column with D_a < D_max.
pub(crate) fn row_passes_block(
    rho: &[f32],
    d_a: &[f32],
    d: &mut [f32],
    cols: usize,
    step: f32,
    d_max: f32,
    scratch: &mut RowBlockScratch,
) {
    let width = BLOCK_ROWS * cols;
    if cols == 0 || rho.len() < width || d_a.len() < width || d.len() < width {
        return;
    }
    let (rho, d_a, d) = (&rho[..width], &d_a[..width], &mut d[..width]);
    // Nothing below D_max in any of the rows: D = D_max throughout.
    if first_where(d_a, |v| v < d_max).is_none() {
        d.iter_mut().for_each(|v| *v = d_max);
        return;
    }
    let RowBlockScratch { own, arc, below, out } = scratch;
    own.resize(cols, Lanes::ZERO);
    arc.resize(cols, Lanes::ZERO);
    below.resize(cols, false);
    out.clear();
    out.resize(cols, Lanes::splat(d_max));
    let (own, arc, below, out) = (&mut own[..cols], &mut arc[..cols], &mut below[..cols], &mut out[..cols]);
    transpose_to_lanes(d_a, cols, own);
    transpose_to_lanes(rho, cols, arc);
    let step_lanes = Lanes::splat(step);
    arc.iter_mut().for_each(|a| *a *= step_lanes);
    let d_max_lanes = Lanes::splat(d_max);
    for (b, o) in below.iter_mut().zip(own.iter()) {
        *b = o.simd_lt(d_max_lanes).any();
    }
    block_pass::<true>(own, arc, below, out, d_max);
    block_pass::<false>(own, arc, below, out, d_max);
    transpose_from_lanes(out, cols, d);
}

/// Row l of the `BLOCK_ROWS × cols` block `rows` becomes lane l of `lanes` (`cols` entries),
/// 4 × 4 tiles at a time.
fn transpose_to_lanes(rows: &[f32], cols: usize, lanes: &mut [Lanes]) {
    let quads: &mut [f32x4] = bytemuck::cast_slice_mut(lanes);
    let tiled = cols / 4 * 4;
    for group in 0..QUADS_PER_LANES {
        let block = &rows[4 * group * cols..(4 * group + 4) * cols];
        let (r0, r1, r2, r3) = (&block[..cols], &block[cols..2 * cols], &block[2 * cols..3 * cols], &block[3 * cols..]);
        for c in (0..tiled).step_by(4) {
            let load = |row: &[f32]| f32x4::new([row[c], row[c + 1], row[c + 2], row[c + 3]]);
            let tile = f32x4::transpose([load(r0), load(r1), load(r2), load(r3)]);
            for (j, column) in tile.into_iter().enumerate() {
                quads[(c + j) * QUADS_PER_LANES + group] = column;
            }
        }
    }
    let flat: &mut [f32] = bytemuck::cast_slice_mut(lanes);
    for (lane, row) in rows.chunks_exact(cols).enumerate() {
        for c in tiled..cols {
            flat[c * BLOCK_ROWS + lane] = row[c];
        }
    }
}

/// The inverse of [`transpose_to_lanes`].
fn transpose_from_lanes(lanes: &[Lanes], cols: usize, rows: &mut [f32]) {
    let quads: &[f32x4] = bytemuck::cast_slice(lanes);
    let tiled = cols / 4 * 4;
    for group in 0..QUADS_PER_LANES {
        let block = &mut rows[4 * group * cols..(4 * group + 4) * cols];
        for c in (0..tiled).step_by(4) {
            let load = |j: usize| quads[(c + j) * QUADS_PER_LANES + group];
            let tile = f32x4::transpose([load(0), load(1), load(2), load(3)]);
            for (i, row_values) in tile.into_iter().enumerate() {
                block[i * cols + c..i * cols + c + 4].copy_from_slice(&row_values.to_array());
            }
        }
    }
    let flat: &[f32] = bytemuck::cast_slice(lanes);
    for (lane, row) in rows.chunks_exact_mut(cols).enumerate() {
        for c in tiled..cols {
            row[c] = flat[c * BLOCK_ROWS + lane];
        }
    }
}

/// One direction of [`row_passes_block`] over transposed columns (slices of equal length;
/// `below[c]`: some lane of column c has D_a < D_max).
#[inline(always)]
fn block_pass<const FORWARD: bool>(own: &[Lanes], arc: &[Lanes], below: &[bool], out: &mut [Lanes], d_max: f32) {
    let cols = out.len().min(own.len()).min(arc.len()).min(below.len());
    let col = |k: usize| {
        let k = if k >= cols { k - cols } else { k };
        if FORWARD { k } else { cols - 1 - k }
    };
    let d_max_lanes = Lanes::splat(d_max);
    let (infinity, one) = (Lanes::splat(f32::INFINITY), Lanes::splat(1.0));
    // Per lane: k − p_last (an integer below 2²⁴, exact in f32), D_a(p_last) and s(p_last), so
    // that D_a(p_last) + (k − p_last)·s(p_last) is computed exactly as the scalar pass does.
    let (mut offset, mut anchor_value, mut arc_last) = (Lanes::ZERO, infinity, Lanes::ZERO);
    let mut k = 0;
    while k < cols {
        offset += one;
        let mut candidate = anchor_value + offset * arc_last;
        if candidate.simd_ge(d_max_lanes).all() {
            // Every lane has reached D_max: until some lane has D_a < D_max nothing is written and
            // each lane restarts at that column (the propagated values only grow meanwhile).
            let next = if FORWARD {
                first_where(&below[k..], |b| b).map(|o| k + o)
            } else {
                last_where(&below[..cols - k], |b| b).map(|i| cols - 1 - i)
            };
            match next {
                Some(next) => k = next,
                None => break,
            }
            candidate = infinity;
        }
        let c = col(k);
        let own_c = own[c];
        // Beaten by the column's own D_a. Where the candidate has reached D_max the scalar pass
        // skips to the next column with D_a < D_max and restarts there; here the candidate only
        // grows until that column beats it, and no value written in between is below D_max.
        let restart = candidate.simd_gt(own_c);
        // The value is own where restarting, else the candidate: min(candidate, own).
        out[c] = out[c].fast_min(candidate.fast_min(own_c));
        offset = restart.select(Lanes::ZERO, offset);
        anchor_value = restart.select(own_c, anchor_value);
        arc_last = restart.select(arc[c], arc_last);
        k += 1;
    }
    // The wrap-around lap: a lane stops for good once its propagated value reaches D_max.
    let mut alive = Lanes::splat(f32::from_bits(u32::MAX));
    for k in cols..2 * cols {
        let c = col(k);
        offset += one;
        let candidate = anchor_value + offset * arc_last;
        alive &= candidate.simd_lt(d_max_lanes);
        if !alive.any() {
            break;
        }
        let own_c = own[c];
        let restart = candidate.simd_gt(own_c);
        out[c] = out[c].fast_min(alive.select(candidate.fast_min(own_c), infinity));
        offset = restart.select(Lanes::ZERO, offset);
        anchor_value = restart.select(own_c, anchor_value);
        arc_last = restart.select(arc[c], arc_last);
    }
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
                first_where(&d_a[k..], |v| v < d_max)
            } else {
                last_where(&d_a[..cols - k], |v| v < d_max).map(|i| cols - k - 1 - i)
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

/// Per-column state of the reachability walk, [`Lanes`] columns per vector (the last vector
/// padded with columns that never have a return).
#[derive(Clone, Debug, Default)]
pub struct ReachScratch {
    r: Vec<Lanes>,
    rho: Vec<Lanes>,
    trav: Vec<Lanes>,
    last_r: Vec<Lanes>,
    active: Vec<Lanes>,
    blocked: Vec<Lanes>,
    range: Vec<Lanes>,
    last_row: Vec<Lanes>,
}

/// Copies `values` into `lanes` (zero-padded), [`BLOCK_ROWS`] values per vector.
fn fill_lanes(values: impl Iterator<Item = f32>, lanes: &mut [Lanes]) {
    let flat: &mut [f32] = bytemuck::cast_slice_mut(lanes);
    let padded = flat.len();
    let mut copied = 0;
    for (slot, v) in flat.iter_mut().zip(values) {
        *slot = v;
        copied += 1;
    }
    flat[copied.min(padded)..].iter_mut().for_each(|v| *v = 0.0);
}

/// Stage 6: the reachability scan S(φ). Each column is walked up from the bottom row (nearest
/// ground) over pixels with a return. The walk stops at the first non-traversable pixel (a known
/// obstacle ends the safe stretch) or when the horizontal range jumps by more than `gap_m`
/// between successive returns (the unknown begins). `range_m` gets the largest horizontal range
/// of the safe pixels walked, `obstacle` whether an obstacle ended the walk, and `last_row` the
/// last safe row (`rows` if none).
///
/// All columns advance together one row at a time, as SIMD lanes with masks for the per-column
/// decisions, until no column is still walking.
#[allow(clippy::too_many_arguments)]
pub fn reachability(
    r: &[f32],
    ranges: &[f32],
    traversable: &[bool],
    cols: usize,
    gap_m: f32,
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
    let vectors = cols.div_ceil(BLOCK_ROWS);
    let ReachScratch {
        r: r_lanes,
        rho: rho_lanes,
        trav: trav_lanes,
        last_r,
        active,
        blocked,
        range,
        last_row: row_lanes,
    } = scratch;
    for buffer in [&mut *r_lanes, &mut *rho_lanes, &mut *trav_lanes, &mut *last_r, &mut *active, &mut *blocked] {
        buffer.clear();
        buffer.resize(vectors, Lanes::ZERO);
    }
    range.clear();
    range.resize(vectors, Lanes::ZERO);
    row_lanes.clear();
    row_lanes.resize(vectors, Lanes::splat(rows as f32));
    last_r.iter_mut().for_each(|v| *v = Lanes::splat(-1.0));
    // Padding columns are not walking.
    fill_lanes((0..cols).map(|_| f32::from_bits(u32::MAX)), active);
    let (gap, zero) = (Lanes::splat(gap_m), Lanes::ZERO);
    let mut walking = cols;
    for row in (0..rows).rev() {
        if walking == 0 {
            break;
        }
        let span = row * width..row * width + cols;
        fill_lanes(r[span.clone()].iter().copied(), r_lanes);
        fill_lanes(ranges[span.clone()].iter().copied(), rho_lanes);
        fill_lanes(traversable[span].iter().map(|&t| if t { f32::from_bits(u32::MAX) } else { 0.0 }), trav_lanes);
        let row_index = Lanes::splat(row as f32);
        let mut still = 0;
        let state = active.iter_mut().zip(last_r.iter_mut()).zip(blocked.iter_mut()).zip(range.iter_mut());
        let inputs = r_lanes.iter().zip(rho_lanes.iter()).zip(trav_lanes.iter()).zip(row_lanes.iter_mut());
        for ((((active, last_r), blocked), range), (((&horizontal, &rho), &trav), last_row)) in state.zip(inputs) {
            let live = *active & rho.simd_gt(zero);
            let jump = last_r.simd_ge(zero) & (horizontal - *last_r).abs().simd_gt(gap);
            let accept = live & !jump & trav;
            // A jump ends the walk (unknown beyond), an obstacle ends it (known obstacle).
            *blocked |= live & !jump & !trav;
            *active &= !live | accept;
            *last_r = accept.select(horizontal, *last_r);
            // Accepted pixels have a return: `horizontal` is a positive number there.
            *range = accept.select(range.fast_max(horizontal), *range);
            *last_row = accept.select(row_index, *last_row);
            still += active.to_bitmask().count_ones() as usize;
        }
        walking = still;
    }
    let range_flat: &[f32] = bytemuck::cast_slice(range);
    let blocked_flat: &[f32] = bytemuck::cast_slice(blocked);
    let row_flat: &[f32] = bytemuck::cast_slice(row_lanes);
    for c in 0..cols {
        range_m[c] = range_flat[c];
        obstacle[c] = blocked_flat[c].to_bits() != 0;
        // An integer-valued row index below 2²³ (or `rows`): exact.
        last_row[c] = small_to_u32(row_flat[c]);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const COLS: usize = 16;

    /// 5 rows × 16 columns, row r at range 6 − r (top rows farther), one obstacle at (2, `col`).
    fn single_obstacle(col: usize) -> (Vec<f32>, Vec<f32>) {
        let ranges: Vec<f32> = (0..5 * COLS).map(|i| 6.0 - (i / COLS) as f32).collect();
        let mut obstacle = vec![false; ranges.len()];
        obstacle[2 * COLS + col] = true;
        let mut scratch = DistanceScratch::default();
        let (mut d_a, mut d) = (vec![0.0; ranges.len()], vec![0.0; ranges.len()]);
        distance_transform(&ranges, &obstacle, COLS, 3.0, &mut scratch, &mut d_a, &mut d);
        (d_a, d)
    }

    #[test]
    fn floor_small_is_floor() {
        for i in 0..100_000 {
            let v = i as f32 * 0.001_37;
            assert_eq!(floor_small(v), v.floor(), "{v}");
        }
        assert_eq!(floor_small(2.0), 2.0);
        assert_eq!(floor_small(2.5), 2.0);
        assert_eq!(floor_small(3.5), 3.0);
        for i in [0u32, 1, 2, 103, 511, 1 << 20] {
            assert_eq!(small_to_u32(i as f32), i);
        }
    }

    #[test]
    fn floor_small_lanes_is_floor() {
        for i in 0..10_000 {
            let v: [f32; LANES] = std::array::from_fn(|l| (i * LANES + l) as f32 * 0.013_7);
            let floored = floor_small_lanes(Lanes::new(v)).to_array();
            assert_eq!(floored, v.map(f32::floor));
        }
    }

    /// [`row_passes_block`] against [`row_passes`] row by row, on rows full of the edge cases:
    /// D_a exactly D_max, no return (ρ = 0), obstacles (D_a = 0), equal neighbours.
    #[test]
    fn row_block_matches_scalar_row_passes() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        let d_max = 2.0f32;
        let mut block = RowBlockScratch::default();
        for cols in [3usize, 4, 7, 8, 13, 33, 64, 101] {
            let step = std::f32::consts::TAU / cols as f32;
            for _ in 0..40 {
                let n = BLOCK_ROWS * cols;
                let rho: Vec<f32> =
                    (0..n).map(|_| [0.0, 1.0, 4.0, rng.random_range(0.5..20.0)][rng.random_range(0..4)]).collect();
                let d_a: Vec<f32> =
                    (0..n).map(|_| [0.0, d_max, 0.5, rng.random_range(0.0..d_max)][rng.random_range(0..4)]).collect();
                let mut expected = vec![0.0; n];
                for ((rho, d_a), d) in
                    rho.chunks_exact(cols).zip(d_a.chunks_exact(cols)).zip(expected.chunks_exact_mut(cols))
                {
                    row_passes(rho, d_a, d, step, d_max);
                }
                let mut got = vec![-1.0; n];
                row_passes_block(&rho, &d_a, &mut got, cols, step, d_max, &mut block);
                let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
                assert_eq!(bits(&got), bits(&expected), "cols {cols}");
            }
        }
    }

    #[test]
    fn distance_transform_follows_algorithm_1() {
        let (d_a, d) = single_obstacle(5);
        let step = std::f32::consts::TAU / COLS as f32;
        let close = |a: f32, b: f32| (a - b).abs() < 1e-5;
        // Column pass: rows above the obstacle (scanned before it) see nothing; rows below get
        // |ρ − ρ_obstacle|.
        assert!(close(d_a[5], 3.0) && close(d_a[COLS + 5], 3.0));
        assert!(close(d_a[2 * COLS + 5], 0.0));
        assert!(close(d_a[3 * COLS + 5], 1.0) && close(d_a[4 * COLS + 5], 2.0));
        // Row passes: D_a(p_last) + |p_a − p_last|·s(p_last), s = (2π/A)·ρ(p_last), capped.
        for (row, base) in [(2usize, 0.0f32), (3, 1.0), (4, 2.0)] {
            let s = step * (6.0 - row as f32);
            for c in 0..COLS {
                let offset = (c as i32 - 5).unsigned_abs() as usize;
                let offset = offset.min(COLS - offset) as f32;
                let expected = (base + offset * s).min(3.0);
                assert!(close(d[row * COLS + c], expected), "({row}, {c}): {} vs {expected}", d[row * COLS + c]);
            }
        }
        assert!(d[..2 * COLS].iter().all(|&v| close(v, 3.0)));
    }

    #[test]
    fn distance_transform_wraps_in_azimuth() {
        let (_, d) = single_obstacle(0);
        let s = std::f32::consts::TAU / COLS as f32 * 4.0;
        assert!((d[2 * COLS + COLS - 1] - s).abs() < 1e-5);
        assert!((d[2 * COLS + 1] - s).abs() < 1e-5);
    }

    #[test]
    fn elevation_window_is_the_smallest_that_spans_w_on_flat_ground() {
        let (rows, fov, h, w) = (64usize, std::f64::consts::FRAC_PI_2, 0.4, 0.5);
        let elevation = |row: usize| fov / 2.0 - row as f64 * fov / (rows - 1) as f64;
        let t = Tables::new(rows, 8, elevation, h, w, 0.05);
        let ground = |row: usize| h / (-elevation(row)).tan();
        for row in rows / 2 + 2..rows {
            let we = t.elevation_window[row] as usize;
            if we < row && elevation(row - we) < 0.0 {
                assert!(ground(row - we) - ground(row) >= w - 1e-9, "row {row}");
                assert!(we == 1 || ground(row - we + 1) - ground(row) < w, "row {row}");
            }
        }
    }

    #[test]
    fn short_obstacle_runs_are_removed_long_ones_kept() {
        // One row at 2 m: a pixel spans 2π/16·2 ≈ 0.785 m, so use a wider ring for short runs.
        let cols = 256;
        let ranges = vec![2.0f32; cols]; // 0.049 m per pixel
        let mut gradient = vec![0.0f32; cols];
        for c in (10..14).chain(100..120).chain((0..3).chain(cols - 3..cols)) {
            gradient[c] = 1.0;
        }
        let mut obstacle = vec![false; cols];
        obstacles(&gradient, &ranges, cols, 0.3, 0.3, &mut obstacle);
        // 4 px ≈ 0.2 m: removed; 20 px ≈ 0.98 m: kept; 6 px across the seam ≈ 0.29 m: removed.
        assert!(obstacle[10..14].iter().all(|&o| !o));
        assert!(obstacle[100..120].iter().all(|&o| o));
        assert!(obstacle[..3].iter().chain(&obstacle[cols - 3..]).all(|&o| !o));
        // 7 px across the seam ≈ 0.34 m: kept.
        gradient[3] = 1.0;
        obstacles(&gradient, &ranges, cols, 0.3, 0.3, &mut obstacle);
        assert!(obstacle[..4].iter().chain(&obstacle[cols - 3..]).all(|&o| o));
    }
}
