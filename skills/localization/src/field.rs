//! The aerial side of the match: one cost plane per weighted class, precomputed from the aerial
//! semantic map (after Miller et al., "Any way you look at it": per-class distance fields of the
//! overhead map).
//!
//! The cost of an observed cell of class c landing on aerial cell q is
//! `min(d_c(q), max_match_distance, d_unknown(q) + U_c)`: the distance to the nearest aerial
//! cell of class c, where an unknown cell may stand in for c at the extra cost U_c, the mean
//! cost of class c over the known map (what a random guess would score). A cell that is itself
//! unknown (or off the map) is marked [`UNKNOWN_COST_LEVEL`] and costs exactly U_c, for every
//! particle alike. Costs are stored as u8 levels so that one plane of an
//! 800 × 600 map is 480 kB and the per-particle loop stays in cache.

use std::collections::BTreeMap;
use std::sync::Arc;

use spomp_core::{AerialMap, ClassId, ClassTable, GridSpec, UNKNOWN_CLASS};
use spomp_raster::{SharedList, SquaredEdt};

use crate::error::LocalizationError;
use crate::params::LocalizationParams;

/// Most classes that can carry a weight at once (one bit each in the local grid's cell mask).
pub const MAX_WEIGHTED_CLASSES: usize = 32;
/// Stored level of an aerial cell that is unknown: costs the class's random-guess cost.
pub(crate) const UNKNOWN_COST_LEVEL: u8 = 255;
/// Highest level of a known cell; it stands for `max_match_distance_m`.
pub(crate) const MAX_KNOWN_LEVEL: f32 = 254.0;
/// Slot value of a class that is not used for matching.
pub(crate) const NO_SLOT: u8 = u8::MAX;

/// The classes used for matching, each given a compact slot index.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct ClassSlots {
    /// Slot of each class index, or [`NO_SLOT`].
    pub slot_of_class: [u8; 256],
    /// Weight of each slot.
    pub weight: Vec<f32>,
    /// Whether each slot is a ground class (else an obstacle class).
    pub is_ground: Vec<bool>,
    /// Class index of each slot.
    pub class_of_slot: Vec<ClassId>,
    /// Whether a class index is a ground class (re-localisation spreads particles over them).
    pub ground_class: [bool; 256],
}

impl ClassSlots {
    /// Resolves the class names of the parameters against a table. A name the table lacks is
    /// left out (a weighted class counts 0), so that a site's table that lacks one class
    /// degrades the match instead of failing every update; only a table with none of the
    /// ground classes is an error (nothing to stand on, nothing to localize against). Callers
    /// that want to report what was left out resolve the names first (`spomp-robot` does, and
    /// reports them once).
    pub fn resolve(params: &LocalizationParams, table: &ClassTable) -> Result<Self, LocalizationError> {
        let mut ground_class = [false; 256];
        for info in params.ground_classes.iter().filter_map(|name| table.by_name(name)) {
            ground_class[info.index as usize] = true;
        }
        if !ground_class.contains(&true) {
            return Err(LocalizationError::UnknownClassName {
                name: params.ground_classes.join(", "),
                known: table.names().join(", "),
            });
        }
        let mut slots = ClassSlots {
            slot_of_class: [NO_SLOT; 256],
            weight: Vec::new(),
            is_ground: Vec::new(),
            class_of_slot: Vec::new(),
            ground_class,
        };
        for (name, &weight) in &params.class_weights {
            let Some(info) = table.by_name(name) else { continue };
            if weight <= 0.0 || info.ignored || info.index == UNKNOWN_CLASS {
                continue;
            }
            if slots.class_of_slot.len() == MAX_WEIGHTED_CLASSES {
                let n = params.class_weights.values().filter(|&&w| w > 0.0).count();
                return Err(LocalizationError::TooManyWeightedClasses(n));
            }
            slots.slot_of_class[info.index as usize] = slots.class_of_slot.len() as u8;
            slots.weight.push(weight as f32);
            slots.is_ground.push(ground_class[info.index as usize]);
            slots.class_of_slot.push(info.index);
        }
        Ok(slots)
    }

    /// Number of slots.
    pub fn len(&self) -> usize {
        self.class_of_slot.len()
    }
}

/// Cost planes of one aerial map version.
#[derive(Clone, Debug)]
pub(crate) struct MatchField {
    /// Placement of the map the planes were built from.
    pub spec: GridSpec,
    version: u64,
    fingerprint: u64,
    table: ClassTable,
    /// The classes used, with slots.
    pub slots: ClassSlots,
    /// Slot-major planes of cost levels, `slots.len() × spec.len()`.
    pub planes: Vec<u8>,
    /// Row-major indices of known cells of a ground class.
    pub ground_cells: Vec<u32>,
    /// Per slot, row-major indices of its cells (ground classes only; empty for the others).
    pub cells_of_slot: Vec<Vec<u32>>,
    /// Metres per cost level.
    pub metres_per_level: f32,
    /// Per slot, cost of a cell landing on unknown, metres.
    pub unknown_cost_m: Vec<f32>,
    /// A second fingerprint of the class layer, with another seed: two fields are shared only
    /// when both agree (a 128-bit check on contents).
    check: u64,
    /// The parameters the planes depend on.
    inputs: FieldInputs,
}

/// The parameters a [`MatchField`] is built from (the others do not change its planes).
#[derive(Clone, Debug, PartialEq)]
struct FieldInputs {
    ground_classes: Vec<String>,
    class_weights: BTreeMap<String, f64>,
    max_match_distance_m: f64,
    unknown_cost_factor: f64,
}

impl FieldInputs {
    fn of(params: &LocalizationParams) -> Self {
        FieldInputs {
            ground_classes: params.ground_classes.clone(),
            class_weights: params.class_weights.clone(),
            max_match_distance_m: params.max_match_distance_m,
            unknown_cost_factor: params.unknown_cost_factor,
        }
    }
}

/// Seed of the second fingerprint.
const CHECK_SEED: u64 = 0x243F_6A88_85A3_08D3;

/// Every match field alive in the process, so that localizers (robots of a team, trials run
/// side by side) holding the same map with the same parameters share one set of planes
/// instead of each building and holding its own: with a prior map, a team of UGVs starts with
/// one map, and a UAV's broadcast gives several robots the same version. A field is a pure
/// function of the map, the class table and [`FieldInputs`], so sharing changes no result.
static SHARED_FIELDS: SharedList<MatchField> = SharedList::new();

/// The match field of a map: one already alive somewhere in the process that was built from
/// the same placement, version, contents (two 64-bit fingerprints), class table and
/// parameters, or a new one (then offered to the others).
pub(crate) fn shared_field(
    map: &AerialMap,
    table: &ClassTable,
    params: &LocalizationParams,
    fingerprint: u64,
) -> Result<Arc<MatchField>, LocalizationError> {
    check_map(map)?;
    let check = spomp_raster::fingerprint(&map.class, CHECK_SEED);
    let inputs = FieldInputs::of(params);
    let same =
        |f: &MatchField| f.matches_fingerprint(map, table, fingerprint) && f.check == check && f.inputs == inputs;
    if let Some(field) = SHARED_FIELDS.find(same) {
        return Ok(field);
    }
    let field = Arc::new(MatchField::build_with_fingerprint(map, table, params, fingerprint)?);
    Ok(SHARED_FIELDS.share(field, same))
}

/// A fast fingerprint of the class layer, so that two maps with the same version number but
/// different contents are told apart.
pub(crate) fn fingerprint(classes: &[ClassId]) -> u64 {
    spomp_raster::fingerprint(classes, 0)
}

/// Checks that a map is well formed.
pub(crate) fn check_map(map: &AerialMap) -> Result<(), LocalizationError> {
    let spec = &map.spec;
    if spec.width == 0 || spec.height == 0 {
        return Err(LocalizationError::InvalidMap("the grid has no cells".into()));
    }
    if !(spec.resolution_m.is_finite() && spec.resolution_m > 0.0) {
        return Err(LocalizationError::InvalidMap(format!("resolution {} m is not positive", spec.resolution_m)));
    }
    if !(spec.origin.x.is_finite() && spec.origin.y.is_finite()) {
        return Err(LocalizationError::InvalidMap("origin is not finite".into()));
    }
    let cells = (spec.width as u64) * (spec.height as u64);
    if cells > u32::MAX as u64 {
        return Err(LocalizationError::InvalidMap("more than 2^32 cells".into()));
    }
    if map.class.len() as u64 != cells {
        return Err(LocalizationError::InvalidMap(format!(
            "class layer has {} values for {} cells",
            map.class.len(),
            cells
        )));
    }
    Ok(())
}

/// Squared Euclidean distance, in cells², from every cell to the nearest cell with a non-zero
/// mask value; `None` when the mask has no such cell.
fn squared_distances(edt: &mut SquaredEdt, mask: &[u8], spec: &GridSpec) -> Option<Vec<f64>> {
    if !mask.iter().any(|&m| m != 0) {
        return None;
    }
    Some(edt.of_mask(mask, spec.width as usize, spec.height as usize))
}

/// How a cell's distances to its class and to unknown ground become a cost level.
struct CostRule {
    res: f64,
    max_cost: f64,
    level_per_m: f64,
    unknown_cost_factor: f64,
    /// The smallest squared cell distance whose cost reaches `max_cost`, with the largest whole
    /// cell radius below it, when it is small enough for the bounded transform.
    bound: Option<DistanceBound>,
}

/// Squared distances of `limit` cells² or more all cost `max_cost`; `radius` is the largest
/// whole distance (cells) below the limit.
#[derive(Clone, Copy)]
struct DistanceBound {
    limit: u16,
    radius: usize,
}

/// Largest radius, cells, that the bounded distance transform handles (beyond it, or when the
/// squared limit passes 254, the planes are built with the whole-map transform).
const MAX_BOUNDED_RADIUS: usize = 16;

impl CostRule {
    fn new(res: f64, params: &LocalizationParams) -> Self {
        let max_cost = params.max_match_distance_m;
        let reaches_cap = |d2: u64| (d2 as f64).sqrt() * res >= max_cost;
        let cells = max_cost / res;
        let bound = if cells.is_finite() && cells < MAX_BOUNDED_RADIUS as f64 {
            // Both steps are monotonic in d², so the first d² that reaches the cap is the limit.
            let mut limit = ((cells * cells).floor() as u64).saturating_sub(2);
            while !reaches_cap(limit) {
                limit += 1;
            }
            while limit > 0 && reaches_cap(limit - 1) {
                limit -= 1;
            }
            let mut radius = 0usize;
            while ((radius + 1) * (radius + 1)) < limit as usize {
                radius += 1;
            }
            // Clamped distances and the unknown marker must fit in a byte.
            u16::try_from(limit).ok().filter(|&l| l < 255).map(|limit| DistanceBound { limit, radius })
        } else {
            None
        };
        CostRule {
            res,
            max_cost,
            level_per_m: MAX_KNOWN_LEVEL as f64 / max_cost,
            unknown_cost_factor: params.unknown_cost_factor,
            bound,
        }
    }

    /// Cost of a cell `d2` cells² from its class (∞: no cell of the class), metres.
    #[inline]
    fn to_class(&self, d2: f64) -> f64 {
        (d2.sqrt() * self.res).min(self.max_cost)
    }

    /// Level of a known cell `d2_class` cells² from its class and `d2_unknown` from unknown
    /// ground (∞: none).
    #[inline]
    fn level(&self, d2_class: f64, d2_unknown: f64, unknown_cost: f64) -> u8 {
        let via_unknown = d2_unknown.sqrt() * self.res + unknown_cost;
        let cost = self.to_class(d2_class).min(via_unknown);
        (cost * self.level_per_m).round().clamp(0.0, MAX_KNOWN_LEVEL as f64) as u8
    }
}

/// The planes with the whole-map distance transform (exact distances everywhere).
fn full_planes(map: &AerialMap, slots: &ClassSlots, costs: &CostRule) -> (Vec<u8>, Vec<f32>) {
    let spec = map.spec;
    let n = spec.len();
    let mut edt = SquaredEdt::default();
    let mut mask: Vec<u8> = map.class.iter().map(|&c| u8::from(c == UNKNOWN_CLASS)).collect();
    let unknown_d2 = squared_distances(&mut edt, &mask, &spec);
    let known_cells = map.class.iter().filter(|&&c| c != UNKNOWN_CLASS).count();

    let mut planes = vec![0u8; slots.len() * n];
    let mut unknown_cost_m = Vec::with_capacity(slots.len());
    for (slot, plane) in planes.chunks_exact_mut(n.max(1)).enumerate().take(slots.len()) {
        let class = slots.class_of_slot[slot];
        mask.iter_mut().zip(&map.class).for_each(|(m, &c)| *m = u8::from(c == class));
        let class_d2 = squared_distances(&mut edt, &mask, &spec);
        let d2_at = |d: &Option<Vec<f64>>, i: usize| d.as_ref().map_or(f64::INFINITY, |d| d[i]);
        // The cost of a random guess: the class's mean cost over the known map.
        let mean_known_cost = if known_cells == 0 {
            costs.max_cost
        } else {
            (0..n).filter(|&i| map.class[i] != UNKNOWN_CLASS).map(|i| costs.to_class(d2_at(&class_d2, i))).sum::<f64>()
                / known_cells as f64
        };
        let unknown_cost = costs.unknown_cost_factor * mean_known_cost;
        unknown_cost_m.push(unknown_cost as f32);
        for (i, level) in plane.iter_mut().enumerate() {
            *level = if map.class[i] == UNKNOWN_CLASS {
                UNKNOWN_COST_LEVEL
            } else {
                costs.level(d2_at(&class_d2, i), d2_at(&unknown_d2, i), unknown_cost)
            };
        }
    }
    (planes, unknown_cost_m)
}

/// The planes with distances computed only up to the cost cap: a squared distance at or past
/// the bound costs `max_cost` whatever its value (and so does a path through unknown ground
/// that long, as the unknown cost is not negative), so every level equals the whole-map
/// transform's. Levels come from a table over (class distance, unknown distance), filled
/// with the same arithmetic as [`full_planes`].
fn bounded_planes(map: &AerialMap, slots: &ClassSlots, costs: &CostRule, bound: DistanceBound) -> (Vec<u8>, Vec<f32>) {
    let spec = map.spec;
    let n = spec.len();
    let (width, height) = (spec.width as usize, spec.height as usize);
    let limit = bound.limit as usize;
    let mut scratch = BoundedEdt::new(width, height, bound);
    let mut unknown_d2 = vec![0u16; n];
    scratch.run(&map.class, |c| c == UNKNOWN_CLASS, &mut unknown_d2);
    let known_cells = map.class.iter().filter(|&&c| c != UNKNOWN_CLASS).count();
    // Past the limit: the class costs the cap, unknown ground is of no help.
    let d2_value = |d2: usize| if d2 >= limit { f64::INFINITY } else { d2 as f64 };
    // Per cell an index: its class distance clamped to the limit, or `unknown_index` for an
    // unknown cell.
    let unknown_index = limit + 1;
    let unknown_d2: Vec<u8> = unknown_d2.iter().map(|&d| d.min(limit as u16) as u8).collect();
    // Cost per index; an unknown cell adds −0, which leaves any sum as it is, so the sum over
    // all cells in order is the sum over the known cells in order without a branch.
    let mut to_class = [0.0f64; 256];
    for (d2, cost) in to_class.iter_mut().enumerate().take(unknown_index) {
        *cost = costs.to_class(d2_value(d2));
    }
    to_class[unknown_index] = -0.0;
    // `Sum` for floats is a fold of `+` from the sum of nothing.
    let empty_sum: f64 = std::iter::empty::<f64>().sum();

    let mut class_d2 = vec![0u16; n];
    let mut index = vec![0u8; n];
    let stride = limit + 1;
    let mut table = vec![UNKNOWN_COST_LEVEL; (unknown_index + 1) * stride];
    let mut planes = vec![0u8; slots.len() * n];
    let mut unknown_cost_m = Vec::with_capacity(slots.len());
    for (slot, plane) in planes.chunks_exact_mut(n.max(1)).enumerate().take(slots.len()) {
        let class = slots.class_of_slot[slot];
        scratch.run(&map.class, |c| c == class, &mut class_d2);
        let (limit_u16, unknown_u8) = (limit as u16, unknown_index as u8);
        for ((k, &c), &d) in index.iter_mut().zip(&map.class).zip(&class_d2) {
            let clamped = d.min(limit_u16) as u8;
            *k = if c == UNKNOWN_CLASS { unknown_u8 } else { clamped };
        }
        let mean_known_cost = if known_cells == 0 {
            costs.max_cost
        } else {
            index.iter().fold(empty_sum, |sum, &k| sum + to_class[k as usize]) / known_cells as f64
        };
        let unknown_cost = costs.unknown_cost_factor * mean_known_cost;
        unknown_cost_m.push(unknown_cost as f32);
        // Rows 0..=limit: known cells by class distance; the last row stays unknown.
        for (dc, row) in table.chunks_exact_mut(stride).enumerate().take(unknown_index) {
            for (du, level) in row.iter_mut().enumerate() {
                *level = costs.level(d2_value(dc), d2_value(du), unknown_cost);
            }
        }
        for ((level, &k), &du) in plane.iter_mut().zip(&index).zip(&unknown_d2) {
            *level = table.get(k as usize * stride + du as usize).copied().unwrap_or(UNKNOWN_COST_LEVEL);
        }
    }
    (planes, unknown_cost_m)
}

/// Squared Euclidean distance transform that is exact below a bound: a pass down the columns
/// (distance along the column to the nearest set cell, capped past the radius), then per row a
/// window of ±radius columns. Both passes run over whole rows of contiguous cells.
struct BoundedEdt {
    width: usize,
    height: usize,
    bound: DistanceBound,
    /// Per cell, squared distance along its column to the nearest set cell, capped.
    column_d2: Vec<i16>,
}

impl BoundedEdt {
    fn new(width: usize, height: usize, bound: DistanceBound) -> Self {
        BoundedEdt { width, height, bound, column_d2: vec![0; width * height] }
    }

    /// Fills `out` with each cell's squared distance (cells²) to the nearest cell whose class
    /// passes `is_set`: exact when below `bound.limit`, else some value ≥ the limit.
    fn run(&mut self, classes: &[ClassId], is_set: impl Fn(ClassId) -> bool, out: &mut [u16]) {
        let (w, h) = (self.width, self.height);
        let r = self.bound.radius;
        if w == 0 || h == 0 || classes.len() != w * h || out.len() != w * h || self.column_d2.len() != w * h {
            return;
        }
        // Any distance past the radius: its square reaches the limit.
        let far = (r + 1) as i16;
        let far_d2 = far * far;
        // Down the columns: distance to the nearest set cell above (capped at `far`)...
        let mut previous = vec![far; w];
        for (row_classes, row_d) in classes.chunks_exact(w).zip(self.column_d2.chunks_exact_mut(w)) {
            for ((&c, d), p) in row_classes.iter().zip(row_d.iter_mut()).zip(previous.iter_mut()) {
                *p = if is_set(c) { 0 } else { (*p + 1).min(far) };
                *d = *p;
            }
        }
        // ... then up, taking the nearer of the two and squaring it.
        previous.fill(far);
        for row_d in self.column_d2.chunks_exact_mut(w).rev() {
            for (d, p) in row_d.iter_mut().zip(previous.iter_mut()) {
                *p = if *d == 0 { 0 } else { (*p + 1).min(far) };
                let nearest = (*p).min(*d);
                *d = if nearest >= far { far_d2 } else { nearest * nearest };
            }
        }
        // Along the rows: the best column within ±radius.
        let mut acc = vec![0i16; w];
        for (row_d2, row_out) in self.column_d2.chunks_exact(w).zip(out.chunks_exact_mut(w)) {
            acc.copy_from_slice(row_d2);
            for dx in 1..=r.min(w - 1) {
                let step = (dx * dx) as i16;
                for (a, &s) in acc[dx..].iter_mut().zip(&row_d2[..w - dx]) {
                    *a = (*a).min(s + step);
                }
                for (a, &s) in acc[..w - dx].iter_mut().zip(&row_d2[dx..]) {
                    *a = (*a).min(s + step);
                }
            }
            for (o, &a) in row_out.iter_mut().zip(&acc) {
                *o = a as u16;
            }
        }
    }
}

impl MatchField {
    /// Whether these planes were built from this map and table.
    #[cfg(test)]
    pub fn matches(&self, map: &AerialMap, table: &ClassTable) -> bool {
        self.matches_fingerprint(map, table, fingerprint(&map.class))
    }

    /// [`Self::matches`] with the map's [`fingerprint`] already computed.
    pub fn matches_fingerprint(&self, map: &AerialMap, table: &ClassTable, fingerprint: u64) -> bool {
        self.spec == map.spec && self.version == map.version && self.table == *table && self.fingerprint == fingerprint
    }

    /// Whether these planes have the placement of this map and were built with this table:
    /// they can stand in for a newer version of the map for a while.
    pub fn same_layout(&self, map: &AerialMap, table: &ClassTable) -> bool {
        self.spec == map.spec && self.table == *table
    }

    /// Builds the planes of a map.
    #[cfg(test)]
    pub fn build(map: &AerialMap, table: &ClassTable, params: &LocalizationParams) -> Result<Self, LocalizationError> {
        Self::build_with_fingerprint(map, table, params, fingerprint(&map.class))
    }

    /// Builds the planes of a map whose [`fingerprint`] is already computed.
    pub fn build_with_fingerprint(
        map: &AerialMap,
        table: &ClassTable,
        params: &LocalizationParams,
        fingerprint: u64,
    ) -> Result<Self, LocalizationError> {
        check_map(map)?;
        let slots = ClassSlots::resolve(params, table)?;
        let spec = map.spec;
        let costs = CostRule::new(spec.resolution_m, params);
        let (planes, unknown_cost_m) = match costs.bound {
            Some(bound) => bounded_planes(map, &slots, &costs, bound),
            None => full_planes(map, &slots, &costs),
        };
        let ground_cells: Vec<u32> = map
            .class
            .iter()
            .enumerate()
            .filter(|&(_, &c)| c != UNKNOWN_CLASS && slots.ground_class[c as usize])
            .map(|(i, _)| i as u32)
            .collect();
        let mut cells_of_slot = vec![Vec::new(); slots.len()];
        for &i in &ground_cells {
            let slot = slots.slot_of_class[map.class[i as usize] as usize];
            if let Some(list) = cells_of_slot.get_mut(slot as usize) {
                list.push(i);
            }
        }

        Ok(MatchField {
            spec,
            version: map.version,
            fingerprint,
            table: table.clone(),
            slots,
            planes,
            ground_cells,
            cells_of_slot,
            metres_per_level: (params.max_match_distance_m / MAX_KNOWN_LEVEL as f64) as f32,
            unknown_cost_m,
            check: spomp_raster::fingerprint(&map.class, CHECK_SEED),
            inputs: FieldInputs::of(params),
        })
    }

    /// The cost plane of a slot.
    #[inline]
    pub fn plane(&self, slot: usize) -> &[u8] {
        let n = self.spec.len();
        self.planes.get(slot * n..(slot + 1) * n).unwrap_or(&[])
    }

    /// The cost in metres of an observed cell of a slot's class landing on a map cell.
    #[cfg(test)]
    pub fn cost_m(&self, slot: usize, col: u32, row: u32) -> f32 {
        let level = self.plane(slot)[self.spec.index(spomp_core::Cell::new(col, row))];
        if level == UNKNOWN_COST_LEVEL { self.unknown_cost_m[slot] } else { level as f32 * self.metres_per_level }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use spomp_core::Point2;

    fn table() -> ClassTable {
        ClassTable::default_table()
    }

    #[test]
    fn cost_is_distance_to_nearest_cell_of_the_class_capped() {
        let spec = GridSpec::new(Point2::new(0.0, 0.0), 0.5, 40, 5);
        let mut map = AerialMap::unknown(spec);
        map.class.iter_mut().for_each(|c| *c = 3); // grass everywhere
        map.class[spec.index(spomp_core::Cell::new(10, 2))] = 0; // one road cell
        let params = LocalizationParams::default();
        let field = MatchField::build(&map, &table(), &params).unwrap();
        let road = field.slots.slot_of_class[0] as usize;
        let grass = field.slots.slot_of_class[3] as usize;
        let tol = field.metres_per_level;
        assert!(field.cost_m(road, 10, 2).abs() <= tol);
        assert!((field.cost_m(road, 13, 2) - 1.5).abs() <= tol, "3 cells away: 1.5 m");
        assert!((field.cost_m(road, 13, 4) - (1.5f32.hypot(1.0))).abs() <= tol);
        assert!((field.cost_m(road, 39, 2) - 4.0).abs() <= tol, "capped at max_match_distance_m");
        assert!((field.cost_m(grass, 10, 2) - 0.5).abs() <= tol);
        assert!(field.cost_m(grass, 0, 0).abs() <= tol);
        // No class 2 (building) anywhere and no unknown: everything at the cap.
        let building = field.slots.slot_of_class[2] as usize;
        assert!((field.cost_m(building, 5, 1) - 4.0).abs() <= tol);
        assert_eq!(field.ground_cells.len(), spec.len());
    }

    #[test]
    fn unknown_cells_cost_a_random_guess_and_stand_in_for_any_class() {
        // Cell 0 road, cells 1..10 grass, cells 10..20 unknown.
        let spec = GridSpec::new(Point2::new(0.0, 0.0), 0.5, 20, 1);
        let mut map = AerialMap::unknown(spec);
        map.class[0] = 0;
        for c in 1..10 {
            map.class[c] = 3;
        }
        let params = LocalizationParams::default();
        let field = MatchField::build(&map, &table(), &params).unwrap();
        let road = field.slots.slot_of_class[0] as usize;
        let tol = field.metres_per_level;
        // Road costs over the known cells: 0, 0.5, …, 3.5, 4 (capped), 4 → mean 2.2 m.
        assert!((field.unknown_cost_m[road] - 2.2).abs() < 1e-5, "{}", field.unknown_cost_m[road]);
        assert!((field.cost_m(road, 15, 0) - 2.2).abs() < 1e-5);
        assert_eq!(field.plane(road)[15], UNKNOWN_COST_LEVEL);
        // Cell 9 is next to unknown cell 10: 0.5 m + 2.2 m beats the 4 m to the road.
        assert!((field.cost_m(road, 9, 0) - 2.7).abs() <= tol);
        assert!((field.cost_m(road, 7, 0) - 3.5).abs() <= tol);
        assert!(field.cost_m(road, 0, 0).abs() <= tol);
        assert_eq!(field.cells_of_slot[road], vec![0]);
        assert_eq!(field.cells_of_slot[field.slots.slot_of_class[3] as usize].len(), 9);
    }

    /// The bounded transform gives the planes and random-guess costs of the whole-map one, bit
    /// for bit, on random maps with unknown patches, at several caps and resolutions.
    #[test]
    fn bounded_planes_equal_the_whole_map_transform() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        let table = table();
        for case in 0..24 {
            let (w, h) = (rng.random_range(1..70u32), rng.random_range(1..50u32));
            let res = [0.5, 0.25, 0.3, 1.0, 0.1][case % 5];
            let spec = GridSpec::new(Point2::new(0.0, 0.0), res, w, h);
            let mut map = AerialMap::unknown(spec);
            let sparse = case % 3 == 0;
            for c in map.class.iter_mut() {
                *c = if rng.random_bool(0.15) {
                    UNKNOWN_CLASS
                } else if sparse {
                    if rng.random_bool(0.02) { rng.random_range(0..8) } else { 3 }
                } else {
                    rng.random_range(0..8)
                };
            }
            // Blobs of unknown, as the aerial map has.
            for _ in 0..3 {
                let (cx, cy) = (rng.random_range(0..w), rng.random_range(0..h));
                for row in cy.saturating_sub(6)..(cy + 6).min(h) {
                    for col in cx.saturating_sub(6)..(cx + 6).min(w) {
                        map.class[spec.index(spomp_core::Cell::new(col, row))] = UNKNOWN_CLASS;
                    }
                }
            }
            let params = LocalizationParams {
                max_match_distance_m: [4.0, 2.0, 3.3, 0.7, 1.2][case % 5],
                unknown_cost_factor: [1.0, 0.0, 0.4, 2.5][case % 4],
                ..Default::default()
            };
            let slots = ClassSlots::resolve(&params, &table).unwrap();
            let costs = CostRule::new(res, &params);
            let bound = costs.bound.expect("small caps use the bounded transform");
            let bounded = bounded_planes(&map, &slots, &costs, bound);
            let full = full_planes(&map, &slots, &costs);
            assert_eq!(bounded.1, full.1, "case {case}: random-guess costs");
            assert!(bounded.0 == full.0, "case {case}: planes differ");
        }
    }

    #[test]
    fn fingerprint_tells_contents_apart_and_rejects_bad_maps() {
        let spec = GridSpec::new(Point2::new(0.0, 0.0), 0.5, 9, 3);
        let a = AerialMap::unknown(spec);
        let mut b = a.clone();
        b.class[26] = 0;
        let params = LocalizationParams::default();
        let field = MatchField::build(&a, &table(), &params).unwrap();
        assert!(field.matches(&a, &table()));
        assert!(!field.matches(&b, &table()));
        let mut broken = a.clone();
        broken.class.pop();
        assert!(matches!(MatchField::build(&broken, &table(), &params), Err(LocalizationError::InvalidMap(_))));
        let bad_names = LocalizationParams { ground_classes: vec!["lava".into()], ..Default::default() };
        assert!(matches!(MatchField::build(&a, &table(), &bad_names), Err(LocalizationError::UnknownClassName { .. })));
    }

    #[test]
    fn a_table_that_lacks_some_classes_degrades_the_match_instead_of_failing() {
        let params = LocalizationParams {
            ground_classes: vec!["road".into(), "lava".into()],
            class_weights: [("road".to_string(), 1.0), ("building".to_string(), 1.5), ("unobtainium".to_string(), 2.0)]
                .into_iter()
                .collect(),
            ..Default::default()
        };
        let slots = ClassSlots::resolve(&params, &table()).unwrap();
        assert_eq!(slots.len(), 2, "the missing class has no slot (weight 0)");
        assert!(slots.ground_class[table().by_name("road").unwrap().index as usize]);
    }
}
