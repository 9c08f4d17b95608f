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
/// row in the gradient, column pass and reachability.
type Lanes = wide::f32x8;
/// Lanes per [`Lanes`] vector.
const LANES: usize = 8;
/// The SIMD vector of Algorithm 1's row passes ([`row_passes_block`]): the rows of a block,
/// one per lane, column by column. (8 rows; 4 and 16 measured slower.)
type BlockLanes = wide::f32x8;
/// 4-lane vectors per [`BlockLanes`], for the 4 × 4 transposes.
const QUADS_PER_BLOCK: usize = BLOCK_ROWS / 4;

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
    /// Elevation gradient window w_e per row: below the horizon the paper's flat-ground rule,
    /// at and above it 1 (the next row up); 0 for row 0 (no elevation term).
    pub elevation_window: Vec<u32>,
    /// |η_z| = η·|sin θ| per row, metres: subtracted from height differences, so the gradient is
    /// the smallest one noise of order η could hide (the paper's stated intent; see the README's
    /// rule 2).
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
                // At and above the horizon there is no flat ground to predict ranges from: the
                // next row up (the authors' rule; row 0 has none).
                if elevations[row] >= 0.0 || elevations[row].is_nan() {
                    return row.min(1) as u32;
                }
                // Smallest δ whose flat-ground ranges h_s/tan θ differ by at least W (a row
                // above the horizon always does). Without one inside the field of view, use
                // the top row, the farthest available.
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

/// `values.iter().position(|&v| pred(v))` for a comparison `pred` that `lanes` evaluates on
/// [`LANES`] values at once (a mask), 16 values at a time: two vector compares and a bit mask,
/// whose lowest set bit is the position (no search loop inside a chunk).
#[inline(always)]
fn first_lanes(values: &[f32], lanes: impl Fn(Lanes) -> Lanes, pred: impl Fn(f32) -> bool) -> Option<usize> {
    let chunks = values.chunks_exact(2 * LANES);
    let tail_start = values.len() - chunks.remainder().len();
    for (i, chunk) in chunks.enumerate() {
        let (low, high) = chunk.split_at(LANES);
        let mask = lanes(lanes_of(low)).to_bitmask() | (lanes(lanes_of(high)).to_bitmask() << LANES);
        if mask != 0 {
            return Some(i * 2 * LANES + mask.trailing_zeros() as usize);
        }
    }
    values[tail_start..].iter().position(|&v| pred(v)).map(|o| tail_start + o)
}

/// `values.iter().position(|&v| v == target)`, 16 values at a time: one byte compare and a bit
/// mask, whose lowest set bit is the position.
#[inline(always)]
fn first_equal(values: &[bool], target: bool) -> Option<usize> {
    let chunks = values.chunks_exact(16);
    let tail_start = values.len() - chunks.remainder().len();
    let wanted = wide::u8x16::splat(target as u8);
    for (i, chunk) in chunks.enumerate() {
        let mask = wide::u8x16::new(std::array::from_fn(|j| chunk[j] as u8)).simd_eq(wanted).to_bitmask();
        if mask != 0 {
            return Some(i * 16 + mask.trailing_zeros() as usize);
        }
    }
    values[tail_start..].iter().position(|&v| v == target).map(|o| tail_start + o)
}

#[inline]
fn sanitize(range: f32) -> f32 {
    // Finite and positive (0 < range < ∞; NaN fails) as one unsigned comparison of the bits: the
    // positive finite non-zero floats are exactly the bit patterns 1..=0x7F7F_FFFF, so
    // bits − 1 (wrapping) < 0x7F7F_FFFF. Written as the two float comparisons, the compiler
    // vectorised it into 15 instructions per 8 pixels (integer range tests for each); this is 4.
    if range.to_bits().wrapping_sub(1) < 0x7F7F_FFFF { range } else { 0.0 }
}

/// Stage 1: copies `input` to `out` (non-finite and non-positive ranges become 0 = no return)
/// and fills, along each row with wrap in azimuth, every run of missing pixels whose arc length
/// is at most `max_gap_m` (the paper's D_m; D_px = D_m / s with s = (2π/A)·ρ, ρ the larger of the
/// two ranges bounding the run) by linear interpolation between its ends.
#[inline(always)]
pub fn fill_holes(input: &[f32], out: &mut [f32], cols: usize, max_gap_m: f32) {
    fill_holes_with(input, out, cols, max_gap_m, &mut Vec::new(), false);
}

/// [`fill_holes`]; `wide_registers`: the caller is compiled for AVX2 or AVX-512, where filling
/// the single missing pixels in one vectorised pass first pays (on the SSE2 baseline it was
/// measured slower than the search alone); `clean` is scratch for that pass (one row), unused
/// on the baseline.
#[inline(always)]
pub(crate) fn fill_holes_with(
    input: &[f32],
    out: &mut [f32],
    cols: usize,
    max_gap_m: f32,
    clean: &mut Vec<f32>,
    wide_registers: bool,
) {
    if cols == 0 {
        return;
    }
    let col_step = std::f32::consts::TAU / cols as f32;
    for (row_in, row) in input.chunks_exact(cols).zip(out.chunks_exact_mut(cols)) {
        if wide_registers {
            let holes_left = sanitize_and_fill_single_holes(row_in, row, clean, col_step, max_gap_m);
            // No hole left inside the row and returns at both ends: nothing to search (the
            // search below would find no hole, and the seam has none).
            if !holes_left && row.first().is_some_and(|&r| r > 0.0) && row.last().is_some_and(|&r| r > 0.0) {
                continue;
            }
        } else {
            for (o, &i) in row.iter_mut().zip(row_in) {
                *o = sanitize(i);
            }
        }
        if cols <= BIT_ROW_COLS {
            fill_row_holes_by_mask(row, col_step, max_gap_m);
            continue;
        }
        let (Some(first), Some(last)) = (row.iter().position(|&r| r > 0.0), row.iter().rposition(|&r| r > 0.0)) else {
            continue;
        };
        // The hole across the seam, from `last` around to `first`.
        fill_gap(row, last, first + cols, col_step, max_gap_m);
        let mut c = first;
        while c < last {
            // `c` holds a return; find the next hole and the return that ends it.
            let Some(offset) = first_lanes(&row[c..last], |v| v.simd_le(Lanes::ZERO), |v| v <= 0.0) else { break };
            let start = c + offset;
            // Most holes are single pixels: test the next one before searching.
            let end = if row[start + 1] > 0.0 {
                start + 1
            } else {
                first_lanes(&row[start..=last], |v| v.simd_gt(Lanes::ZERO), |v| v > 0.0).map_or(last, |o| start + o)
            };
            fill_gap(row, start - 1, end, col_step, max_gap_m);
            c = end;
        }
    }
}

/// Widest row whose return mask ([`BitRow`]) the hole search keeps on the stack; wider rows take
/// the chunked search ([`first_lanes`]).
const BIT_ROW_COLS: usize = 64 * BIT_ROW_WORDS;
/// 64-bit words of a [`BitRow`].
const BIT_ROW_WORDS: usize = 64;

/// One flag per column of a row (at most [`BIT_ROW_COLS`]), 64 to a word; the bits past the row's
/// end are 0. Finding the next hole is then a `trailing_zeros` per word, and a row with many
/// holes (a real sensor's) costs a few instructions per hole instead of a search that reloads
/// the row.
struct BitRow {
    words: [u64; BIT_ROW_WORDS],
    /// Words in use: ⌈cols/64⌉.
    len: usize,
}

impl BitRow {
    /// Bit c set where `row[c] > 0` (a return), `row.len()` ≤ [`BIT_ROW_COLS`].
    #[inline(always)]
    fn returns(row: &[f32]) -> Self {
        let mut bits = BitRow { words: [0; BIT_ROW_WORDS], len: row.len().div_ceil(64).min(BIT_ROW_WORDS) };
        for (word, chunk) in bits.words.iter_mut().zip(row.chunks(64)) {
            if let Ok(full) = <&[f32; 64]>::try_from(chunk) {
                // Eight vector compares and their sign masks.
                *word = full.chunks_exact(LANES).enumerate().fold(0, |w, (k, eight)| {
                    w | (u64::from(lanes_of(eight).simd_gt(Lanes::ZERO).to_bitmask()) << (LANES * k))
                });
            } else {
                *word = chunk.iter().enumerate().fold(0, |w, (k, &r)| w | (u64::from(r > 0.0) << k));
            }
        }
        bits
    }

    /// Bit c set where `flags[c]`, `flags.len()` ≤ [`BIT_ROW_COLS`].
    #[cfg(test)]
    fn flags(flags: &[bool]) -> Self {
        let mut bits = BitRow { words: [0; BIT_ROW_WORDS], len: flags.len().div_ceil(64).min(BIT_ROW_WORDS) };
        for (word, chunk) in bits.words.iter_mut().zip(flags.chunks(64)) {
            *word = chunk.iter().enumerate().fold(0, |w, (k, &f)| w | (u64::from(f) << k));
        }
        bits
    }

    /// The first column ≥ `from` whose bit is `set`, if any; searching for an unset bit may
    /// answer a column past the row's end (its bits are 0), which callers bound.
    #[inline(always)]
    fn next(&self, from: usize, set: bool) -> Option<usize> {
        let flip = if set { 0 } else { u64::MAX };
        let mut w = from / 64;
        let mut bits = (*self.words[..self.len].get(w)? ^ flip) & (u64::MAX << (from % 64));
        loop {
            if bits != 0 {
                return Some(w * 64 + bits.trailing_zeros() as usize);
            }
            w += 1;
            bits = *self.words[..self.len].get(w)? ^ flip;
        }
    }

    /// The last column with its bit set, if any.
    #[inline(always)]
    fn last_set(&self) -> Option<usize> {
        let w = self.words[..self.len].iter().rposition(|&w| w != 0)?;
        Some(w * 64 + 63 - self.words[w].leading_zeros() as usize)
    }
}

/// [`fill_holes`]'s search and fill for one sanitised row (`row.len()` ≤ [`BIT_ROW_COLS`]): the
/// hole across the seam, then every hole between the first and the last return, found in the
/// row's return mask. The holes are those the chunked search finds, in the same order, so the
/// result is the same bit for bit (a fill only writes inside its own hole, and the mask is taken
/// before any: no search reads a filled pixel).
#[inline(always)]
fn fill_row_holes_by_mask(row: &mut [f32], col_step: f32, max_gap_m: f32) {
    let returns = BitRow::returns(row);
    fill_row_holes_in_mask(row, &returns, col_step, max_gap_m);
}

/// [`fill_row_holes_by_mask`] with the row's return mask given (it must be the row's).
#[inline(always)]
fn fill_row_holes_in_mask(row: &mut [f32], returns: &BitRow, col_step: f32, max_gap_m: f32) {
    let cols = row.len();
    let (Some(first), Some(last)) = (returns.next(0, true), returns.last_set()) else { return };
    // The hole across the seam, from `last` around to `first`.
    fill_gap(row, last, first + cols, col_step, max_gap_m);
    let mut c = first;
    // `c` holds a return; the next hole starts at the next pixel without one, and ends at the
    // return after it (there is one: `last`).
    while let Some(start) = returns.next(c, false).filter(|&start| start < last) {
        let end = returns.next(start, true).unwrap_or(last);
        fill_gap(row, start - 1, end, col_step, max_gap_m);
        c = end;
    }
}

/// `row` = the sanitised `row_in`, with each single missing pixel between two returns (not
/// across the seam) filled as [`fill_gap`] does: most holes are single dropouts, and this pass
/// fills them without a search or a branch (the compiler vectorises it). A filled pixel's
/// neighbours are returns of the input, so the fill does not depend on the order of the holes.
/// Returns whether a pixel strictly inside the row is still missing (then, or without returns at
/// both ends, the caller searches for the longer holes).
///
/// The row is sanitised into `clean` first (one vectorised pass), so that each pixel is
/// sanitised once, not once per neighbour (with the mask search of [`fill_row_holes_by_mask`],
/// 27 % fewer instructions in this stage on the bench street with a real sensor's dropouts).
#[inline(always)]
fn sanitize_and_fill_single_holes(
    row_in: &[f32],
    row: &mut [f32],
    clean: &mut Vec<f32>,
    col_step: f32,
    max_gap_m: f32,
) -> bool {
    let cols = row.len().min(row_in.len());
    if cols < 3 {
        row.iter_mut().zip(row_in).for_each(|(o, &i)| *o = sanitize(i));
        return true;
    }
    clean.resize(cols, 0.0);
    let clean = &mut clean[..cols];
    for (c, &i) in clean.iter_mut().zip(row_in) {
        *c = sanitize(i);
    }
    let neighbours = clean[..cols - 2].iter().zip(&clean[1..cols - 1]).zip(&clean[2..cols]);
    let mut holes_left = false;
    for (o, ((&left, &centre), &right)) in row[1..cols - 1].iter_mut().zip(neighbours) {
        let widest = if left > right { left } else { right };
        // [`fill_gap`] for a gap of 1: 1·step = step exactly, and 1·(1/2) = ½.
        let missing = centre <= 0.0;
        let fill = missing & (left > 0.0) & (right > 0.0) & (col_step * widest <= max_gap_m);
        holes_left |= missing & !fill;
        *o = if fill { left + (right - left) * 0.5 } else { centre };
    }
    row[0] = clean[0];
    row[cols - 1] = clean[cols - 1];
    holes_left
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
    if gap == 1 {
        // The loop below for j = 1: 1·(1/2) = ½ exactly, without the division.
        row[wrap(from + 1)] = start + (end - start) * 0.5;
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
#[inline(always)]
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
#[inline(always)]
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
    /// w_a per column as an index; [`ANY_WINDOW`] where the pixel has no return (on AVX2 and
    /// AVX-512; the baseline stores w_a there too).
    half_index: Vec<u32>,
    rise_a: Vec<f32>,
    /// The row's z padded on both sides with the largest w_a of columns from the other end.
    z_padded: Vec<f32>,
}

/// Stage 3: gradient magnitude |∇| = sqrt(∇_a² + ∇_e²) per pixel, with the paper's metric
/// windows w_a = ⌊min(W/s_xy, W_max)/2⌋ + 1 (azimuth, wrapping) and w_e (per row, from
/// [`Tables`]), and the noise |η_z| = η·|sin θ| subtracted from height differences and η_xy
/// added to the horizontal-range difference: the minimum gradient noise of order η could hide,
/// as the paper's text says (its formula's signed sin θ would add |η_z| below the horizon; see
/// the README's rule 2). `z` and `r` come from [`project`] (NaN without a return); a term whose
/// neighbour has no return is 0 (the other term stands alone), and the gradient of a pixel
/// without a return is 0.
#[inline(always)]
pub fn gradients(
    z: &[f32],
    r: &[f32],
    tables: &Tables,
    window: GradientWindow,
    scratch: &mut GradientScratch,
    gradient: &mut [f32],
) {
    gradients_with(z, r, tables, window, scratch, gradient, pulp::Scalar::new());
}

/// [`gradients`] compiled for the instruction set of `simd` (see [`gradient_row`]).
#[inline(always)]
pub(crate) fn gradients_with<S: pulp::Simd>(
    z: &[f32],
    r: &[f32],
    tables: &Tables,
    window: GradientWindow,
    scratch: &mut GradientScratch,
    gradient: &mut [f32],
    simd: S,
) {
    let cols = tables.cols;
    if cols < 3 {
        gradient.iter_mut().for_each(|g| *g = 0.0);
        return;
    }
    let rows = z.len().min(r.len()).min(gradient.len()) / cols;
    for (row, out) in gradient.chunks_exact_mut(cols).take(rows).enumerate() {
        gradient_row(row, z, r, tables, window, scratch, out, simd);
    }
}

/// [`gradients`] for one row: `z` and `r` are whole panoramas, of which this row and the row
/// w_e above it are read; `out` is the row's gradient. Compiled for AVX2 or AVX-512 (`simd`)
/// it runs [`gradient_row_columns`], for the baseline [`gradient_row_lanes`].
#[allow(clippy::too_many_arguments)]
#[inline(always)]
pub(crate) fn gradient_row<S: pulp::Simd>(
    row: usize,
    z: &[f32],
    r: &[f32],
    tables: &Tables,
    window: GradientWindow,
    scratch: &mut GradientScratch,
    out: &mut [f32],
    simd: S,
) {
    if !S::IS_SCALAR {
        gradient_row_columns(row, z, r, tables, window, scratch, out, simd);
    } else {
        gradient_row_lanes(row, z, r, tables, window, scratch, out);
    }
}

/// [`gradient_row`] as plain per-column loops.
///
/// The loops are plain per-column code the compiler vectorises for the instruction set the
/// caller is compiled for (512-bit vectors under AVX-512: the divisions and square roots bound
/// this stage). Every step is written as the x86 vector instruction it becomes ([`min_ps`],
/// [`max_ps`]: the second operand where either is NaN), so that each width gives the same bits.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn gradient_row_columns<S: pulp::Simd>(
    row: usize,
    z: &[f32],
    r: &[f32],
    tables: &Tables,
    window: GradientWindow,
    scratch: &mut GradientScratch,
    out: &mut [f32],
    simd: S,
) {
    let cols = tables.cols;
    if cols < 3 || out.len() != cols || z.len() < (row + 1) * cols || r.len() < (row + 1) * cols {
        out.iter_mut().for_each(|g| *g = 0.0);
        return;
    }
    let step = tables.col_step_rad;
    let (max_half, max_px) = (((cols - 1) / 2) as f32, window.max_window_px.max(0.0));
    let w_over_step = window.window_m / step;
    scratch.half_window.resize(cols, 1.0);
    scratch.half_index.resize(cols, 1);
    scratch.rise_a.resize(cols, 0.0);
    let base = row * cols;
    let z_row = &z[base..base + cols];
    let r_row = &r[base..base + cols];
    let noise_z = tables.noise_z_m.get(row).copied().unwrap_or(0.0);
    let noise_xy = tables.noise_xy_m.get(row).copied().unwrap_or(0.0);
    let half = &mut scratch.half_window[..cols];
    let half_index = &mut scratch.half_index[..cols];
    let rise_a = &mut scratch.rise_a[..cols];
    // w_a from the arc length on the x–y plane, s_xy = (2π/A)·r, so W/s_xy = (W/step)/r;
    // the denominator s·(2w_a + 1) uses the arc length s = (2π/A)·ρ = (2π/A)·r / cos θ.
    let cos_e = tables.row_cos.get(row).copied().unwrap_or(1.0).max(1e-6);
    let arc_per_r = step / cos_e;
    // Without a return r is NaN and `min_ps` yields W_max (its second operand); that pixel's
    // gradient is 0 anyway.
    for ((&r, h), index) in r_row.iter().zip(half.iter_mut()).zip(half_index.iter_mut()) {
        let px = max_ps(min_ps(w_over_step / r, max_px), 0.0);
        let w_a = min_ps(floor_small(px * 0.5) + 1.0, max_half);
        *h = w_a;
        // Without a return (r NaN) the gradient is 0 whatever the rise: any window will do, so
        // that column does not split a run of equal windows in [`azimuth_rise`].
        #[allow(clippy::eq_op)]
        let has_return = r == r;
        *index = if has_return { small_to_u32(w_a) } else { ANY_WINDOW };
    }
    // The row with `pad` ≥ max w_a columns of wrap-around on both sides: column c sits at
    // c + pad, and c ± w_a needs no wrap test.
    let pad = small_to_u32(min_ps(floor_small(max_px * 0.5) + 1.0, max_half)) as usize;
    let padded = &mut scratch.z_padded;
    padded.clear();
    padded.extend_from_slice(&z_row[cols - pad..]);
    padded.extend_from_slice(z_row);
    padded.extend_from_slice(&z_row[..pad]);
    azimuth_rise_with(simd, padded, pad, half_index, rise_a);
    let w_e = tables.elevation_window.get(row).copied().unwrap_or(0) as usize;
    let above = (w_e > 0 && w_e <= row).then(|| (row - w_e) * cols);
    // ∇_a's rise and run, clamped: a NaN rise (a neighbour without a return) gives 0, a NaN
    // run (the pixel has no return) stays NaN so that the gradient is 0.
    let azimuth = |r_c: f32, half: f32, rise: f32| {
        let run_a = arc_per_r * r_c * (2.0 * half + 1.0);
        (zero_unless_positive(rise - noise_z), clamp_run(run_a))
    };
    // NaN (no return) becomes 0; a gradient is NaN or ≥ +0, never −0.
    match above {
        Some(b) => {
            let (z_up, r_up) = (&z[b..b + cols], &r[b..b + cols]);
            let columns = (r_row.iter().zip(half.iter()))
                .zip(rise_a.iter().zip(z_row))
                .zip(z_up.iter().zip(r_up))
                .zip(out.iter_mut());
            for ((((&r_c, &h), (&rise, &z_c)), (&z_up, &r_up)), o) in columns {
                let (rise_a, run_a) = azimuth(r_c, h, rise);
                // sqrt(∇_a² + ∇_e²) with one division: sqrt((a·n_e)² + (e·n_a)²) / (n_a·n_e).
                let rise_e = zero_unless_positive((z_c - z_up).abs() - noise_z);
                let run_e = clamp_run((r_c - r_up).abs() + noise_xy);
                // No return one window up: ∇_e = 0 (its rise is already 0) and the azimuth term
                // stands alone; a run of 1 keeps the NaN out of the shared denominator.
                #[allow(clippy::eq_op)]
                let run_e = if r_up == r_up { run_e } else { 1.0 };
                let (ta, te) = (rise_a * run_e, rise_e * run_a);
                *o = zero_unless_positive((ta * ta + te * te).sqrt() / (run_a * run_e));
            }
        }
        None => {
            let columns = r_row.iter().zip(half.iter()).zip(rise_a.iter()).zip(out.iter_mut());
            for (((&r_c, &h), &rise), o) in columns {
                let (rise_a, run_a) = azimuth(r_c, h, rise);
                *o = zero_unless_positive(rise_a / run_a);
            }
        }
    }
}

/// `minps`: a where a < b, else b (so b where either is NaN, and b for ±0 against ∓0).
#[inline(always)]
pub(crate) fn min_ps(a: f32, b: f32) -> f32 {
    if a < b { a } else { b }
}

/// `maxps`: a where a > b, else b (so b where either is NaN, and b for ±0 against ∓0).
#[inline(always)]
fn max_ps(a: f32, b: f32) -> f32 {
    if a > b { a } else { b }
}

/// `v` where v > 0, else +0 (NaN and −0 included).
#[inline(always)]
fn zero_unless_positive(v: f32) -> f32 {
    max_ps(v, 0.0)
}

/// max(run, 1e-12), NaN kept as NaN. (Runs are never negative here: horizontal ranges and
/// η·cos θ are ≥ 0 for |θ| ≤ π/2; a negative run would be clamped too.)
#[inline(always)]
fn clamp_run(run: f32) -> f32 {
    max_ps(1e-12, run)
}

/// [`gradient_row_columns`] with explicit [`LANES`]-wide vectors: faster than the compiler's own
/// vectorisation for the SSE2 baseline (measured), the same bits.
#[inline(always)]
fn gradient_row_lanes(
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
    scratch.half_index.resize(cols, 1);
    scratch.rise_a.resize(cols, 0.0);
    let base = row * cols;
    let z_row = &z[base..base + cols];
    let r_row = &r[base..base + cols];
    let noise_z = Lanes::splat(tables.noise_z_m.get(row).copied().unwrap_or(0.0));
    let noise_xy = Lanes::splat(tables.noise_xy_m.get(row).copied().unwrap_or(0.0));
    let half = &mut scratch.half_window[..cols];
    let half_index = &mut scratch.half_index[..cols];
    let rise_a = &mut scratch.rise_a[..cols];
    let (zero, one, two) = (Lanes::ZERO, Lanes::splat(1.0), Lanes::splat(2.0));
    // w_a from the arc length on the x–y plane, s_xy = (2π/A)·r, so W/s_xy = (W/step)/r;
    // the denominator s·(2w_a + 1) uses the arc length s = (2π/A)·ρ = (2π/A)·r / cos θ.
    let cos_e = tables.row_cos.get(row).copied().unwrap_or(1.0).max(1e-6);
    let arc_per_r = Lanes::splat(step / cos_e);
    // Without a return r is NaN and `fast_min` yields W_max (its second operand); that pixel's
    // gradient is 0 anyway.
    let w_a = |r: Lanes| {
        let px = (w_over_step / r).fast_min(max_px).fast_max(zero);
        (floor_small_lanes(px * Lanes::splat(0.5)) + one).fast_min(max_half)
    };
    // Whole vectors through `chunks_exact` (no bounds checks), then the partial one.
    let full = cols / LANES * LANES;
    let chunks = r_row[..full]
        .chunks_exact(LANES)
        .zip(half[..full].chunks_exact_mut(LANES).zip(half_index[..full].chunks_exact_mut(LANES)));
    for (r, (h, index)) in chunks {
        let v = w_a(lanes_of(r));
        h.copy_from_slice(&v.to_array());
        store_index_lanes(v, index, 0);
    }
    if full < cols {
        let v = w_a(load_lanes(r_row, full));
        store_lanes(v, half, full);
        store_index_lanes(v, half_index, full);
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
    azimuth_rise(padded, pad, half_index, rise_a);
    let w_e = tables.elevation_window.get(row).copied().unwrap_or(0) as usize;
    let above = (w_e > 0 && w_e <= row).then(|| (row - w_e) * cols);
    // ∇_a's rise and run, clamped.
    let azimuth = |r_c: Lanes, half: Lanes, rise: Lanes| {
        let run_a = arc_per_r * r_c * (two * half + one);
        positive_part_lanes(rise - noise_z, run_a)
    };
    // NaN (no return) becomes 0.
    // (A gradient is NaN or ≥ +0, never −0: the same as keeping it where g ≥ 0.)
    let finish = zero_unless_positive_lanes;
    match above {
        Some(b) => {
            let (z_up, r_up) = (&z[b..b + cols], &r[b..b + cols]);
            let gradient = |r_c: Lanes, half: Lanes, rise: Lanes, z_c: Lanes, z_up: Lanes, r_up: Lanes| {
                let (rise_a, run_a) = azimuth(r_c, half, rise);
                // sqrt(∇_a² + ∇_e²) with one division: sqrt((a·n_e)² + (e·n_a)²) / (n_a·n_e).
                let rise_e = (z_c - z_up).abs() - noise_z;
                let (rise_e, run_e) = positive_part_lanes(rise_e, (r_c - r_up).abs() + noise_xy);
                // No return one window up: ∇_e = 0 (its rise is already 0) and the azimuth term
                // stands alone; a run of 1 keeps the NaN out of the shared denominator.
                let run_e = r_up.simd_eq(r_up).select(run_e, one);
                let (ta, te) = (rise_a * run_e, rise_e * run_a);
                finish((ta * ta + te * te).sqrt() / (run_a * run_e))
            };
            let chunks = (r_row[..full].chunks_exact(LANES).zip(half[..full].chunks_exact(LANES)))
                .zip(rise_a[..full].chunks_exact(LANES).zip(z_row[..full].chunks_exact(LANES)))
                .zip(z_up[..full].chunks_exact(LANES).zip(r_up[..full].chunks_exact(LANES)))
                .zip(out[..full].chunks_exact_mut(LANES));
            for ((((r_c, h), (rise, z_c)), (z_u, r_u)), o) in chunks {
                let g =
                    gradient(lanes_of(r_c), lanes_of(h), lanes_of(rise), lanes_of(z_c), lanes_of(z_u), lanes_of(r_u));
                o.copy_from_slice(&g.to_array());
            }
            if full < cols {
                let load = |values: &[f32]| load_lanes(values, full);
                let g = gradient(load(r_row), load(half), load(rise_a), load(z_row), load(z_up), load(r_up));
                store_lanes(g, out, full);
            }
        }
        None => {
            let gradient = |r_c: Lanes, half: Lanes, rise: Lanes| {
                let (rise_a, run_a) = azimuth(r_c, half, rise);
                finish(rise_a / run_a)
            };
            let chunks = (r_row[..full].chunks_exact(LANES).zip(half[..full].chunks_exact(LANES)))
                .zip(rise_a[..full].chunks_exact(LANES))
                .zip(out[..full].chunks_exact_mut(LANES));
            for (((r_c, h), rise), o) in chunks {
                o.copy_from_slice(&gradient(lanes_of(r_c), lanes_of(h), lanes_of(rise)).to_array());
            }
            if full < cols {
                let g = gradient(load_lanes(r_row, full), load_lanes(half, full), load_lanes(rise_a, full));
                store_lanes(g, out, full);
            }
        }
    }
}

/// The [`LANES`] values of a whole chunk.
#[inline(always)]
fn lanes_of(chunk: &[f32]) -> Lanes {
    Lanes::new(std::array::from_fn(|i| chunk[i]))
}

/// A column's azimuth window in [`GradientScratch`]'s indices when the pixel has no return: its
/// gradient is 0 whatever its rise ([`gradient_row_columns`]: the run is NaN), so [`azimuth_rise`]
/// may use any window there (it uses `pad` when alone, else its run's).
const ANY_WINDOW: u32 = u32::MAX;

/// |z(c − w_a) − z(c + w_a)| per column c: `padded` is the row with `pad` ≥ every w_a columns of
/// wrap-around on both sides, `half` holds w_a per column ([`ANY_WINDOW`]: a column whose rise
/// is not used, given any value).
///
/// The baseline's version (AVX2 and AVX-512 run [`azimuth_rise_with`]'s permutes). On ground
/// and walls w_a changes slowly along a row, so most runs of [`LANES`] columns share one w_a:
/// their neighbours at ±w_a are then two vector loads instead of a gather. Runs with mixed w_a
/// take the scalar loop. Columns marked [`ANY_WINDOW`] do not count. (Selecting among the loads
/// of each distinct w_a of a run was measured slower here: mixed runs mostly spread widely; so
/// were a gather loop on AVX2 and AVX-512, and keeping this function out of line.)
#[inline(always)]
fn azimuth_rise(padded: &[f32], pad: usize, half: &[u32], rise: &mut [f32]) {
    let cols = rise.len().min(half.len()).min(padded.len().saturating_sub(2 * pad));
    let (half, rise) = (&half[..cols], &mut rise[..cols]);
    let vectorised = cols / LANES * LANES;
    let chunks = rise[..vectorised].chunks_exact_mut(LANES).zip(half[..vectorised].chunks_exact(LANES));
    for ((rise, h), start) in chunks.zip((0..).step_by(LANES)) {
        // The run's window, taken from its first or last column (a run whose ends both lack a
        // return but whose middle has two windows takes the scalar loop, correctly; all
        // [`ANY_WINDOW`]: `pad`). Equality tests only: they vectorise, a min/max reduction
        // over u32 did not (SSE2 has no unsigned minimum).
        let first = if h[0] != ANY_WINDOW { h[0] } else { h[LANES - 1] };
        if h.iter().fold(true, |same, &x| same & ((x == first) | (x == ANY_WINDOW))) {
            let h = (first as usize).min(pad);
            // Column c sits at c + pad in `padded`.
            let left = lanes_of(&padded[start + pad - h..start + pad - h + LANES]);
            let right = lanes_of(&padded[start + pad + h..start + pad + h + LANES]);
            rise.copy_from_slice(&(left - right).abs().to_array());
        } else {
            azimuth_rise_scalar(&padded[start..start + 2 * pad + LANES], pad, h, rise);
        }
    }
    azimuth_rise_scalar(&padded[vectorised..], pad, &half[vectorised..], &mut rise[vectorised..]);
}

/// [`azimuth_rise`] one column at a time (`padded` starts at the first column's window).
#[inline(always)]
fn azimuth_rise_scalar(padded: &[f32], pad: usize, half: &[u32], rise: &mut [f32]) {
    // Column c's window is padded[c..=c + 2·pad], centred on c + pad.
    for ((rise, &h), window) in rise.iter_mut().zip(half).zip(padded.windows(2 * pad + 1)) {
        let h = (h as usize).min(pad);
        let (left, right) = (&window[..=pad], &window[pad..]);
        *rise = (left[pad - h] - right[h]).abs();
    }
}

/// [`azimuth_rise`] with the instruction set's permutes, where `simd` is AVX-512 (runs of 16
/// columns, one two-register permute per side) or AVX2 (runs of 8, two one-register permutes and
/// a blend per side); else [`azimuth_rise`].
///
/// A run takes its neighbours at ±w_a from the `2·N` values around its reference window (its
/// first column's, or its last's when the first has no return): two plain loads when every
/// window is the reference, else one permute per side for windows within `N/2` of it. On a real
/// sensor's panorama half of the runs have mixed windows (w_a changes with the noise of r),
/// which the scalar loop took one column at a time (a fifth of the pipeline's instructions on
/// the street with dropouts). Runs whose windows spread further, and runs whose tables would
/// leave the padded row, still take the scalar loop. Each column gets the same two values
/// subtracted as in [`azimuth_rise_scalar`], so the same bits. (Permuting every run, equal
/// windows too, measured slower on the simulator's panorama, where 92 % of the runs have one
/// window: +14 µs of gradients and +2 % instructions.)
#[inline(always)]
fn azimuth_rise_with<S: pulp::Simd>(simd: S, padded: &[f32], pad: usize, half: &[u32], rise: &mut [f32]) {
    #[cfg(target_arch = "x86_64")]
    {
        // `S` is one concrete type in each compiled copy: these tests are resolved at compile time.
        let any: &dyn std::any::Any = &simd;
        if let Some(&v4) = any.downcast_ref::<pulp::x86::V4>() {
            azimuth_rise_runs(Avx512Run(v4), padded, pad, half, rise);
            return;
        }
        if let Some(&v3) = any.downcast_ref::<pulp::x86::V3>() {
            azimuth_rise_runs(Avx2Run(v3), padded, pad, half, rise);
            return;
        }
    }
    let _ = simd;
    azimuth_rise(padded, pad, half, rise);
}

/// One run of `N` columns of [`azimuth_rise_with`].
trait RiseRun<const N: usize>: Copy {
    /// `rise[i]` = |padded[c − w_i] − padded[c + w_i]| for c = `start` + `pad` + i and
    /// w_i = min(`h[i]`, `pad`) (any window where `h[i]` is [`ANY_WINDOW`]), from the tables of
    /// [`run_tables`]; false, and `rise` untouched, where some window is too far from the
    /// reference for them.
    fn run(self, tables: RunTables<'_>, pad: usize, h: &[u32; N], rise: &mut [f32; N]) -> bool;
}

/// The values a run of `n` columns reads, for [`RiseRun::run`]: `2·n` from
/// start + pad − reference − n/2 (left neighbours) and from start + pad + reference − n/2
/// (right neighbours).
#[derive(Clone, Copy)]
struct RunTables<'a> {
    reference: u32,
    left: &'a [f32],
    right: &'a [f32],
}

/// [`RunTables`] of the run of `n` columns from `start` with windows `h`; `None` where they
/// would leave `padded`.
#[inline(always)]
fn run_tables<'a>(padded: &'a [f32], pad: usize, start: usize, n: usize, h: &[u32]) -> Option<RunTables<'a>> {
    let first = *h.first()?;
    let reference = if first != ANY_WINDOW { first } else { *h.last()? };
    let reference = (reference as usize).min(pad);
    let centre = start + pad;
    let left = centre.checked_sub(reference + n / 2)?;
    let right = (centre + reference).checked_sub(n / 2)?;
    Some(RunTables {
        reference: u32::try_from(reference).ok()?,
        left: padded.get(left..left + 2 * n)?,
        right: padded.get(right..right + 2 * n)?,
    })
}

/// [`RiseRun`] of 16 columns with AVX-512.
#[cfg(target_arch = "x86_64")]
#[derive(Clone, Copy)]
struct Avx512Run(pulp::x86::V4);

#[cfg(target_arch = "x86_64")]
impl RiseRun<16> for Avx512Run {
    #[inline(always)]
    fn run(self, tables: RunTables<'_>, pad: usize, h: &[u32; 16], rise: &mut [f32; 16]) -> bool {
        use std::arch::x86_64::{__m512, __m512i};
        let f = self.0.avx512f;
        let (Ok(left), Ok(right)) = (<&[f32; 32]>::try_from(tables.left), <&[f32; 32]>::try_from(tables.right)) else {
            return false;
        };
        let splat = |v: u32| f._mm512_set1_epi32(v as i32);
        let h: __m512i = bytemuck::cast(*h);
        let reference = splat(tables.reference);
        // w_i: h_i clamped to `pad`, the reference where h_i is any window.
        let any = f._mm512_cmpeq_epi32_mask(h, splat(ANY_WINDOW));
        let w = f._mm512_mask_blend_epi32(any, f._mm512_min_epu32(h, splat(pad as u32)), reference);
        if f._mm512_cmpneq_epi32_mask(w, reference) == 0 {
            // One window: the neighbours are the tables' values from n/2 on.
            let l: [f32; 16] = std::array::from_fn(|j| left[8 + j]);
            let r: [f32; 16] = std::array::from_fn(|j| right[8 + j]);
            *rise = std::array::from_fn(|j| (l[j] - r[j]).abs());
            return true;
        }
        let iota = f._mm512_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15);
        let base = f._mm512_add_epi32(iota, splat(8));
        // Left i + 8 + reference − w_i, right i + 8 + w_i − reference: in [0, 32) when
        // |w_i − reference| ≤ 8; outside (wrapping) the bits above the fifth are set.
        let left_index = f._mm512_sub_epi32(f._mm512_add_epi32(base, reference), w);
        let right_index = f._mm512_sub_epi32(f._mm512_add_epi32(base, w), reference);
        let outside = f._mm512_test_epi32_mask(f._mm512_or_si512(left_index, right_index), splat(!31));
        if outside != 0 {
            return false;
        }
        let table = |t: &[f32; 32], i: usize| -> __m512 {
            let half: [f32; 16] = std::array::from_fn(|j| t[16 * i + j]);
            bytemuck::cast(half)
        };
        let l = f._mm512_permutex2var_ps(table(left, 0), left_index, table(left, 1));
        let r = f._mm512_permutex2var_ps(table(right, 0), right_index, table(right, 1));
        *rise = bytemuck::cast(f._mm512_abs_ps(f._mm512_sub_ps(l, r)));
        true
    }
}

/// [`RiseRun`] of 8 columns with AVX2.
#[cfg(target_arch = "x86_64")]
#[derive(Clone, Copy)]
struct Avx2Run(pulp::x86::V3);

#[cfg(target_arch = "x86_64")]
impl Avx2Run {
    /// `table[index[i]]` per lane, `index` in [0, 16): a permute of each half, blended on bit 3.
    #[inline(always)]
    fn pick(self, table: &[f32; 16], index: std::arch::x86_64::__m256i) -> std::arch::x86_64::__m256 {
        let (avx, avx2) = (self.0.avx, self.0.avx2);
        let low: [f32; 8] = std::array::from_fn(|j| table[j]);
        let high: [f32; 8] = std::array::from_fn(|j| table[8 + j]);
        let low = avx2._mm256_permutevar8x32_ps(bytemuck::cast(low), index);
        let high = avx2._mm256_permutevar8x32_ps(bytemuck::cast(high), index);
        // Bit 3 of the index to the sign bit, which the blend reads.
        avx._mm256_blendv_ps(low, high, avx._mm256_castsi256_ps(avx2._mm256_slli_epi32::<28>(index)))
    }
}

#[cfg(target_arch = "x86_64")]
impl RiseRun<8> for Avx2Run {
    #[inline(always)]
    fn run(self, tables: RunTables<'_>, pad: usize, h: &[u32; 8], rise: &mut [f32; 8]) -> bool {
        use std::arch::x86_64::__m256i;
        let (avx, avx2) = (self.0.avx, self.0.avx2);
        let (Ok(left), Ok(right)) = (<&[f32; 16]>::try_from(tables.left), <&[f32; 16]>::try_from(tables.right)) else {
            return false;
        };
        let splat = |v: u32| avx._mm256_set1_epi32(v as i32);
        let h: __m256i = bytemuck::cast(*h);
        let reference = splat(tables.reference);
        // w_i: h_i clamped to `pad`, the reference where h_i is any window.
        let any = avx2._mm256_cmpeq_epi32(h, splat(ANY_WINDOW));
        let w = avx2._mm256_blendv_epi8(avx2._mm256_min_epu32(h, splat(pad as u32)), reference, any);
        if avx._mm256_testz_si256(avx2._mm256_xor_si256(w, reference), splat(u32::MAX)) != 0 {
            // One window: the neighbours are the tables' values from n/2 on.
            let l: [f32; 8] = std::array::from_fn(|j| left[4 + j]);
            let r: [f32; 8] = std::array::from_fn(|j| right[4 + j]);
            *rise = std::array::from_fn(|j| (l[j] - r[j]).abs());
            return true;
        }
        let base = avx2._mm256_add_epi32(avx._mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7), splat(4));
        // Left i + 4 + reference − w_i, right i + 4 + w_i − reference: in [0, 16) when
        // |w_i − reference| ≤ 4; outside (wrapping) the bits above the fourth are set.
        let left_index = avx2._mm256_sub_epi32(avx2._mm256_add_epi32(base, reference), w);
        let right_index = avx2._mm256_sub_epi32(avx2._mm256_add_epi32(base, w), reference);
        if avx._mm256_testz_si256(avx2._mm256_or_si256(left_index, right_index), splat(!15)) == 0 {
            return false;
        }
        let diff = avx._mm256_sub_ps(self.pick(left, left_index), self.pick(right, right_index));
        let magnitude = avx._mm256_and_ps(diff, avx._mm256_castsi256_ps(splat(0x7FFF_FFFF)));
        *rise = bytemuck::cast(magnitude);
        true
    }
}

/// [`azimuth_rise_with`] in runs of `N` columns with `kernel`, the scalar loop for the runs it
/// declines and the last partial run.
#[inline(always)]
fn azimuth_rise_runs<const N: usize, K: RiseRun<N>>(
    kernel: K,
    padded: &[f32],
    pad: usize,
    half: &[u32],
    rise: &mut [f32],
) {
    let cols = rise.len().min(half.len()).min(padded.len().saturating_sub(2 * pad));
    let (half, rise) = (&half[..cols], &mut rise[..cols]);
    let vectorised = cols / N * N;
    let chunks = rise[..vectorised].chunks_exact_mut(N).zip(half[..vectorised].chunks_exact(N));
    for ((rise, h), start) in chunks.zip((0..).step_by(N)) {
        let (Ok(rise_run), Ok(h_run)) = (<&mut [f32; N]>::try_from(&mut *rise), <&[u32; N]>::try_from(h)) else {
            continue;
        };
        let done = run_tables(padded, pad, start, N, h).is_some_and(|t| kernel.run(t, pad, h_run, rise_run));
        if !done {
            azimuth_rise_scalar(&padded[start..start + 2 * pad + N], pad, h, rise);
        }
    }
    azimuth_rise_scalar(&padded[vectorised..], pad, &half[vectorised..], &mut rise[vectorised..]);
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

/// [`small_to_u32`] per lane (one truncating conversion, `cvttps2dq` on SSE2: exact for the
/// integer values in [0, 2²³) it is used on), stored to `values` from `start` (dropping lanes
/// past the end).
#[inline(always)]
fn store_index_lanes(v: Lanes, values: &mut [u32], start: usize) {
    let lanes: [u32; LANES] = bytemuck::cast(v.fast_trunc_int().to_array());
    match values.get_mut(start..start + LANES) {
        Some(chunk) => chunk.copy_from_slice(&lanes),
        None => values.iter_mut().skip(start).zip(lanes).for_each(|(slot, x)| *slot = x),
    }
}

/// [`floor_small`] per lane: for 0 ≤ v < 2²³ the floor is the truncation, and one truncating
/// conversion to integers and one back (`cvttps2dq`, `cvtdq2ps` on SSE2) are exact there.
#[inline(always)]
fn floor_small_lanes(v: Lanes) -> Lanes {
    Lanes::from_i32x8(v.fast_trunc_int())
}

/// Per lane (max(rise, 0), run clamped away from 0); a NaN rise (a neighbour without a return)
/// gives rise 0, a NaN run (the pixel has no return) stays NaN so that the caller yields 0.
#[inline(always)]
fn positive_part_lanes(rise: Lanes, run: Lanes) -> (Lanes, Lanes) {
    (zero_unless_positive_lanes(rise), clamp_run_lanes(run))
}

/// Per lane `v` where v > 0, else +0 (NaN and −0 included). With SSE one `maxps(v, 0)`, which
/// returns its second operand (+0) when v is NaN or equal to it (±0).
#[cfg(target_feature = "sse")]
#[inline(always)]
fn zero_unless_positive_lanes(v: Lanes) -> Lanes {
    v.fast_max(Lanes::ZERO)
}

/// Per lane `v` where v > 0, else +0 (NaN and −0 included).
#[cfg(not(target_feature = "sse"))]
#[inline(always)]
fn zero_unless_positive_lanes(v: Lanes) -> Lanes {
    v.simd_gt(Lanes::ZERO) & v
}

/// Per lane max(run, 1e-12), NaN kept as NaN. With SSE one `maxps`, which returns its second
/// operand when either is NaN. (Runs are never negative here: horizontal ranges and η·cos θ are
/// ≥ 0 for |θ| ≤ π/2; a negative run would be clamped too.)
#[cfg(target_feature = "sse")]
#[inline(always)]
fn clamp_run_lanes(run: Lanes) -> Lanes {
    Lanes::splat(1e-12).fast_max(run)
}

/// Per lane max(run, 1e-12) where run ≥ 0, NaN kept as NaN (other backends' `fast_max` may not
/// return its second operand for NaN).
#[cfg(not(target_feature = "sse"))]
#[inline(always)]
fn clamp_run_lanes(run: Lanes) -> Lanes {
    run.simd_ge(Lanes::ZERO).select(run.fast_max(Lanes::splat(1e-12)), run)
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

/// Which obstacle runs along a row stage 4 clears as noise: a run is cleared when it has fewer
/// than `min_px` pixels, or when `min_arc_m` is positive and its arc length (Σρ)·2π/A is below
/// it. The authors count pixels; the arc rule is spomp's former rule, kept for the simulation
/// profile (see [`crate::TerrainParams::min_obstacle_run_m`]).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct RunFilter {
    /// Shortest kept run, pixels (0 or 1 keeps every run by count).
    pub min_px: u32,
    /// Shortest kept run, metres of arc (0 disables the arc rule).
    pub min_arc_m: f32,
}

impl RunFilter {
    /// True when the filter can clear nothing.
    fn keeps_all(self) -> bool {
        self.min_px <= 1 && self.min_arc_m <= 0.0
    }

    /// True when the run of `len_px` pixels at `ranges` is cleared.
    #[inline]
    fn clears<'a>(self, len_px: usize, ranges: impl Iterator<Item = &'a f32>, step: f32) -> bool {
        len_px < self.min_px as usize
            || (self.min_arc_m > 0.0 && run_length(ranges, step, self.min_arc_m) < self.min_arc_m)
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

/// Stage 4: obstacle = gradient above `slope_threshold` (pixels with a return only); then,
/// along each row with wrap in azimuth, the runs `filter` names are cleared as noise. A row
/// that is obstacle all round is one closed ring and is kept.
#[inline(always)]
pub fn obstacles(
    gradient: &[f32],
    ranges: &[f32],
    cols: usize,
    slope_threshold: f32,
    filter: RunFilter,
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
        if !any || filter.keeps_all() {
            continue;
        }
        let Some(first_free) = obs.iter().position(|&o| !o) else { continue };
        let last_free = obs.iter().rposition(|&o| !o).unwrap_or(first_free);
        // The run across the seam: (last_free, cols) then [0, first_free).
        let seam = (cols - 1 - last_free) + first_free;
        if seam > 0 && filter.clears(seam, rho[last_free + 1..].iter().chain(&rho[..first_free]), step) {
            obs[last_free + 1..].iter_mut().for_each(|o| *o = false);
            obs[..first_free].iter_mut().for_each(|o| *o = false);
        }
        let mut c = first_free;
        while c < last_free {
            let Some(offset) = first_equal(&obs[c..last_free], true) else { break };
            let start = c + offset;
            let end = first_equal(&obs[start..last_free], false).map_or(last_free, |o| start + o);
            if filter.clears(end - start, rho[start..end].iter(), step) {
                obs[start..end].iter_mut().for_each(|o| *o = false);
            }
            c = end;
        }
    }
}

/// Scratch space for [`distance_transform`]: one value per column and the row pass state.
#[derive(Clone, Debug, Default)]
pub struct DistanceScratch {
    nearest_obstacle: Vec<f32>,
    block: RowBlockScratch,
}

/// Rows handled together by [`row_passes_block`], one per SIMD lane.
pub(crate) const BLOCK_ROWS: usize = std::mem::size_of::<BlockLanes>() / 4;

/// A block of [`BLOCK_ROWS`] rows transposed to column-major, one row per lane, for
/// [`row_passes_block`].
#[derive(Clone, Debug, Default)]
pub(crate) struct RowBlockScratch {
    /// D_a per column.
    own: Vec<BlockLanes>,
    /// s = (2π/A)·ρ per column.
    arc: Vec<BlockLanes>,
    /// Some row of the block has D_a < D_max in this column.
    below: Vec<bool>,
    /// D per column.
    out: Vec<BlockLanes>,
}

/// Stage 5: Algorithm 1, the distance-transform approximation, capped at `max_distance_m`.
///
/// Column pass, top row to bottom (far to near on the ground): `along_column` D_a gets |ρ − D_obs|
/// with D_obs the smallest range of an obstacle met so far in the column (0 on obstacles).
/// Then two passes along each row, forwards and backwards, propagate D_a(p_last) +
/// |p_a − p_last|·s(p_last), where p_last is the last column whose own D_a beat the propagated
/// value; the passes wrap around in azimuth: after a pass reaches the end of a row it continues
/// from the other end for as long as the propagated distance stays below `max_distance_m`.
#[inline(always)]
pub fn distance_transform(
    ranges: &[f32],
    obstacle: &[bool],
    cols: usize,
    max_distance_m: f32,
    scratch: &mut DistanceScratch,
    along_column: &mut [f32],
    distance: &mut [f32],
) {
    let simd = pulp::Scalar::new();
    distance_transform_with(ranges, obstacle, cols, max_distance_m, scratch, along_column, distance, simd);
}

/// [`distance_transform`] compiled for the instruction set of `simd` (see [`column_pass_row`]
/// and [`row_passes_block_native`]).
#[allow(clippy::too_many_arguments)]
#[inline(always)]
pub(crate) fn distance_transform_with<S: pulp::Simd>(
    ranges: &[f32],
    obstacle: &[bool],
    cols: usize,
    max_distance_m: f32,
    scratch: &mut DistanceScratch,
    along_column: &mut [f32],
    distance: &mut [f32],
    simd: S,
) {
    if cols == 0 {
        return;
    }
    let step = std::f32::consts::TAU / cols as f32;
    let d_max = max_distance_m;
    let (nearest, block) = scratch.reset(cols);
    let rows = ranges.chunks_exact(cols).zip(obstacle.chunks_exact(cols));
    for ((rho, obs), d_a) in rows.zip(along_column.chunks_exact_mut(cols)) {
        column_pass_row(rho, obs, nearest, d_max, d_a, !S::IS_SCALAR);
    }
    let block_rows = native_block_rows::<S>();
    let width = block_rows * cols;
    let blocks = ranges.chunks_exact(width).zip(along_column.chunks_exact(width));
    let full_rows = blocks.len() * block_rows;
    for ((rho, d_a), d) in blocks.zip(distance.chunks_exact_mut(width)) {
        row_passes_block_native(simd, rho, d_a, d, cols, step, d_max, block);
    }
    let rows = ranges.chunks_exact(cols).zip(along_column.chunks_exact(cols)).skip(full_rows);
    for ((rho, d_a), d) in rows.zip(distance.chunks_exact_mut(cols).skip(full_rows)) {
        row_passes(rho, d_a, d, step, d_max);
    }
}

/// The column pass of Algorithm 1 for one row: `nearest` holds, per column, the smallest range
/// of an obstacle in the rows above (∞ before any). `wide_registers`: the caller is compiled for
/// AVX2 or AVX-512, where plain per-column code vectorises best ([`column_pass_row_columns`]);
/// on the baseline explicit [`LANES`]-wide vectors were measured faster
/// ([`column_pass_row_lanes`]). The same bits either way.
#[inline(always)]
pub(crate) fn column_pass_row(
    rho: &[f32],
    obs: &[bool],
    nearest: &mut [f32],
    d_max: f32,
    d_a: &mut [f32],
    wide_registers: bool,
) {
    if wide_registers {
        column_pass_row_columns(rho, obs, nearest, d_max, d_a);
    } else {
        column_pass_row_lanes(rho, obs, nearest, d_max, d_a);
    }
}

/// [`column_pass_row`] as plain per-column code.
#[inline(always)]
fn column_pass_row_columns(rho: &[f32], obs: &[bool], nearest: &mut [f32], d_max: f32, d_a: &mut [f32]) {
    let n = rho.len().min(obs.len()).min(d_a.len()).min(nearest.len());
    let (rho, obs, nearest, d_a) = (&rho[..n], &obs[..n], &mut nearest[..n], &mut d_a[..n]);
    // Plain per-column code with every store unconditional (a conditional store of `nearest`
    // becomes a scalarised masked store): the compiler vectorises it at the width the caller is
    // compiled for. No NaN reaches the `min_ps`s: ranges are finite and `nearest` is finite or
    // ∞, so they are `min`.
    let columns = rho.iter().zip(obs).zip(nearest.iter_mut().zip(d_a.iter_mut()));
    for ((&range, &is_obstacle), (nearest, d_a)) in columns {
        let near = *nearest;
        *nearest = if is_obstacle { min_ps(range, near) } else { near };
        let free = if range > 0.0 { min_ps((range - near).abs(), d_max) } else { d_max };
        *d_a = if is_obstacle { 0.0 } else { free };
    }
}

/// [`column_pass_row`] with explicit [`LANES`]-wide vectors.
#[inline(always)]
fn column_pass_row_lanes(rho: &[f32], obs: &[bool], nearest: &mut [f32], d_max: f32, d_a: &mut [f32]) {
    let n = rho.len().min(obs.len()).min(d_a.len()).min(nearest.len());
    let (rho, obs, nearest, d_a) = (&rho[..n], &obs[..n], &mut nearest[..n], &mut d_a[..n]);
    let vectorised = n / LANES * LANES;
    // No NaN reaches the `fast_min`s: ranges are finite and `nearest` is finite or ∞.
    let d_max_lanes = Lanes::splat(d_max);
    let chunks = rho[..vectorised]
        .chunks_exact(LANES)
        .zip(obs[..vectorised].chunks_exact(LANES))
        .zip(nearest[..vectorised].chunks_exact_mut(LANES).zip(d_a[..vectorised].chunks_exact_mut(LANES)));
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
#[inline(always)]
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
/// nothing below D_max and leaves the same state at the next column with D_a < D_max. A lane
/// whose propagated value has reached D_max stays there, writes nothing and restarts at the next
/// column where its own D_a < D_max exactly as the scalar pass does, so while every lane is
/// there the block may jump to the next column where some lane has D_a < D_max, or not: the
/// jump is only an optimisation, tried at columns where no lane has D_a < D_max.
#[inline(always)]
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
    let d_max_lanes = Lanes::splat(d_max);
    if first_lanes(d_a, |v| v.simd_lt(d_max_lanes), |v| v < d_max).is_none() {
        d.iter_mut().for_each(|v| *v = d_max);
        return;
    }
    let RowBlockScratch { own, arc, below, out } = scratch;
    own.resize(cols, BlockLanes::ZERO);
    arc.resize(cols, BlockLanes::ZERO);
    below.resize(cols, false);
    out.resize(cols, BlockLanes::ZERO);
    let (own, arc, below, out) = (&mut own[..cols], &mut arc[..cols], &mut below[..cols], &mut out[..cols]);
    transpose_to_lanes(d_a, cols, QUADS_PER_BLOCK, bytemuck::cast_slice_mut(own));
    transpose_to_lanes(rho, cols, QUADS_PER_BLOCK, bytemuck::cast_slice_mut(arc));
    let (step_lanes, d_max_lanes) = (BlockLanes::splat(step), BlockLanes::splat(d_max));
    // One sweep: s = (2π/A)·ρ, whether any row is below D_max, D initialised to D_max.
    for (((a, o), b), d) in arc.iter_mut().zip(own.iter()).zip(below.iter_mut()).zip(out.iter_mut()) {
        *a *= step_lanes;
        *b = o.simd_lt(d_max_lanes).to_bitmask() != 0;
        *d = d_max_lanes;
    }
    block_passes(WideOps, own, arc, below, out, d_max);
    transpose_from_lanes(bytemuck::cast_slice(out), cols, QUADS_PER_BLOCK, d);
}

/// Row l of the `4·quads × cols` block `rows` becomes lane l of column c's `4·quads` values in
/// `lanes` (column-major: `lanes[c·4·quads + l]`, `cols · quads` 4-lane vectors), 4 × 4 tiles at a
/// time.
#[inline(always)]
fn transpose_to_lanes(rows: &[f32], cols: usize, quads: usize, lanes: &mut [f32x4]) {
    let tiled = cols / 4 * 4;
    // Strips of [`TRANSPOSE_STRIP`] columns, each group of 4 rows in turn: a strip's lane vectors
    // stay in the first-level cache while the groups fill their quads.
    for strip in (0..tiled).step_by(TRANSPOSE_STRIP) {
        let end = (strip + TRANSPOSE_STRIP).min(tiled);
        let strip_lanes = &mut lanes[strip * quads..end * quads];
        for group in 0..quads {
            let row = |i: usize| &rows[(4 * group + i) * cols + strip..(4 * group + i) * cols + end];
            let (r0, r1, r2, r3) = (row(0), row(1), row(2), row(3));
            let sources = r0.chunks_exact(4).zip(r1.chunks_exact(4)).zip(r2.chunks_exact(4).zip(r3.chunks_exact(4)));
            // Four columns: four lane vectors, of which this group fills one quad each.
            for (out, ((a, b), (c, d))) in strip_lanes.chunks_exact_mut(4 * quads).zip(sources) {
                // One unaligned 16-byte load per row.
                let load = |s: &[f32]| bytemuck::pod_read_unaligned::<f32x4>(bytemuck::cast_slice(s));
                let tile = f32x4::transpose([load(a), load(b), load(c), load(d)]);
                for (j, column) in tile.into_iter().enumerate() {
                    out[j * quads + group] = column;
                }
            }
        }
    }
    let flat: &mut [f32] = bytemuck::cast_slice_mut(lanes);
    for (lane, row) in rows.chunks_exact(cols).take(4 * quads).enumerate() {
        for c in tiled..cols {
            flat[c * 4 * quads + lane] = row[c];
        }
    }
}

/// Columns per strip of [`transpose_to_lanes`] and [`transpose_from_lanes`] (a multiple of 4):
/// a 16-row strip's lane vectors are 16 KiB. (Measured on the street panorama with 16-row
/// blocks: whole rows at once, whose lane vectors leave the first-level cache between groups,
/// 11 % slower over the distance transform; strips of 128–512 columns alike; 32 slower.)
const TRANSPOSE_STRIP: usize = 256;

/// The inverse of [`transpose_to_lanes`].
#[inline(always)]
fn transpose_from_lanes(lanes: &[f32x4], cols: usize, quads: usize, rows: &mut [f32]) {
    let tiled = cols / 4 * 4;
    // Strips as [`transpose_to_lanes`].
    for strip in (0..tiled).step_by(TRANSPOSE_STRIP) {
        let end = (strip + TRANSPOSE_STRIP).min(tiled);
        let strip_lanes = &lanes[strip * quads..end * quads];
        for group in 0..quads {
            let block = &mut rows[4 * group * cols..(4 * group + 4) * cols];
            let (r0, rest) = block.split_at_mut(cols);
            let (r1, rest) = rest.split_at_mut(cols);
            let (r2, r3) = rest.split_at_mut(cols);
            let targets = r0[strip..end]
                .chunks_exact_mut(4)
                .zip(r1[strip..end].chunks_exact_mut(4))
                .zip(r2[strip..end].chunks_exact_mut(4).zip(r3[strip..end].chunks_exact_mut(4)));
            for (lanes, ((a, b), (c, d))) in strip_lanes.chunks_exact(4 * quads).zip(targets) {
                let column = |j: usize| lanes[j * quads + group];
                let [t0, t1, t2, t3] = f32x4::transpose([column(0), column(1), column(2), column(3)]);
                a.copy_from_slice(&t0.to_array());
                b.copy_from_slice(&t1.to_array());
                c.copy_from_slice(&t2.to_array());
                d.copy_from_slice(&t3.to_array());
            }
        }
    }
    let flat: &[f32] = bytemuck::cast_slice(lanes);
    for (lane, row) in rows.chunks_exact_mut(cols).take(4 * quads).enumerate() {
        for c in tiled..cols {
            row[c] = flat[c * 4 * quads + lane];
        }
    }
}

/// One direction of [`row_passes_block`] over transposed columns: the pass's position and, per
/// lane, k − p_last (an integer below 2²⁴, exact in f32), D_a(p_last) and s(p_last), so that
/// D_a(p_last) + (k − p_last)·s(p_last) is computed exactly as the scalar pass does.
///
/// Each step depends on the previous one through a compare and a select (the pass is bound by
/// that latency), so [`block_passes`] runs the two directions interleaved, step for step: their
/// writes are combined with `min`, whose result does not depend on the order.
struct BlockPass<O: PassOps, const FORWARD: bool> {
    ops: O,
    /// Unwrapped position in [0, 2·cols): the second lap is the wrap-around continuation.
    k: usize,
    offset: O::V,
    anchor_value: O::V,
    arc_last: O::V,
    /// Wrap-around lap: lanes whose propagated value is still below D_max.
    alive: O::M,
}

/// The vector operations of [`BlockPass`], one row per lane: `wide`'s portable 8-lane vectors
/// ([`WideOps`]) and the native vectors of a `pulp` instruction set ([`NativeOps`]) run the same
/// steps, lane for lane.
trait PassOps: Copy {
    /// A vector of one value per row.
    type V: Copy;
    /// A mask of one flag per row.
    type M: Copy;
    fn splat(self, v: f32) -> Self::V;
    fn add(self, a: Self::V, b: Self::V) -> Self::V;
    fn mul(self, a: Self::V, b: Self::V) -> Self::V;
    /// The lane-wise minimum (never meets a NaN here).
    fn min(self, a: Self::V, b: Self::V) -> Self::V;
    fn less(self, a: Self::V, b: Self::V) -> Self::M;
    fn greater(self, a: Self::V, b: Self::V) -> Self::M;
    /// `a` where `mask` is set, else `b`.
    fn select(self, mask: Self::M, a: Self::V, b: Self::V) -> Self::V;
    fn and(self, a: Self::M, b: Self::M) -> Self::M;
    fn any(self, mask: Self::M) -> bool;
    /// Every lane set.
    fn all_set(self) -> Self::M;
}

/// [`PassOps`] on [`BlockLanes`] (the SSE2 baseline's blocks).
#[derive(Clone, Copy)]
struct WideOps;

impl PassOps for WideOps {
    type V = BlockLanes;
    type M = BlockLanes;
    #[inline(always)]
    fn splat(self, v: f32) -> BlockLanes {
        BlockLanes::splat(v)
    }
    #[inline(always)]
    fn add(self, a: BlockLanes, b: BlockLanes) -> BlockLanes {
        a + b
    }
    #[inline(always)]
    fn mul(self, a: BlockLanes, b: BlockLanes) -> BlockLanes {
        a * b
    }
    #[inline(always)]
    fn min(self, a: BlockLanes, b: BlockLanes) -> BlockLanes {
        a.fast_min(b)
    }
    #[inline(always)]
    fn less(self, a: BlockLanes, b: BlockLanes) -> BlockLanes {
        a.simd_lt(b)
    }
    #[inline(always)]
    fn greater(self, a: BlockLanes, b: BlockLanes) -> BlockLanes {
        a.simd_gt(b)
    }
    #[inline(always)]
    fn select(self, mask: BlockLanes, a: BlockLanes, b: BlockLanes) -> BlockLanes {
        mask.select(a, b)
    }
    #[inline(always)]
    fn and(self, a: BlockLanes, b: BlockLanes) -> BlockLanes {
        a & b
    }
    #[inline(always)]
    fn any(self, mask: BlockLanes) -> bool {
        mask.any()
    }
    #[inline(always)]
    fn all_set(self) -> BlockLanes {
        BlockLanes::splat(f32::from_bits(u32::MAX))
    }
}

/// [`PassOps`] on the native vectors of `pulp`'s instruction set `S`.
#[derive(Clone, Copy)]
struct NativeOps<S>(S);

impl<S: pulp::Simd> PassOps for NativeOps<S> {
    type V = S::f32s;
    type M = S::m32s;
    #[inline(always)]
    fn splat(self, v: f32) -> S::f32s {
        self.0.splat_f32s(v)
    }
    #[inline(always)]
    fn add(self, a: S::f32s, b: S::f32s) -> S::f32s {
        self.0.add_f32s(a, b)
    }
    #[inline(always)]
    fn mul(self, a: S::f32s, b: S::f32s) -> S::f32s {
        self.0.mul_f32s(a, b)
    }
    #[inline(always)]
    fn min(self, a: S::f32s, b: S::f32s) -> S::f32s {
        self.0.min_f32s(a, b)
    }
    #[inline(always)]
    fn less(self, a: S::f32s, b: S::f32s) -> S::m32s {
        self.0.less_than_f32s(a, b)
    }
    #[inline(always)]
    fn greater(self, a: S::f32s, b: S::f32s) -> S::m32s {
        self.0.greater_than_f32s(a, b)
    }
    #[inline(always)]
    fn select(self, mask: S::m32s, a: S::f32s, b: S::f32s) -> S::f32s {
        self.0.select_f32s(mask, a, b)
    }
    #[inline(always)]
    fn and(self, a: S::m32s, b: S::m32s) -> S::m32s {
        self.0.and_m32s(a, b)
    }
    #[inline(always)]
    fn any(self, mask: S::m32s) -> bool {
        self.0.first_true_m32s(mask) < S::F32_LANES
    }
    #[inline(always)]
    fn all_set(self) -> S::m32s {
        let zero = self.0.splat_f32s(0.0);
        self.0.equal_f32s(zero, zero)
    }
}

impl<O: PassOps, const FORWARD: bool> BlockPass<O, FORWARD> {
    #[inline(always)]
    fn new(ops: O) -> Self {
        BlockPass {
            ops,
            k: 0,
            offset: ops.splat(0.0),
            anchor_value: ops.splat(f32::INFINITY),
            arc_last: ops.splat(0.0),
            alive: ops.all_set(),
        }
    }

    /// The column at unwrapped position `k`.
    #[inline(always)]
    fn col(k: usize, cols: usize) -> usize {
        let k = if k >= cols { k - cols } else { k };
        if FORWARD { k } else { cols - 1 - k }
    }

    /// One column of the first lap (`self.k < cols`, slices of length `cols`); after the lap's
    /// last column `self.k` is `cols`.
    #[inline(always)]
    fn first_lap_step(&mut self, own: &[O::V], arc: &[O::V], below: &[bool], out: &mut [O::V], d_max: O::V) {
        let ops = self.ops;
        let cols = out.len();
        // The first lap needs no wrap: the caller guarantees k < cols.
        let c = if FORWARD { self.k } else { cols - 1 - self.k };
        self.offset = ops.add(self.offset, ops.splat(1.0));
        let candidate = ops.add(self.anchor_value, ops.mul(self.offset, self.arc_last));
        // The skip is an optimisation only (see [`row_passes_block`]): it is tried only at columns
        // where no lane has D_a < D_max, which saves the test at all the others.
        if !below[c] && !ops.any(ops.less(candidate, d_max)) {
            // Every lane has reached D_max: until some lane has D_a < D_max nothing is written and
            // each lane restarts at that column (the propagated values only grow meanwhile).
            let k = self.k;
            let next = if FORWARD {
                first_where(&below[k..], |b| b).map(|o| k + o)
            } else {
                last_where(&below[..cols - k], |b| b).map(|i| cols - 1 - i)
            };
            match next {
                // The next step's candidate is ∞ (∞ + offset·0): every lane restarts there.
                Some(next) => {
                    self.k = next;
                    self.anchor_value = ops.splat(f32::INFINITY);
                    self.arc_last = ops.splat(0.0);
                    self.offset = ops.splat(0.0);
                }
                None => self.k = cols,
            }
            return;
        }
        let own_c = own[c];
        // Beaten by the column's own D_a. Where the candidate has reached D_max the scalar pass
        // skips to the next column with D_a < D_max and restarts there; here the candidate only
        // grows until that column beats it, and no value written in between is below D_max.
        let restart = ops.greater(candidate, own_c);
        // The value is own where restarting, else the candidate: min(candidate, own).
        out[c] = ops.min(out[c], ops.min(candidate, own_c));
        self.restart_where(restart, own_c, arc[c]);
        self.k += 1;
    }

    /// One column of the wrap-around lap (`cols ≤ self.k < 2·cols`): a lane stops for good once
    /// its propagated value reaches D_max; when none is left, or after the lap, `self.k` is
    /// `2·cols`.
    #[inline(always)]
    fn wrap_step(&mut self, own: &[O::V], arc: &[O::V], out: &mut [O::V], d_max: O::V) {
        let ops = self.ops;
        let cols = out.len();
        let c = Self::col(self.k, cols);
        self.offset = ops.add(self.offset, ops.splat(1.0));
        let candidate = ops.add(self.anchor_value, ops.mul(self.offset, self.arc_last));
        self.alive = ops.and(self.alive, ops.less(candidate, d_max));
        if !ops.any(self.alive) {
            self.k = 2 * cols;
            return;
        }
        let own_c = own[c];
        let restart = ops.greater(candidate, own_c);
        let value = ops.select(self.alive, ops.min(candidate, own_c), ops.splat(f32::INFINITY));
        out[c] = ops.min(out[c], value);
        self.restart_where(restart, own_c, arc[c]);
        self.k += 1;
    }

    /// Lanes of `restart` start propagating afresh from this column (own D_a, own arc step).
    #[inline(always)]
    fn restart_where(&mut self, restart: O::M, own_c: O::V, arc_c: O::V) {
        let ops = self.ops;
        self.offset = ops.select(restart, ops.splat(0.0), self.offset);
        self.anchor_value = ops.select(restart, own_c, self.anchor_value);
        self.arc_last = ops.select(restart, arc_c, self.arc_last);
    }
}

/// Both directions of [`row_passes_block`] over transposed columns (slices of equal length;
/// `below[c]`: some lane of column c has D_a < D_max), interleaved step for step.
#[inline(always)]
fn block_passes<O: PassOps>(ops: O, own: &[O::V], arc: &[O::V], below: &[bool], out: &mut [O::V], d_max: f32) {
    let cols = out.len().min(own.len()).min(arc.len()).min(below.len());
    let (own, arc, below, out) = (&own[..cols], &arc[..cols], &below[..cols], &mut out[..cols]);
    let d_max = ops.splat(d_max);
    let (mut forward, mut backward) = (BlockPass::<O, true>::new(ops), BlockPass::<O, false>::new(ops));
    while forward.k < cols && backward.k < cols {
        forward.first_lap_step(own, arc, below, out, d_max);
        backward.first_lap_step(own, arc, below, out, d_max);
    }
    while forward.k < cols {
        forward.first_lap_step(own, arc, below, out, d_max);
    }
    while backward.k < cols {
        backward.first_lap_step(own, arc, below, out, d_max);
    }
    while forward.k < 2 * cols && backward.k < 2 * cols {
        forward.wrap_step(own, arc, out, d_max);
        backward.wrap_step(own, arc, out, d_max);
    }
    while forward.k < 2 * cols {
        forward.wrap_step(own, arc, out, d_max);
    }
    while backward.k < 2 * cols {
        backward.wrap_step(own, arc, out, d_max);
    }
}

/// Rows per block of [`row_passes_block_native`] for the instruction set `S`: one per lane of its
/// native vector (AVX2: 8, AVX-512: 16); [`BLOCK_ROWS`] where that is not a multiple of 8 (the
/// baseline, whose blocks [`row_passes_block`] runs).
#[inline(always)]
pub(crate) fn native_block_rows<S: pulp::Simd>() -> usize {
    if S::F32_LANES.is_multiple_of(BLOCK_ROWS) { S::F32_LANES } else { BLOCK_ROWS }
}

/// [`row_passes_block`] for [`native_block_rows`] consecutive rows with the native vectors of
/// `simd`, one row per lane: bit for bit the same result (each lane takes the same steps with the
/// same operations: additions, multiplications, and `min`s that meet no NaN). Under AVX-512 a
/// block is 16 rows in one register, where [`BlockLanes`] is two 4-lane halves: half the steps,
/// each a quarter of the instructions. Without a native width that is a multiple of 8 it is
/// [`row_passes_block`].
#[allow(clippy::too_many_arguments)]
#[inline(always)]
pub(crate) fn row_passes_block_native<S: pulp::Simd>(
    simd: S,
    rho: &[f32],
    d_a: &[f32],
    d: &mut [f32],
    cols: usize,
    step: f32,
    d_max: f32,
    scratch: &mut RowBlockScratch,
) {
    let rows = native_block_rows::<S>();
    if rows != S::F32_LANES {
        row_passes_block(rho, d_a, d, cols, step, d_max, scratch);
        return;
    }
    let width = rows * cols;
    if cols == 0 || rho.len() < width || d_a.len() < width || d.len() < width {
        return;
    }
    let (rho, d_a, d) = (&rho[..width], &d_a[..width], &mut d[..width]);
    // Nothing below D_max in any of the rows: D = D_max throughout.
    let d_max_lanes = Lanes::splat(d_max);
    if first_lanes(d_a, |v| v.simd_lt(d_max_lanes), |v| v < d_max).is_none() {
        d.iter_mut().for_each(|v| *v = d_max);
        return;
    }
    // Storage in [`BlockLanes`] (aligned), `rows / BLOCK_ROWS` of them per column.
    let storage = cols * (rows / BLOCK_ROWS);
    let RowBlockScratch { own, arc, below, out } = scratch;
    own.resize(storage, BlockLanes::ZERO);
    arc.resize(storage, BlockLanes::ZERO);
    below.resize(cols, false);
    out.resize(storage, BlockLanes::ZERO);
    let (own_lanes, arc_lanes, below, out_lanes) =
        (&mut own[..storage], &mut arc[..storage], &mut below[..cols], &mut out[..storage]);
    transpose_to_lanes(d_a, cols, rows / 4, bytemuck::cast_slice_mut(own_lanes));
    transpose_to_lanes(rho, cols, rows / 4, bytemuck::cast_slice_mut(arc_lanes));
    {
        let (own, _) = S::as_simd_f32s(bytemuck::cast_slice(own_lanes));
        let (arc, _) = S::as_mut_simd_f32s(bytemuck::cast_slice_mut(arc_lanes));
        let (out, _) = S::as_mut_simd_f32s(bytemuck::cast_slice_mut(out_lanes));
        let n = cols.min(own.len()).min(arc.len()).min(out.len());
        let (own, arc, below, out) = (&own[..n], &mut arc[..n], &mut below[..n], &mut out[..n]);
        let (step_lanes, d_max_lanes) = (simd.splat_f32s(step), simd.splat_f32s(d_max));
        // One sweep: s = (2π/A)·ρ, whether any row is below D_max, D initialised to D_max.
        for (((a, &o), b), d) in arc.iter_mut().zip(own.iter()).zip(below.iter_mut()).zip(out.iter_mut()) {
            *a = simd.mul_f32s(*a, step_lanes);
            *b = simd.first_true_m32s(simd.less_than_f32s(o, d_max_lanes)) < rows;
            *d = d_max_lanes;
        }
        block_passes(NativeOps(simd), own, arc, below, out, d_max);
    }
    transpose_from_lanes(bytemuck::cast_slice(out_lanes), cols, rows / 4, d);
}

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
#[inline(always)]
pub fn traversable(ranges: &[f32], distance: &[f32], inflation_m: f32, out: &mut [bool]) {
    for ((o, &rho), &d) in out.iter_mut().zip(ranges).zip(distance) {
        // `&` rather than `&&`: no short-circuit branch, so the loop vectorises.
        *o = (rho > 0.0) & (d >= inflation_m);
    }
}

/// Per-column state of the reachability walk, eight columns per vector (the last vector
/// padded with columns that are not walking), and the vectors still walking.
#[derive(Clone, Debug, Default)]
pub struct ReachScratch {
    state: Vec<ReachLanes>,
    /// Indices of the vectors with a column still walking.
    walking: Vec<u32>,
}

/// The walk's state for [`LANES`] columns.
#[derive(Clone, Copy, Debug)]
struct ReachLanes {
    /// Still walking (mask).
    active: Lanes,
    /// Horizontal range of the last safe pixel (−1 before any).
    last_r: Lanes,
    /// An obstacle ended the walk (mask).
    blocked: Lanes,
    /// Largest horizontal range of the safe pixels.
    range: Lanes,
    /// Last safe row (`rows` before any).
    last_row: Lanes,
}

impl ReachLanes {
    /// One row: `horizontal` = r, `has_return` and `trav` masks.
    #[inline(always)]
    fn step(&mut self, horizontal: Lanes, has_return: Lanes, trav: Lanes, gap: Lanes, row_index: Lanes) {
        let live = self.active & has_return;
        let jump = self.last_r.simd_ge(Lanes::ZERO) & (horizontal - self.last_r).abs().simd_gt(gap);
        let accept = live & !jump & trav;
        // A non-traversable pixel ends the walk as a known obstacle, also beyond a gap (the
        // authors' order); a jump onto traversable ground ends it as unknown.
        self.blocked |= live & !trav;
        self.active &= !live | accept;
        self.last_r = accept.select(horizontal, self.last_r);
        // Accepted pixels have a return: `horizontal` is a positive number there.
        self.range = accept.select(self.range.fast_max(horizontal), self.range);
        self.last_row = accept.select(row_index, self.last_row);
    }
}

/// [`LANES`] values of `values` from `start`, `pad` past the end.
#[inline(always)]
fn load_lanes_or<T: Copy>(values: &[T], start: usize, pad: T, map: impl Fn(T) -> f32) -> Lanes {
    match values.get(start..start + LANES) {
        Some(chunk) => Lanes::new(std::array::from_fn(|i| map(chunk[i]))),
        None => Lanes::new(std::array::from_fn(|i| map(values.get(start + i).copied().unwrap_or(pad)))),
    }
}

/// Stage 6: the reachability scan S(φ). Each column is walked up from the bottom row (nearest
/// ground) over pixels with a return. The walk stops at the first non-traversable pixel (a known
/// obstacle ends the safe stretch, even when its range lies more than `gap_m` beyond the last
/// safe pixel) or at a traversable pixel whose horizontal range jumps by more than `gap_m` from
/// the last safe pixel's (the unknown begins). `range_m` gets the largest horizontal range of the
/// safe pixels walked, at least `min_range_m` (the blind zone around the robot counts as safe),
/// `obstacle` whether an obstacle ended the walk, and `last_row` the last safe row (`rows` if
/// none).
///
/// All columns advance together one row at a time, as SIMD lanes with masks for the per-column
/// decisions; a vector of columns drops out of the walk once none of its columns is walking.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
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
    let (vectors, full) = (cols.div_ceil(LANES), cols / LANES);
    let ReachScratch { state, walking } = scratch;
    let true_mask = f32::from_bits(u32::MAX);
    state.clear();
    state.extend((0..vectors).map(|v| ReachLanes {
        // Padding columns are not walking.
        active: Lanes::new(std::array::from_fn(|i| if v * LANES + i < cols { true_mask } else { 0.0 })),
        last_r: Lanes::splat(-1.0),
        blocked: Lanes::ZERO,
        range: Lanes::ZERO,
        last_row: Lanes::splat(rows as f32),
    }));
    walking.clear();
    walking.extend((0..vectors).map(|v| v as u32));
    let (gap, zero) = (Lanes::splat(gap_m), Lanes::ZERO);
    let mask_of = |t: bool| if t { true_mask } else { 0.0 };
    for row in (0..rows).rev() {
        if walking.is_empty() {
            break;
        }
        let span = row * width..row * width + cols;
        let (r_row, rho_row, trav_row) = (&r[span.clone()], &ranges[span.clone()], &traversable[span]);
        let row_index = Lanes::splat(row as f32);
        // Walk the vectors on the list, keeping those still walking (in order).
        let mut kept = 0;
        for i in 0..walking.len() {
            let v = walking[i] as usize;
            let Some(lanes) = state.get_mut(v) else { continue };
            let start = v * LANES;
            if v < full {
                let (r, rho) = (lanes_of(&r_row[start..start + LANES]), lanes_of(&rho_row[start..start + LANES]));
                let trav = &trav_row[start..start + LANES];
                let trav = Lanes::new(std::array::from_fn(|i| trav[i] as u8 as f32)).simd_gt(zero);
                lanes.step(r, rho.simd_gt(zero), trav, gap, row_index);
            } else {
                // Padding columns have no return (ρ = 0): never live.
                let (r, rho) = (load_lanes_or(r_row, start, 0.0, |x| x), load_lanes_or(rho_row, start, 0.0, |x| x));
                let trav = load_lanes_or(trav_row, start, false, mask_of);
                lanes.step(r, rho.simd_gt(zero), trav, gap, row_index);
            }
            if lanes.active.any() {
                walking[kept] = v as u32;
                kept += 1;
            }
        }
        walking.truncate(kept);
    }
    for (v, lanes) in state.iter().enumerate() {
        let (range, blocked, last) = (lanes.range.to_array(), lanes.blocked.to_array(), lanes.last_row.to_array());
        for (i, c) in (v * LANES..cols.min(v * LANES + LANES)).enumerate() {
            // The floor also applies to a column that accepted nothing (range 0).
            range_m[c] = range[i].max(min_range_m);
            obstacle[c] = blocked[i].to_bits() != 0;
            // An integer-valued row index below 2²³ (or `rows`): exact.
            last_row[c] = small_to_u32(last[i]);
        }
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
                let n = MAX_NATIVE_ROWS * cols;
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
                let n = BLOCK_ROWS * cols;
                let mut got = vec![-1.0; n];
                row_passes_block(&rho[..n], &d_a[..n], &mut got, cols, step, d_max, &mut block);
                assert_eq!(bits(&got), bits(&expected[..n]), "cols {cols}");
                check_native_blocks(&rho, &d_a, &expected, cols, d_max, &mut block);
            }
        }
    }

    /// [`row_passes_block`] against [`row_passes`] on blocks like a real panorama's: rows mostly
    /// at D_max with a few obstacles or close columns (also at the seam), whole rows at D_max,
    /// small ranges whose propagation wraps around the row, and pixels without a return: this
    /// exercises the jumps over columns where every lane has reached D_max and the wrap-around
    /// laps of both directions.
    #[test]
    fn row_block_matches_scalar_row_passes_on_sparse_rows() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
        let d_max = 2.0f32;
        let mut block = RowBlockScratch::default();
        let mut jumps = 0;
        for cols in [5usize, 16, 64, 257, 1024] {
            let step = std::f32::consts::TAU / cols as f32;
            for _ in 0..30 {
                let n = MAX_NATIVE_ROWS * cols;
                let mut d_a = vec![d_max; n];
                let mut rho = vec![0.0f32; n];
                for row in 0..MAX_NATIVE_ROWS {
                    let near = rng.random_bool(0.3);
                    for c in 0..cols {
                        rho[row * cols + c] = match rng.random_range(0..10) {
                            0 => 0.0,
                            _ if near => rng.random_range(0.01..0.3),
                            _ => rng.random_range(0.5..20.0),
                        };
                    }
                    if rng.random_bool(0.3) {
                        continue;
                    }
                    for _ in 0..rng.random_range(1..4) {
                        let c = match rng.random_range(0..4) {
                            0 => 0,
                            1 => cols - 1,
                            _ => rng.random_range(0..cols),
                        };
                        d_a[row * cols + c] = if rng.random_bool(0.5) { 0.0 } else { rng.random_range(0.0..d_max) };
                    }
                }
                // Columns where no row is below D_max, next to one where some is: a jump can happen.
                let below: Vec<bool> = (0..cols).map(|c| (0..BLOCK_ROWS).any(|l| d_a[l * cols + c] < d_max)).collect();
                jumps += (1..cols).filter(|&c| below[c - 1] && !below[c]).count();
                let mut expected = vec![0.0; n];
                for ((rho, d_a), d) in
                    rho.chunks_exact(cols).zip(d_a.chunks_exact(cols)).zip(expected.chunks_exact_mut(cols))
                {
                    row_passes(rho, d_a, d, step, d_max);
                }
                let n = BLOCK_ROWS * cols;
                let mut got = vec![-1.0; n];
                row_passes_block(&rho[..n], &d_a[..n], &mut got, cols, step, d_max, &mut block);
                assert_eq!(bits(&got), bits(&expected[..n]), "cols {cols}");
                check_native_blocks(&rho, &d_a, &expected, cols, d_max, &mut block);
            }
        }
        assert!(jumps > 100, "{jumps}");
    }

    /// The most rows a block of [`row_passes_block_native`] has (AVX-512: 16 lanes).
    const MAX_NATIVE_ROWS: usize = 16;

    /// The bits of `values`, to compare results exactly.
    fn bits(values: &[f32]) -> Vec<u32> {
        values.iter().map(|x| x.to_bits()).collect()
    }

    /// Runs [`row_passes_block_native`] compiled for every instruction set this processor has
    /// (the baseline, AVX2, AVX-512) on the first rows of the [`MAX_NATIVE_ROWS`]-row block
    /// `rho`, `d_a`, and checks it bit for bit against `expected`, the rows one at a time.
    fn check_native_blocks(
        rho: &[f32],
        d_a: &[f32],
        expected: &[f32],
        cols: usize,
        d_max: f32,
        block: &mut RowBlockScratch,
    ) {
        struct Run<'a> {
            rho: &'a [f32],
            d_a: &'a [f32],
            expected: &'a [f32],
            cols: usize,
            d_max: f32,
            block: &'a mut RowBlockScratch,
        }
        impl pulp::WithSimd for Run<'_> {
            type Output = ();
            fn with_simd<S: pulp::Simd>(self, simd: S) {
                let Run { rho, d_a, expected, cols, d_max, block } = self;
                let rows = native_block_rows::<S>();
                assert!(rows <= MAX_NATIVE_ROWS && rows.is_multiple_of(BLOCK_ROWS), "{rows}");
                let n = rows * cols;
                let step = std::f32::consts::TAU / cols as f32;
                let mut got = vec![-1.0; n];
                row_passes_block_native(simd, &rho[..n], &d_a[..n], &mut got, cols, step, d_max, block);
                assert_eq!(bits(&got), bits(&expected[..n]), "cols {cols}, {rows} rows");
            }
        }
        let mut arches = vec![pulp::Arch::Scalar];
        #[cfg(any(target_arch = "x86", target_arch = "x86_64"))]
        arches.extend(pulp::x86::V3::try_new().map(pulp::Arch::V3));
        #[cfg(any(target_arch = "x86", target_arch = "x86_64"))]
        arches.extend(pulp::x86::V4::try_new().map(pulp::Arch::V4));
        for arch in arches {
            arch.dispatch(Run { rho, d_a, expected, cols, d_max, block: &mut *block });
        }
    }

    /// The bit-mask searches agree with `position` at every offset and length (chunks and tails).
    #[test]
    fn mask_searches_find_the_first_match() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(9);
        for len in 0usize..80 {
            for _ in 0..20 {
                let values: Vec<f32> = (0..len).map(|_| [0.0, -1.0, 1.0, 2.5][rng.random_range(0..4)]).collect();
                let flags: Vec<bool> = (0..len).map(|_| rng.random_bool(0.1)).collect();
                for start in [0, len / 3, len.saturating_sub(1)] {
                    let (values, flags) = (&values[start..], &flags[start..]);
                    let got = first_lanes(values, |v| v.simd_le(Lanes::ZERO), |v| v <= 0.0);
                    assert_eq!(got, values.iter().position(|&v| v <= 0.0));
                    let got = first_lanes(values, |v| v.simd_gt(Lanes::splat(2.0)), |v| v > 2.0);
                    assert_eq!(got, values.iter().position(|&v| v > 2.0));
                    for target in [true, false] {
                        assert_eq!(first_equal(flags, target), flags.iter().position(|&f| f == target));
                    }
                }
            }
        }
    }

    /// The bit-row searches agree with `position` / `rposition` on rows of every length up to
    /// [`BIT_ROW_COLS`] (whole words and a partial last one), from every kind of start.
    #[test]
    fn bit_row_searches_find_the_next_flag() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(13);
        for len in (1usize..200).chain([511, 512, 513, 1024, BIT_ROW_COLS - 1, BIT_ROW_COLS]) {
            for density in [0.02, 0.5, 0.98] {
                let flags: Vec<bool> = (0..len).map(|_| rng.random_bool(density)).collect();
                let ranges: Vec<f32> =
                    flags.iter().map(|&f| if f { rng.random_range(0.1..50.0) } else { 0.0 }).collect();
                for bits in [BitRow::flags(&flags), BitRow::returns(&ranges)] {
                    assert_eq!(bits.last_set(), flags.iter().rposition(|&f| f), "len {len}");
                    for from in [0, 1, len / 3, len / 2, len.saturating_sub(1)] {
                        let want = flags[from.min(len)..].iter().position(|&f| f).map(|o| from + o);
                        assert_eq!(bits.next(from, true), want, "len {len} from {from}");
                        let want = flags[from.min(len)..].iter().position(|&f| !f).map(|o| from + o);
                        assert_eq!(bits.next(from, false).filter(|&c| c < len), want, "len {len} from {from}");
                    }
                }
            }
        }
    }

    /// The clamps written as the x86 instructions they become keep the semantics the gradient
    /// needs: NaN and ±0 give +0, a NaN run stays NaN.
    #[test]
    fn clamps_keep_their_semantics() {
        let inputs = [f32::NAN, -0.0, 0.0, -1.0, 1e-13, 2.5, f32::INFINITY, f32::NEG_INFINITY];
        for v in inputs {
            let expected = if v > 0.0 { v } else { 0.0 };
            assert_eq!(zero_unless_positive(v).to_bits(), expected.to_bits(), "{v}");
        }
        for run in [f32::NAN, 0.0, 1e-13, 1e-12, 2.5, f32::INFINITY, 3.0e-10, 7.0] {
            let clamped = clamp_run(run);
            if run.is_nan() {
                assert!(clamped.is_nan());
            } else {
                assert_eq!(clamped.to_bits(), run.max(1e-12).to_bits(), "{run}");
            }
        }
        assert_eq!(min_ps(f32::NAN, 3.0), 3.0);
        assert!(min_ps(3.0, f32::NAN).is_nan());
        assert_eq!(max_ps(-0.0, 0.0).to_bits(), 0.0f32.to_bits());
        let large = [4_194_303.5f32, 4_194_304.0, 0.999_999_9, 1.0, 0.0, 102.4, 7.5];
        for v in large {
            assert_eq!(floor_small(v), v.floor(), "{v}");
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

    /// The one-instruction SSE forms keep the semantics of the selects they replace.
    #[test]
    fn lane_clamps_keep_their_semantics() {
        let inputs = [f32::NAN, -0.0, 0.0, -1.0, 1e-13, 2.5, f32::INFINITY, f32::NEG_INFINITY];
        let positive = zero_unless_positive_lanes(Lanes::new(inputs)).to_array();
        let expected_positive = inputs.map(|v| if v > 0.0 { v } else { 0.0 });
        assert_eq!(positive.map(f32::to_bits), expected_positive.map(f32::to_bits));
        let runs = [f32::NAN, 0.0, 1e-13, 1e-12, 2.5, f32::INFINITY, 3.0e-10, 7.0];
        let clamped = clamp_run_lanes(Lanes::new(runs)).to_array();
        for (got, run) in clamped.into_iter().zip(runs) {
            if run.is_nan() {
                assert!(got.is_nan());
            } else {
                assert_eq!(got.to_bits(), run.max(1e-12).to_bits(), "{run}");
            }
        }
        let mut index = [0u32; LANES];
        for base in [0u32, 1, 100, 1 << 20, (1 << 23) - LANES as u32] {
            let v: [f32; LANES] = std::array::from_fn(|l| (base + l as u32) as f32);
            store_index_lanes(Lanes::new(v), &mut index, 0);
            assert_eq!(index, std::array::from_fn(|l| base + l as u32));
        }
        let large: [f32; LANES] = [4_194_303.5, 4_194_304.0, 8_388_607.0, 0.999_999_9, 1.0, 0.0, 102.4, 7.5];
        assert_eq!(floor_small_lanes(Lanes::new(large)).to_array(), large.map(f32::floor));
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
        let cols = 256;
        let ranges = vec![2.0f32; cols];
        let mut gradient = vec![0.0f32; cols];
        for c in (10..14).chain(100..120).chain((0..3).chain(cols - 3..cols)) {
            gradient[c] = 1.0;
        }
        let mut obstacle = vec![false; cols];
        obstacles(&gradient, &ranges, cols, 0.3, RunFilter { min_px: 5, min_arc_m: 0.0 }, &mut obstacle);
        // Fewer than 5 px: removed; 20 px: kept; 6 px across the seam: kept.
        assert!(obstacle[10..14].iter().all(|&o| !o));
        assert!(obstacle[100..120].iter().all(|&o| o));
        assert!(obstacle[..3].iter().chain(&obstacle[cols - 3..]).all(|&o| o));
        // With 7 px: the seam run goes; with 4 px the 4-pixel run stays.
        obstacles(&gradient, &ranges, cols, 0.3, RunFilter { min_px: 7, min_arc_m: 0.0 }, &mut obstacle);
        assert!(obstacle[..3].iter().chain(&obstacle[cols - 3..]).all(|&o| !o));
        assert!(obstacle[100..120].iter().all(|&o| o));
        obstacles(&gradient, &ranges, cols, 0.3, RunFilter { min_px: 4, min_arc_m: 0.0 }, &mut obstacle);
        assert!(obstacle[10..14].iter().all(|&o| o));
    }

    /// The sanitising bit test is the two comparisons it replaces, on the special values and on
    /// bit patterns from every part of the range.
    #[test]
    fn sanitize_is_positive_and_finite() {
        let specials = [
            0.0,
            -0.0,
            f32::MIN_POSITIVE,
            f32::from_bits(1),
            -f32::from_bits(1),
            f32::MAX,
            f32::MIN,
            f32::INFINITY,
            f32::NEG_INFINITY,
            f32::NAN,
            -f32::NAN,
            f32::from_bits(0x7F80_0001),
            f32::from_bits(0xFFFF_FFFF),
            1.0,
            -1.0,
        ];
        let mut state = 0x9E37_79B9_u32;
        let patterns = (0..200_000).map(|_| {
            state ^= state << 13;
            state ^= state >> 17;
            state ^= state << 5;
            f32::from_bits(state)
        });
        for v in specials.into_iter().chain(patterns) {
            let want = if v > 0.0 && v < f32::INFINITY { v } else { 0.0 };
            assert_eq!(sanitize(v).to_bits(), want.to_bits(), "{v:e} ({:#x})", v.to_bits());
        }
    }

    /// The permuted runs of the azimuth rise (AVX2, AVX-512, where this processor has them) give
    /// the scalar loop's values on every column with a return: runs of one window, of windows
    /// spread by 1 to 12 (within and beyond the permutes' reach), windows above `pad` (clamped),
    /// columns without a return ([`ANY_WINDOW`]) first, last, inside and throughout a run, runs
    /// at both ends of the row (tables past the padding) and a partial last run.
    #[test]
    fn azimuth_rise_runs_match_the_scalar_loop() {
        let mut state = 0x2545_F491_u32;
        let mut next = move |n: u32| {
            state ^= state << 13;
            state ^= state >> 17;
            state ^= state << 5;
            state % n
        };
        for (pad, cols) in [(20usize, 203usize), (3, 64), (9, 40), (40, 1024)] {
            let padded: Vec<f32> = (0..cols + 2 * pad)
                .map(|_| if next(10) == 0 { f32::NAN } else { next(10_000) as f32 * 1e-3 - 5.0 })
                .collect();
            let mut half = Vec::with_capacity(cols);
            while half.len() < cols {
                let run = 1 + next(24) as usize;
                let base = 1 + next(pad as u32 + 2);
                let spread = [0, 0, 1, 2, 4, 5, 8, 9, 12][next(9) as usize];
                let any_share = [0, 0, 3, 10][next(4) as usize];
                for _ in 0..run.min(cols - half.len()) {
                    let w = base + if spread > 0 { next(spread + 1) } else { 0 };
                    half.push(if any_share > 0 && next(any_share) == 0 { ANY_WINDOW } else { w });
                }
            }
            let mut want = vec![0.0f32; cols];
            azimuth_rise_scalar(&padded, pad, &half, &mut want);
            let check = |got: &[f32], set: &str| {
                for (c, ((g, w), &h)) in got.iter().zip(&want).zip(&half).enumerate() {
                    if h != ANY_WINDOW {
                        assert!(
                            g.to_bits() == w.to_bits() || (g.is_nan() && w.is_nan()),
                            "{set} pad {pad}, column {c}"
                        );
                    }
                }
            };
            let mut got = vec![0.0f32; cols];
            azimuth_rise_with(pulp::Scalar::new(), &padded, pad, &half, &mut got);
            check(&got, "baseline");
            #[cfg(target_arch = "x86_64")]
            {
                if let Some(v3) = pulp::x86::V3::try_new() {
                    azimuth_rise_with(v3, &padded, pad, &half, &mut got);
                    check(&got, "avx2");
                }
                if let Some(v4) = pulp::x86::V4::try_new() {
                    azimuth_rise_with(v4, &padded, pad, &half, &mut got);
                    check(&got, "avx512");
                }
            }
        }
    }
}
