//! Per-cell features of the learned traversability model: colour C(p), distance to the nearest
//! cell of each semantic class S(p), elevation h(p); each channel normalised to zero mean and
//! unit variance over the mapped cells.
//!
//! The distance rasters and the normalisation are a pure function of the map (and the class
//! table and distance cap), so planners holding the same map — a team starting with one prior
//! map, robots that received the same map version — share one set ([`Rasters`]) instead of
//! each building and holding its own (one byte per cell and class: 4.3 MB for an 800 × 600
//! map with nine classes).

use std::sync::Arc;

use spomp_core::{AerialMap, ClassTable, GridSpec, UNKNOWN_CLASS};
use spomp_raster::{FAR, SharedList, SquaredEdt, fingerprint};

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

/// What a set of rasters was built from: two rasters with the same key are equal.
#[derive(Clone, Copy, Debug, PartialEq)]
struct RastersKey {
    spec: GridSpec,
    version: u64,
    /// Fingerprints of the class, colour and elevation layers (two independent seeds).
    content: [u64; 2],
    /// Fingerprint of the slot → class assignment (the class table's indices).
    slots: u64,
    /// Bits of the quantisation step (the distance cap / 255).
    step_bits: u32,
}

impl RastersKey {
    fn of(map: &AerialMap, class_of_slot: &[u8], step_m: f32) -> Self {
        RastersKey {
            spec: map.spec,
            version: map.version,
            content: [CONTENT_SEEDS[0], CONTENT_SEEDS[1]].map(|seed| map_fingerprint(map, seed)),
            slots: fingerprint(class_of_slot, 0),
            step_bits: step_m.to_bits(),
        }
    }
}

/// Seeds of the two content fingerprints.
const CONTENT_SEEDS: [u64; 2] = [0x4528_21E6_38D0_1377, 0xBE54_66CF_34E9_0C6C];

/// Fingerprint of a map's three layers (elevations by their bit patterns).
fn map_fingerprint(map: &AerialMap, seed: u64) -> u64 {
    let class = fingerprint(&map.class, seed);
    let rgb = fingerprint(map.rgb.as_flattened(), seed.rotate_left(13));
    let elevation_bytes: Vec<u8> = map.elevation.iter().flat_map(|e| e.to_bits().to_le_bytes()).collect();
    let elevation = fingerprint(&elevation_bytes, seed.rotate_left(29));
    fingerprint(&[class, rgb, elevation].map(u64::to_le_bytes).concat(), seed)
}

/// The map-derived part of the features.
#[derive(Clone, Debug, Default)]
struct Rasters {
    /// What they were built from (`None`: nothing yet).
    key: Option<RastersKey>,
    /// Distance to each class, quantised: `cells × slots` bytes, `cap_m / 255` per step.
    distance_q: Vec<u8>,
    /// Metres per quantisation step of `distance_q`.
    step_m: f32,
    /// Per channel mean.
    mean: Vec<f32>,
    /// Per channel 1 / standard deviation.
    inv_std: Vec<f32>,
}

/// Every set of rasters alive in the process (planners of a team, trials run side by side),
/// found by what they were built from.
static SHARED_RASTERS: SharedList<Rasters> = SharedList::new();

/// Feature rasters derived from the aerial map.
#[derive(Clone, Debug, Default)]
pub(crate) struct Features {
    /// Table class index → slot in the distance vector (`u8::MAX`: not a table class).
    slot_of_class: Vec<u8>,
    /// Class index of each slot.
    class_of_slot: Vec<u8>,
    /// Distances and normalisation, shared with every planner holding the same map.
    rasters: Arc<Rasters>,
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
        let rasters = Rasters { mean: vec![0.0; channels], inv_std: vec![1.0; channels], ..Default::default() };
        Features { slot_of_class, class_of_slot, rasters: Arc::new(rasters), scratch: Vec::new() }
    }

    /// Number of input channels: RGB, one distance per class, elevation.
    pub fn channels(&self) -> usize {
        3 + self.class_of_slot.len() + 1
    }

    /// Brings the distance rasters and the normalisation up to date with the map: the set
    /// another planner built from the same map when there is one, else this planner's own,
    /// rebuilt — with a changed box, only distances within the cap of that box are recomputed:
    /// farther cells cannot change.
    pub fn rebuild(&mut self, map: &AerialMap, edt: &mut SquaredEdt, cap_m: f64, changed: ClassChange) {
        let cap_m = if cap_m.is_finite() && cap_m > 0.0 { cap_m } else { 25.0 };
        let step_m = (cap_m / 255.0) as f32;
        let key = RastersKey::of(map, &self.class_of_slot, step_m);
        if self.rasters.key == Some(key) {
            return;
        }
        if let Some(found) = SHARED_RASTERS.find(|r| r.key == Some(key)) {
            self.rasters = found;
            return;
        }
        let n = map.spec.len();
        let slots = self.class_of_slot.len();
        let incremental =
            changed != ClassChange::All && self.rasters.distance_q.len() == n * slots && self.rasters.step_m == step_m;
        if !incremental {
            // Start afresh rather than copy a set others hold only to overwrite it.
            let channels = self.channels();
            self.rasters =
                Arc::new(Rasters { mean: vec![0.0; channels], inv_std: vec![1.0; channels], ..Default::default() });
        }
        let rasters = Arc::make_mut(&mut self.rasters);
        rasters.key = Some(key);
        rasters.step_m = step_m;
        if !(incremental && changed == ClassChange::None) && n > 0 {
            let change = if incremental { changed } else { ClassChange::All };
            rasters.rebuild_distances(map, edt, &self.class_of_slot, &mut self.scratch, cap_m, change);
        } else if n == 0 {
            rasters.distance_q.clear();
        }
        // The scratch is the size of the searched window (the whole map on a full rebuild, 4
        // bytes a cell): give it back rather than hold it per robot between rebuilds.
        self.scratch = Vec::new();
        rasters.normalise(map, slots);
        self.rasters = SHARED_RASTERS.share(Arc::clone(&self.rasters), |r| r.key == Some(key));
    }

    /// Normalised features of cell `i` into `out` (`channels()` long); false when the cell is
    /// not mapped (its descriptor is unknown).
    pub fn fill(&self, map: &AerialMap, i: usize, out: &mut [f32]) -> bool {
        if out.len() < self.channels() || map.class.get(i).is_none_or(|&c| c == UNKNOWN_CLASS) {
            return false;
        }
        let has_elevation = self.rasters.raw(map, i, out, self.class_of_slot.len());
        let last = self.channels() - 1;
        for ((x, m), s) in out.iter_mut().zip(&self.rasters.mean).zip(&self.rasters.inv_std) {
            *x = (*x - m) * s;
        }
        if !has_elevation {
            out[last] = 0.0;
        }
        true
    }

    /// Bytes of one cell's packed raw features ([`Self::pack`]): colour, one quantised
    /// distance per class, the elevation's bits.
    pub fn packed_len(&self) -> usize {
        3 + self.class_of_slot.len() + 4
    }

    /// Appends the raw features of cell `i` to `out`, packed ([`Self::packed_len`] bytes: a
    /// quarter of the normalised floats, for the features an edge caches); false (nothing
    /// appended) when the cell is not mapped.
    pub fn pack(&self, map: &AerialMap, i: usize, out: &mut Vec<u8>) -> bool {
        if map.class.get(i).is_none_or(|&c| c == UNKNOWN_CLASS) {
            return false;
        }
        let slots = self.class_of_slot.len();
        out.extend_from_slice(&map.rgb.get(i).copied().unwrap_or([0, 0, 0]));
        let base = i * slots;
        out.extend((0..slots).map(|s| self.rasters.distance_q.get(base + s).copied().unwrap_or(u8::MAX)));
        out.extend_from_slice(&map.elevation.get(i).copied().unwrap_or(f32::NAN).to_bits().to_le_bytes());
        true
    }

    /// The normalised features of one packed cell into `out` (`channels()` long): exactly what
    /// [`Self::fill`] gives for that cell while the rasters are unchanged.
    #[inline(always)]
    pub fn unpack(&self, packed: &[u8], out: &mut [f32]) {
        let slots = self.class_of_slot.len();
        if packed.len() < self.packed_len() || out.len() < self.channels() {
            return;
        }
        let r = &self.rasters;
        for c in 0..3 {
            out[c] = packed[c] as f32;
        }
        for s in 0..slots {
            out[3 + s] = packed[3 + s] as f32 * r.step_m;
        }
        let mut bits = [0u8; 4];
        bits.copy_from_slice(&packed[3 + slots..7 + slots]);
        let e = f32::from_bits(u32::from_le_bytes(bits));
        let last = 3 + slots;
        out[last] = if e.is_finite() { e } else { 0.0 };
        for ((x, m), s) in out.iter_mut().zip(&r.mean).zip(&r.inv_std) {
            *x = (*x - m) * s;
        }
        if !e.is_finite() {
            out[last] = 0.0;
        }
    }

    /// Distance from cell `i` to the nearest cell of a class, metres (saturated at the cap).
    pub fn class_distance_m(&self, i: usize, class: u8) -> f32 {
        let slots = self.class_of_slot.len();
        let r = &self.rasters;
        match self.slot_of_class.get(class as usize) {
            Some(&s) if s != u8::MAX => {
                r.distance_q.get(i * slots + s as usize).copied().unwrap_or(u8::MAX) as f32 * r.step_m
            }
            _ => 255.0 * r.step_m,
        }
    }
}

impl Rasters {
    /// Recomputes the quantised distances (all of them, or within the cap of a changed box).
    fn rebuild_distances(
        &mut self,
        map: &AerialMap,
        edt: &mut SquaredEdt,
        class_of_slot: &[u8],
        scratch: &mut Vec<f32>,
        cap_m: f64,
        changed: ClassChange,
    ) {
        let (w, h) = (map.spec.width as usize, map.spec.height as usize);
        let n = w * h;
        let slots = class_of_slot.len();
        let res = map.spec.resolution_m as f32;
        let step_m = self.step_m;
        let cap_cells = (cap_m / res as f64).ceil() as usize + 1;
        // Cells whose distances are written, and the larger window searched for seeds.
        let (write, window) = match changed {
            ClassChange::Box([c0, r0, c1, r1]) => {
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
        for (slot, &class) in class_of_slot.iter().enumerate() {
            scratch.clear();
            for row in wr0..=wr1 {
                let line = &map.class[row * w + wc0..=row * w + wc1];
                scratch.extend(line.iter().map(|&c| if c == class { 0.0 } else { FAR }));
            }
            if scratch.contains(&0.0) {
                edt.in_place(scratch, ww, wh);
            }
            for row in write[1]..=write[3] {
                for col in write[0]..=write[2] {
                    let d2 = scratch[(row - wr0) * ww + (col - wc0)];
                    let q = (d2.sqrt() * res / step_m).round().min(255.0);
                    self.distance_q[(row * w + col) * slots + slot] = q as u8;
                }
            }
        }
    }

    fn normalise(&mut self, map: &AerialMap, slots: usize) {
        let channels = 3 + slots + 1;
        let mut sum = vec![0.0f64; channels];
        let mut sum_sq = vec![0.0f64; channels];
        let mut count = vec![0u64; channels];
        let mut raw = vec![0.0f32; channels];
        for i in 0..map.class.len() {
            if map.class[i] == UNKNOWN_CLASS {
                continue;
            }
            let has_elevation = self.raw(map, i, &mut raw, slots);
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
    fn raw(&self, map: &AerialMap, i: usize, out: &mut [f32], slots: usize) -> bool {
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
        // A full rebuild from scratch (not through the shared sets, which would hand back the
        // incremental one).
        let slots = inc.class_of_slot.len();
        let mut full = Rasters {
            step_m: (5.0 / 255.0) as f32,
            mean: vec![0.0; slots + 4],
            inv_std: vec![1.0; slots + 4],
            ..Default::default()
        };
        full.rebuild_distances(&map, &mut edt, &inc.class_of_slot, &mut Vec::new(), 5.0, ClassChange::All);
        full.normalise(&map, slots);
        assert_eq!(inc.rasters.distance_q, full.distance_q);
        assert_eq!(inc.rasters.mean, full.mean);
        assert_eq!(inc.rasters.inv_std, full.inv_std);
    }

    #[test]
    fn planners_holding_the_same_map_share_one_set_of_rasters() {
        let table = ClassTable::default_table();
        let spec = GridSpec::new(Point2::new(0.0, 0.0), 0.5, 40, 30);
        let mut map = AerialMap::unknown(spec);
        for i in 0..map.class.len() {
            map.class[i] = [0u8, 3, 2][(i * 5 + i / 40) % 3];
            map.elevation[i] = (i % 7) as f32 * 0.1;
            map.rgb[i] = [i as u8, 0, 9];
        }
        let mut edt = SquaredEdt::default();
        let mut a = Features::new(&table);
        let mut b = Features::new(&table);
        a.rebuild(&map, &mut edt, 6.0, ClassChange::All);
        b.rebuild(&map, &mut edt, 6.0, ClassChange::All);
        assert!(Arc::ptr_eq(&a.rasters, &b.rasters), "same map, same cap: one set");
        // Same classes, another colour: the normalisation differs, so no sharing.
        let mut recoloured = map.clone();
        recoloured.rgb[5] = [200, 200, 200];
        b.rebuild(&recoloured, &mut edt, 6.0, ClassChange::None);
        assert!(!Arc::ptr_eq(&a.rasters, &b.rasters));
        assert_eq!(a.rasters.distance_q, b.rasters.distance_q);
        assert_ne!(a.rasters.mean, b.rasters.mean);
        // Another cap: other quantisation.
        let mut c = Features::new(&table);
        c.rebuild(&map, &mut edt, 9.0, ClassChange::All);
        assert!(!Arc::ptr_eq(&a.rasters, &c.rasters));
        // A's set is unchanged by B's rebuild (copy on write).
        let mut fresh = Features::new(&table);
        fresh.rebuild(&map, &mut edt, 6.0, ClassChange::All);
        assert!(Arc::ptr_eq(&a.rasters, &fresh.rasters));
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
        let mut packed = Vec::new();
        let mut unpacked = vec![0.0; f.channels()];
        map.elevation[7] = f32::NAN;
        for i in 0..10 {
            assert!(f.fill(&map, i, &mut x));
            mean_red += x[0];
            packed.clear();
            assert!(f.pack(&map, i, &mut packed));
            assert_eq!(packed.len(), f.packed_len());
            f.unpack(&packed, &mut unpacked);
            let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
            assert_eq!(bits(&unpacked), bits(&x), "cell {i}: packed features unpack to the very same floats");
        }
        assert!(mean_red.abs() < 1e-3, "normalised red has zero mean");
    }
}
