//! Exact squared Euclidean distance transform (Felzenszwalb & Huttenlocher's lower envelope of
//! parabolas), one pass per column then per row.
//!
//! Written here rather than taken from `imageproc` because graph construction runs it over small
//! windows hundreds of times with reused scratch buffers and `f32` values in place.

/// Value standing for "no seed here" (any value this large is treated as infinite).
pub const FAR: f32 = 1e20;

/// Scratch buffers for repeated transforms.
#[derive(Debug, Default)]
pub struct SquaredEdt {
    line: Vec<f32>,
    out: Vec<f32>,
    vertices: Vec<usize>,
    bounds: Vec<f32>,
}

impl SquaredEdt {
    /// In place: `grid` (row-major, `width × height`) holds 0 at seeds and [`FAR`] elsewhere; on
    /// return each cell holds the squared distance, in cells², to the nearest seed ([`FAR`]
    /// when there is none).
    pub fn transform(&mut self, grid: &mut [f32], width: usize, height: usize) {
        if width == 0 || height == 0 || grid.len() < width * height {
            return;
        }
        let grid = &mut grid[..width * height];
        // Along columns the seeds are binary, so the 1D transform is the distance to the nearest
        // seed: two sweeps over whole rows, in memory order.
        for row in 1..height {
            let (above, here) = grid[(row - 1) * width..(row + 1) * width].split_at_mut(width);
            for (h, a) in here.iter_mut().zip(above.iter()) {
                if *h != 0.0 {
                    *h = (*a + 1.0).min(FAR);
                }
            }
        }
        for row in (0..height.saturating_sub(1)).rev() {
            let (here, below) = grid[row * width..(row + 2) * width].split_at_mut(width);
            for (h, b) in here.iter_mut().zip(below.iter()) {
                *h = h.min(*b + 1.0);
            }
        }
        let limit = (width + height) as f32;
        for v in grid.iter_mut() {
            *v = if *v > limit { FAR } else { *v * *v };
        }
        self.line.resize(width, FAR);
        self.out.resize(width, FAR);
        self.vertices.resize(width, 0);
        self.bounds.resize(width + 1, 0.0);
        for row in 0..height {
            let cells = &mut grid[row * width..(row + 1) * width];
            self.line.copy_from_slice(cells);
            self.lower_envelope(width);
            cells.copy_from_slice(&self.out[..width]);
        }
    }

    /// 1D transform of `line[..n]` into `out[..n]`.
    fn lower_envelope(&mut self, n: usize) {
        let f = &self.line;
        let v = &mut self.vertices;
        let z = &mut self.bounds;
        let mut k = 0usize;
        let mut first = None;
        for (q, &fq) in f.iter().enumerate().take(n) {
            if fq < FAR {
                first = Some(q);
                break;
            }
        }
        let Some(first) = first else {
            self.out[..n].fill(FAR);
            return;
        };
        v[0] = first;
        z[0] = f32::NEG_INFINITY;
        z[1] = f32::INFINITY;
        for q in first + 1..n {
            let fq = f[q];
            if fq >= FAR {
                continue;
            }
            let qf = q as f32;
            loop {
                let p = v[k];
                let pf = p as f32;
                let s = ((fq + qf * qf) - (f[p] + pf * pf)) / (2.0 * (qf - pf));
                // z[0] is −∞, so this never steps below the first parabola.
                if s <= z[k] && k > 0 {
                    k -= 1;
                } else {
                    k += 1;
                    v[k] = q;
                    z[k] = s;
                    z[k + 1] = f32::INFINITY;
                    break;
                }
            }
        }
        let mut k = 0usize;
        for q in 0..n {
            let qf = q as f32;
            while z[k + 1] < qf {
                k += 1;
            }
            let p = v[k];
            let d = qf - p as f32;
            self.out[q] = d * d + f[p];
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn brute(seeds: &[bool], w: usize, h: usize) -> Vec<f32> {
        (0..w * h)
            .map(|i| {
                let (x, y) = ((i % w) as f32, (i / w) as f32);
                seeds
                    .iter()
                    .enumerate()
                    .filter(|(_, s)| **s)
                    .map(|(j, _)| {
                        let (a, b) = ((j % w) as f32, (j / w) as f32);
                        (x - a) * (x - a) + (y - b) * (y - b)
                    })
                    .fold(FAR, f32::min)
            })
            .collect()
    }

    #[test]
    fn single_seed_gives_squared_distances() {
        let (w, h) = (5, 4);
        let mut g = vec![FAR; w * h];
        g[2 * w + 1] = 0.0;
        SquaredEdt::default().transform(&mut g, w, h);
        assert_eq!(g[0], 1.0 + 4.0);
        assert_eq!(g[3 * w + 4], 9.0 + 1.0);
        assert_eq!(g[2 * w + 1], 0.0);
    }

    proptest! {
        #[test]
        fn matches_brute_force(w in 1usize..12, h in 1usize..12, bits in proptest::collection::vec(proptest::bool::weighted(0.15), 144)) {
            let seeds: Vec<bool> = bits[..w * h].to_vec();
            let mut g: Vec<f32> = seeds.iter().map(|&s| if s { 0.0 } else { FAR }).collect();
            SquaredEdt::default().transform(&mut g, w, h);
            let expect = brute(&seeds, w, h);
            for (a, b) in g.iter().zip(&expect) {
                if *b >= FAR { prop_assert!(*a >= FAR * 0.5); } else { prop_assert!((a - b).abs() < 1e-3, "{a} vs {b}"); }
            }
        }
    }
}
