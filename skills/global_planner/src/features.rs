//! Per-cell features of the learned traversability model: colour C(p), distance to the nearest
//! cell of each semantic class S(p), elevation h(p); each channel normalised to zero mean and
//! unit variance over the mapped cells.

use spomp_core::{AerialMap, ClassTable, UNKNOWN_CLASS};

use spomp_raster::{FAR, SquaredEdt};

/// Where classes changed since the last rebuild.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum ClassChange {
    /// Anywhere (or first map): recompute everything.
    All,
    /// Inside the inclusive cell box `[col0, row0, col1, row1]`.
    Box([usize; 4]),
    /// Nowhere (colours or elevations may have changed).
    None,
}

/// Feature rasters derived from the aerial map.
#[derive(Clone, Debug, Default)]
pub(crate) struct Features {
    /// Table class index → slot in the distance vector (`u8::MAX`: not a table class).
    slot_of_class: Vec<u8>,
    /// Class index of each slot.
    class_of_slot: Vec<u8>,
    /// Distance to each class, quantised: `cells × slots` bytes, `cap_m / 255` per step.
    distance_q: Vec<u8>,
    /// Metres per quantisation step of `distance_q`.
    step_m: f32,
    /// Per channel mean.
    mean: Vec<f32>,
    /// Per channel 1 / standard deviation.
    inv_std: Vec<f32>,
    /// Squared-distance scratch, used during a rebuild and released after it.
    scratch: Vec<f32>,
}

impl Features {
    /// Features for the classes of `table`.
    pub fn new(table: &ClassTable) -> Self {
        let mut slot_of_class = vec![u8::MAX; 256];
        let mut class_of_slot = Vec::new();
        let mut indices: Vec<u8> = table.classes.iter().map(|c| c.index).collect();
        indices.sort_unstable();
        for c in indices {
            slot_of_class[c as usize] = class_of_slot.len() as u8;
            class_of_slot.push(c);
        }
        let channels = 3 + class_of_slot.len() + 1;
        Features {
            slot_of_class,
            class_of_slot,
            mean: vec![0.0; channels],
            inv_std: vec![1.0; channels],
            ..Default::default()
        }
    }

    /// Number of input channels: RGB, one distance per class, elevation.
    pub fn channels(&self) -> usize {
        3 + self.class_of_slot.len() + 1
    }

    /// Recomputes the distance rasters and the normalisation from the map. With a changed box,
    /// only distances within the cap of that box are recomputed: farther cells cannot change.
    pub fn rebuild(&mut self, map: &AerialMap, edt: &mut SquaredEdt, cap_m: f64, changed: ClassChange) {
        let (w, h) = (map.spec.width as usize, map.spec.height as usize);
        let n = w * h;
        let slots = self.class_of_slot.len();
        let cap_m = if cap_m.is_finite() && cap_m > 0.0 { cap_m } else { 25.0 };
        let res = map.spec.resolution_m as f32;
        let step_m = (cap_m / 255.0) as f32;
        let incremental = changed != ClassChange::All && self.distance_q.len() == n * slots && self.step_m == step_m;
        self.step_m = step_m;
        if incremental && changed == ClassChange::None {
            self.normalise(map);
            return;
        }
        if n == 0 {
            self.distance_q.clear();
            self.normalise(map);
            return;
        }
        let cap_cells = (cap_m / res as f64).ceil() as usize + 1;
        // Cells whose distances are written, and the larger window searched for seeds.
        let (write, window) = match changed {
            ClassChange::Box([c0, r0, c1, r1]) if incremental => {
                let grow =
                    |b: usize| [c0.saturating_sub(b), r0.saturating_sub(b), (c1 + b).min(w - 1), (r1 + b).min(h - 1)];
                (grow(cap_cells), grow(2 * cap_cells))
            }
            _ => {
                self.distance_q.clear();
                self.distance_q.resize(n * slots, u8::MAX);
                ([0, 0, w - 1, h - 1], [0, 0, w - 1, h - 1])
            }
        };
        let [wc0, wr0, wc1, wr1] = window;
        let (ww, wh) = (wc1 - wc0 + 1, wr1 - wr0 + 1);
        for slot in 0..slots {
            let class = self.class_of_slot[slot];
            self.scratch.clear();
            for row in wr0..=wr1 {
                let line = &map.class[row * w + wc0..=row * w + wc1];
                self.scratch.extend(line.iter().map(|&c| if c == class { 0.0 } else { FAR }));
            }
            if self.scratch.contains(&0.0) {
                edt.in_place(&mut self.scratch, ww, wh);
            }
            for row in write[1]..=write[3] {
                for col in write[0]..=write[2] {
                    let d2 = self.scratch[(row - wr0) * ww + (col - wc0)];
                    let q = (d2.sqrt() * res / step_m).round().min(255.0);
                    self.distance_q[(row * w + col) * slots + slot] = q as u8;
                }
            }
        }
        // The scratch is the size of the searched window (the whole map on a full rebuild, 4
        // bytes a cell): give it back rather than hold it per robot between rebuilds.
        self.scratch = Vec::new();
        self.normalise(map);
    }

    fn normalise(&mut self, map: &AerialMap) {
        let channels = self.channels();
        let mut sum = vec![0.0f64; channels];
        let mut sum_sq = vec![0.0f64; channels];
        let mut count = vec![0u64; channels];
        let mut raw = vec![0.0f32; channels];
        for i in 0..map.class.len() {
            if map.class[i] == UNKNOWN_CLASS {
                continue;
            }
            let has_elevation = self.raw(map, i, &mut raw);
            for (c, &v) in raw.iter().enumerate() {
                if c + 1 == channels && !has_elevation {
                    continue;
                }
                sum[c] += v as f64;
                sum_sq[c] += (v as f64) * (v as f64);
                count[c] += 1;
            }
        }
        for c in 0..channels {
            if count[c] == 0 {
                self.mean[c] = 0.0;
                self.inv_std[c] = 1.0;
                continue;
            }
            let mean = sum[c] / count[c] as f64;
            let var = (sum_sq[c] / count[c] as f64 - mean * mean).max(0.0);
            self.mean[c] = mean as f32;
            self.inv_std[c] = (1.0 / var.sqrt().max(1e-3)) as f32;
        }
    }

    /// Raw (unnormalised) features of a cell; returns whether the elevation is known.
    fn raw(&self, map: &AerialMap, i: usize, out: &mut [f32]) -> bool {
        let slots = self.class_of_slot.len();
        let rgb = map.rgb.get(i).copied().unwrap_or([0, 0, 0]);
        out[0] = rgb[0] as f32;
        out[1] = rgb[1] as f32;
        out[2] = rgb[2] as f32;
        let base = i * slots;
        for s in 0..slots {
            out[3 + s] = self.distance_q.get(base + s).copied().unwrap_or(u8::MAX) as f32 * self.step_m;
        }
        let e = map.elevation.get(i).copied().unwrap_or(f32::NAN);
        out[3 + slots] = if e.is_finite() { e } else { 0.0 };
        e.is_finite()
    }

    /// Normalised features of cell `i` into `out` (`channels()` long); false when the cell is
    /// not mapped (its descriptor is unknown).
    pub fn fill(&self, map: &AerialMap, i: usize, out: &mut [f32]) -> bool {
        if out.len() < self.channels() || map.class.get(i).is_none_or(|&c| c == UNKNOWN_CLASS) {
            return false;
        }
        let has_elevation = self.raw(map, i, out);
        let last = self.channels() - 1;
        for ((x, m), s) in out.iter_mut().zip(&self.mean).zip(&self.inv_std) {
            *x = (*x - m) * s;
        }
        if !has_elevation {
            out[last] = 0.0;
        }
        true
    }

    /// Distance from cell `i` to the nearest cell of a class, metres (saturated at the cap).
    pub fn class_distance_m(&self, i: usize, class: u8) -> f32 {
        let slots = self.class_of_slot.len();
        match self.slot_of_class.get(class as usize) {
            Some(&s) if s != u8::MAX => {
                self.distance_q.get(i * slots + s as usize).copied().unwrap_or(u8::MAX) as f32 * self.step_m
            }
            _ => 255.0 * self.step_m,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use spomp_core::{GridSpec, Point2};

    #[test]
    fn incremental_distances_match_a_full_rebuild() {
        let table = ClassTable::default_table();
        let spec = GridSpec::new(Point2::new(0.0, 0.0), 0.5, 90, 70);
        let mut map = AerialMap::unknown(spec);
        for i in 0..map.class.len() {
            map.class[i] = [0u8, 2, 3, 6, 255][(i * 7 + i / 90) % 5 % 3];
            map.elevation[i] = 0.0;
        }
        let mut edt = SquaredEdt::default();
        let mut inc = Features::new(&table);
        inc.rebuild(&map, &mut edt, 5.0, ClassChange::All);
        // Grow a tile of gravel and buildings in one corner.
        for row in 50..60 {
            for col in 70..85 {
                map.class[row * 90 + col] = if col % 4 == 0 { 2 } else { 6 };
            }
        }
        inc.rebuild(&map, &mut edt, 5.0, ClassChange::Box([70, 50, 84, 59]));
        let mut full = Features::new(&table);
        full.rebuild(&map, &mut edt, 5.0, ClassChange::All);
        assert_eq!(inc.distance_q, full.distance_q);
        assert_eq!(inc.mean, full.mean);
    }

    #[test]
    fn distances_and_normalisation() {
        let table = ClassTable::default_table();
        let mut map = AerialMap::unknown(GridSpec::new(Point2::new(0.0, 0.0), 0.5, 10, 1));
        for i in 0..10 {
            map.class[i] = if i == 0 { 2 } else { 0 };
            map.rgb[i] = [i as u8 * 10, 0, 0];
            map.elevation[i] = 1.0;
        }
        let mut f = Features::new(&table);
        f.rebuild(&map, &mut SquaredEdt::default(), 25.0, ClassChange::All);
        assert!((f.class_distance_m(4, 2) - 2.0).abs() < 0.06, "{}", f.class_distance_m(4, 2));
        assert_eq!(f.class_distance_m(4, 0), 0.0);
        // Class 6 (gravel) is absent: saturated.
        assert!((f.class_distance_m(4, 6) - 25.0).abs() < 1e-3);
        let mut x = vec![0.0; f.channels()];
        let mut mean_red = 0.0;
        for i in 0..10 {
            assert!(f.fill(&map, i, &mut x));
            mean_red += x[0];
        }
        assert!(mean_red.abs() < 1e-3, "normalised red has zero mean");
    }
}
