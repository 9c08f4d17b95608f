//! Exact squared Euclidean distance transform of a row-major grid (Felzenszwalb &
//! Huttenlocher): the distance along each column to the nearest seed by two sweeps over whole
//! rows, then per row the lower envelope of the parabolas `f(p) + (x − p)²`.
//!
//! Squared distances are whole numbers, exact in `f64`; the envelope's crossings are computed in
//! `f64` too, so the result is exact for any grid that fits in memory.

/// What [`SquaredEdt::in_place`] writes where there is no seed (any value this large stands for
/// "infinitely far").
pub const FAR: f32 = 1e20;

/// Column distance standing for "no seed in this column".
const NONE: u32 = u32::MAX;

/// Reusable buffers of the transform: after the first call of a given size, a call allocates
/// nothing but its result (and [`SquaredEdt::in_place`] not even that).
#[derive(Clone, Debug, Default)]
pub struct SquaredEdt {
    /// Per column of the current sweep, distance to the nearest seed seen (`NONE`: none).
    sweep: Vec<u32>,
    /// Per cell, distance along its column to the nearest seed (`NONE`: none).
    along_column: Vec<u32>,
    /// One row's column distances squared (`∞`: none).
    row: Vec<f64>,
    /// One row's result.
    row_out: Vec<f64>,
    /// Lower envelope: parabola centres and the boundaries between them.
    centres: Vec<usize>,
    bounds: Vec<f64>,
}

impl SquaredEdt {
    /// Squared distance (cells²) from every cell of a `width × height` row-major grid to the
    /// nearest cell with a non-zero `mask` value; `∞` everywhere when there is none (or when
    /// `mask` is not `width × height` long).
    pub fn of_mask(&mut self, mask: &[u8], width: usize, height: usize) -> Vec<f64> {
        let mut out = vec![f64::INFINITY; mask.len()];
        if width == 0 || height == 0 || mask.len() != width * height {
            return out;
        }
        self.column_pass(width, height, |row| mask[row * width..(row + 1) * width].iter().map(|&m| m != 0));
        for (row, out_row) in out.chunks_exact_mut(width).enumerate() {
            out_row.copy_from_slice(self.row_pass(width, row));
        }
        out
    }

    /// In place: `grid` (row-major, `width × height`) holds 0 at the seeds and anything else
    /// elsewhere; on return each cell holds its squared distance (cells²) to the nearest seed,
    /// [`FAR`] when there is none. A grid shorter than `width × height` is left as it is.
    pub fn in_place(&mut self, grid: &mut [f32], width: usize, height: usize) {
        if width == 0 || height == 0 || grid.len() < width * height {
            return;
        }
        let grid = &mut grid[..width * height];
        self.column_pass(width, height, |row| grid[row * width..(row + 1) * width].iter().map(|&v| v == 0.0));
        for (row, cells) in grid.chunks_exact_mut(width).enumerate() {
            for (cell, &d2) in cells.iter_mut().zip(self.row_pass(width, row)) {
                // Whole numbers below 2²⁴ convert exactly; larger ones are far anyway.
                *cell = if d2.is_finite() { (d2 as f32).min(FAR) } else { FAR };
            }
        }
    }

    /// Fills `along_column` with each cell's distance along its column to the nearest seed;
    /// `seeds_of(row)` yields the row's seed flags, left to right.
    fn column_pass<I: Iterator<Item = bool>>(&mut self, width: usize, height: usize, seeds_of: impl Fn(usize) -> I) {
        self.sweep.clear();
        self.sweep.resize(width, NONE);
        self.along_column.clear();
        self.along_column.resize(width * height, NONE);
        // Downwards: distance to the nearest seed above (or here).
        for (row, out_row) in self.along_column.chunks_exact_mut(width).enumerate() {
            for ((seed, s), o) in seeds_of(row).zip(self.sweep.iter_mut()).zip(out_row.iter_mut()) {
                *s = if seed { 0 } else { s.saturating_add(1) };
                *o = *s;
            }
        }
        // Upwards: the nearer of that and the nearest seed below.
        self.sweep.fill(NONE);
        for out_row in self.along_column.chunks_exact_mut(width).rev() {
            for (s, o) in self.sweep.iter_mut().zip(out_row.iter_mut()) {
                *s = if *o == 0 { 0 } else { s.saturating_add(1) };
                *o = (*o).min(*s);
            }
        }
    }

    /// The squared distances of one row, from the column distances of [`Self::column_pass`].
    fn row_pass(&mut self, width: usize, row: usize) -> &[f64] {
        self.row.resize(width, f64::INFINITY);
        self.row_out.resize(width, f64::INFINITY);
        self.centres.resize(width, 0);
        self.bounds.resize(width + 1, 0.0);
        let column = &self.along_column[row * width..(row + 1) * width];
        for (f, &d) in self.row.iter_mut().zip(column) {
            *f = if d == NONE { f64::INFINITY } else { d as f64 * d as f64 };
        }
        lower_envelope(&self.row, &mut self.centres, &mut self.bounds, &mut self.row_out);
        &self.row_out
    }
}

/// Where the parabolas centred at `p` and `q` (values `f[p]`, `f[q]`) cross.
#[inline]
fn crossing(f: &[f64], p: usize, q: usize) -> f64 {
    let (fp, fq) = (f[p], f[q]);
    let (p, q) = (p as f64, q as f64);
    ((fq + q * q) - (fp + p * p)) / (2.0 * q - 2.0 * p)
}

/// One-dimensional transform: `out[x] = min_p (x − p)² + f[p]` (`∞` when every `f` is).
fn lower_envelope(f: &[f64], centres: &mut [usize], bounds: &mut [f64], out: &mut [f64]) {
    let len = f.len();
    if len == 0 || centres.len() < len || bounds.len() < len + 1 || out.len() < len {
        return;
    }
    let mut k = 0;
    centres[0] = 0;
    bounds[0] = f64::NEG_INFINITY;
    bounds[1] = f64::INFINITY;
    for q in 1..len {
        if f[q] == f64::INFINITY {
            continue;
        }
        // Until a finite parabola is in the envelope, the first finite one replaces it.
        if k == 0 && f[centres[0]] == f64::INFINITY {
            centres[0] = q;
            continue;
        }
        let mut s = crossing(f, centres[k], q);
        while s <= bounds[k] {
            k -= 1;
            s = crossing(f, centres[k], q);
        }
        k += 1;
        centres[k] = q;
        bounds[k] = s;
        bounds[k + 1] = f64::INFINITY;
    }
    let mut k = 0;
    for (q, o) in out.iter_mut().enumerate().take(len) {
        while bounds[k + 1] < q as f64 {
            k += 1;
        }
        let d = q as f64 - centres[k] as f64;
        *o = d * d + f[centres[k]];
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use image::GrayImage;
    use imageproc::distance_transform::euclidean_squared_distance_transform;
    use proptest::prelude::*;
    use rand::{Rng, SeedableRng};

    /// Same values as imageproc's transform, bit for bit, on random grids of every density,
    /// thin and empty ones included, with one scratch reused across sizes.
    #[test]
    fn of_mask_equals_imageprocs_transform() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        let mut edt = SquaredEdt::default();
        for case in 0..60 {
            let (w, h) = match case {
                0 => (1, 1),
                1 => (1, 17),
                2 => (23, 1),
                _ => (rng.random_range(1..90usize), rng.random_range(1..70usize)),
            };
            let density = [0.0, 0.001, 0.01, 0.1, 0.5, 1.0][case % 6];
            let mask: Vec<u8> = (0..w * h).map(|_| if rng.random_bool(density) { 255 } else { 0 }).collect();
            let image = GrayImage::from_raw(w as u32, h as u32, mask.clone()).expect("image");
            let expected = euclidean_squared_distance_transform(&image).into_raw();
            let got = edt.of_mask(&mask, w, h);
            assert_eq!(got.len(), expected.len());
            for (i, (a, b)) in got.iter().zip(&expected).enumerate() {
                assert!(a.to_bits() == b.to_bits(), "case {case} ({w}×{h}) cell {i}: {a} vs {b}");
            }
        }
    }

    #[test]
    fn a_single_seed_gives_squared_distances_and_bad_sizes_change_nothing() {
        let (w, h) = (5, 4);
        let mut grid = vec![FAR; w * h];
        grid[2 * w + 1] = 0.0;
        let mut edt = SquaredEdt::default();
        edt.in_place(&mut grid, w, h);
        assert_eq!(grid[0], 1.0 + 4.0);
        assert_eq!(grid[3 * w + 4], 9.0 + 1.0);
        assert_eq!(grid[2 * w + 1], 0.0);

        let mut short = vec![0.0f32, 7.0];
        edt.in_place(&mut short, 3, 3);
        assert_eq!(short, vec![0.0, 7.0]);
        assert!(edt.of_mask(&[1, 0], 3, 3).iter().all(|d| d.is_infinite()));
        assert!(edt.of_mask(&[0; 6], 3, 2).iter().all(|d| d.is_infinite()));
    }

    fn brute_force(seeds: &[bool], w: usize) -> Vec<f32> {
        (0..seeds.len())
            .map(|i| {
                let (x, y) = ((i % w) as f32, (i / w) as f32);
                seeds
                    .iter()
                    .enumerate()
                    .filter(|&(_, &s)| s)
                    .map(|(j, _)| {
                        let (a, b) = ((j % w) as f32, (j / w) as f32);
                        (x - a) * (x - a) + (y - b) * (y - b)
                    })
                    .fold(FAR, f32::min)
            })
            .collect()
    }

    proptest! {
        #[test]
        fn in_place_matches_brute_force(
            w in 1usize..14,
            h in 1usize..14,
            bits in proptest::collection::vec(proptest::bool::weighted(0.15), 196),
        ) {
            let seeds = &bits[..w * h];
            let mut grid: Vec<f32> = seeds.iter().map(|&s| if s { 0.0 } else { FAR }).collect();
            SquaredEdt::default().in_place(&mut grid, w, h);
            prop_assert_eq!(grid, brute_force(seeds, w));
        }
    }
}
