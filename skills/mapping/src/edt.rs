//! Exact squared Euclidean distance transform of a binary grid (Felzenszwalb & Huttenlocher):
//! the distance along each column to the nearest set cell by two sweeps over whole rows, then
//! per row the lower envelope of the parabolas `f(p) + (x − p)²`.
//!
//! The values are those of `imageproc::distance_transform::euclidean_squared_distance_transform`
//! (squared distances are whole numbers, exact in `f64`; `∞` when no cell is set), computed
//! without per-pixel image accessors or column-strided passes.

/// Reusable buffers of [`SquaredEdt::transform`].
#[derive(Clone, Debug, Default)]
pub(crate) struct SquaredEdt {
    /// Per column of the current sweep, distance to the nearest set cell seen (`u32::MAX`: none).
    sweep: Vec<u32>,
    /// Per cell, distance along its column to the nearest set cell.
    along_column: Vec<u32>,
    /// One row's column distances squared.
    row: Vec<f64>,
    /// Lower envelope: parabola centres and the boundaries between them.
    centres: Vec<usize>,
    bounds: Vec<f64>,
}

impl SquaredEdt {
    /// Squared distance (cells²) from every cell of a `width × height` row-major grid to the
    /// nearest cell with a non-zero `mask` value; `∞` everywhere when there is none. Row order
    /// does not matter (the transform is symmetric).
    pub fn transform(&mut self, mask: &[u8], width: usize, height: usize) -> Vec<f64> {
        let n = width * height;
        if n == 0 || mask.len() != n {
            return vec![f64::INFINITY; mask.len()];
        }
        const NONE: u32 = u32::MAX;
        self.sweep.clear();
        self.sweep.resize(width, NONE);
        self.along_column.clear();
        self.along_column.resize(n, NONE);
        for (mask_row, out_row) in mask.chunks_exact(width).zip(self.along_column.chunks_exact_mut(width)) {
            for ((&m, s), o) in mask_row.iter().zip(self.sweep.iter_mut()).zip(out_row.iter_mut()) {
                *s = if m != 0 { 0 } else { s.saturating_add(1) };
                *o = *s;
            }
        }
        self.sweep.fill(NONE);
        for out_row in self.along_column.chunks_exact_mut(width).rev() {
            for (s, o) in self.sweep.iter_mut().zip(out_row.iter_mut()) {
                *s = if *o == 0 { 0 } else { s.saturating_add(1) };
                *o = (*o).min(*s);
            }
        }

        let mut out = vec![0.0f64; n];
        self.row.resize(width, 0.0);
        self.centres.resize(width, 0);
        self.bounds.resize(width + 1, 0.0);
        for (column_row, out_row) in self.along_column.chunks_exact(width).zip(out.chunks_exact_mut(width)) {
            for (f, &d) in self.row.iter_mut().zip(column_row) {
                *f = if d == NONE { f64::INFINITY } else { d as f64 * d as f64 };
            }
            lower_envelope(&self.row, &mut self.centres, &mut self.bounds, out_row);
        }
        out
    }
}

/// Where the parabolas centred at `p` and `q` (values `f[p]`, `f[q]`) cross.
#[inline]
fn crossing(f: &[f64], p: usize, q: usize) -> f64 {
    let (fp, fq) = (f[p], f[q]);
    let (p, q) = (p as f64, q as f64);
    ((fq + q * q) - (fp + p * p)) / (2.0 * q - 2.0 * p)
}

/// One-dimensional transform: `out[x] = min_p (x − p)² + f[p]`.
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
        if k == 0 && f[centres[0]] == f64::INFINITY {
            centres[0] = q;
            bounds[0] = f64::NEG_INFINITY;
            bounds[1] = f64::INFINITY;
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
    use rand::{Rng, SeedableRng};

    /// Same values as imageproc's transform, bit for bit, on random grids of every density,
    /// thin and empty ones included.
    #[test]
    fn equals_imageprocs_transform() {
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
            let image = GrayImage::from_raw(w as u32, h as u32, mask.clone()).unwrap();
            let expected = euclidean_squared_distance_transform(&image).into_raw();
            let got = edt.transform(&mask, w, h);
            assert_eq!(got.len(), expected.len());
            for (i, (a, b)) in got.iter().zip(&expected).enumerate() {
                assert!(a.to_bits() == b.to_bits(), "case {case} ({w}×{h}) cell {i}: {a} vs {b}");
            }
        }
    }
}
