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

use image::GrayImage;
use imageproc::distance_transform::euclidean_squared_distance_transform;
use spomp_core::{AerialMap, ClassId, ClassTable, GridSpec, UNKNOWN_CLASS};

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
    /// Resolves the class names of the parameters against a table.
    pub fn resolve(params: &LocalizationParams, table: &ClassTable) -> Result<Self, LocalizationError> {
        let unknown = |name: &str| LocalizationError::UnknownClassName {
            name: name.to_string(),
            known: table.names().join(", "),
        };
        let mut ground_class = [false; 256];
        for name in &params.ground_classes {
            let info = table.by_name(name).ok_or_else(|| unknown(name))?;
            ground_class[info.index as usize] = true;
        }
        let mut slots = ClassSlots {
            slot_of_class: [NO_SLOT; 256],
            weight: Vec::new(),
            is_ground: Vec::new(),
            class_of_slot: Vec::new(),
            ground_class,
        };
        for (name, &weight) in &params.class_weights {
            let info = table.by_name(name).ok_or_else(|| unknown(name))?;
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
}

/// A fast fingerprint of the class layer, so that two maps with the same version number but
/// different contents are told apart.
fn fingerprint(classes: &[ClassId]) -> u64 {
    const K: u64 = 0x9E37_79B9_7F4A_7C15;
    // Four independent lanes so the multiplies overlap: this runs on every update.
    let mut lanes = [K ^ classes.len() as u64, K.rotate_left(16), K.rotate_left(32), K.rotate_left(48)];
    let mut blocks = classes.chunks_exact(32);
    for block in &mut blocks {
        for (lane, word) in lanes.iter_mut().zip(block.chunks_exact(8)) {
            let mut bytes = [0u8; 8];
            bytes.copy_from_slice(word);
            *lane = (*lane ^ u64::from_le_bytes(bytes)).wrapping_mul(K).rotate_left(31);
        }
    }
    let mut h = lanes.iter().fold(0u64, |acc, &l| (acc ^ l).wrapping_mul(K).rotate_left(27));
    for &b in blocks.remainder() {
        h = (h ^ b as u64).wrapping_mul(K).rotate_left(5);
    }
    h
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
fn squared_distances(mask: Vec<u8>, spec: &GridSpec) -> Option<Vec<f64>> {
    if !mask.iter().any(|&m| m != 0) {
        return None;
    }
    // Row order does not matter for a distance transform, so the grid's south-up rows can be
    // handed over as an image's top-down rows unchanged.
    let image = GrayImage::from_raw(spec.width, spec.height, mask)?;
    Some(euclidean_squared_distance_transform(&image).into_raw())
}

impl MatchField {
    /// Whether these planes were built from this map and table.
    pub fn matches(&self, map: &AerialMap, table: &ClassTable) -> bool {
        self.spec == map.spec
            && self.version == map.version
            && self.table == *table
            && self.fingerprint == fingerprint(&map.class)
    }

    /// Whether these planes have the placement of this map and were built with this table:
    /// they can stand in for a newer version of the map for a while.
    pub fn same_layout(&self, map: &AerialMap, table: &ClassTable) -> bool {
        self.spec == map.spec && self.table == *table
    }

    /// Builds the planes of a map.
    pub fn build(map: &AerialMap, table: &ClassTable, params: &LocalizationParams) -> Result<Self, LocalizationError> {
        check_map(map)?;
        let slots = ClassSlots::resolve(params, table)?;
        let spec = map.spec;
        let n = spec.len();
        let res = spec.resolution_m;
        let max_cost = params.max_match_distance_m;
        let level_per_m = MAX_KNOWN_LEVEL as f64 / max_cost;

        let unknown_mask: Vec<u8> = map.class.iter().map(|&c| u8::from(c == UNKNOWN_CLASS)).collect();
        let unknown_d2 = squared_distances(unknown_mask, &spec);
        let known_cells = map.class.iter().filter(|&&c| c != UNKNOWN_CLASS).count();

        let mut planes = vec![0u8; slots.len() * n];
        let mut unknown_cost_m = Vec::with_capacity(slots.len());
        for (slot, plane) in planes.chunks_exact_mut(n.max(1)).enumerate().take(slots.len()) {
            let class = slots.class_of_slot[slot];
            let mask: Vec<u8> = map.class.iter().map(|&c| u8::from(c == class)).collect();
            let class_d2 = squared_distances(mask, &spec);
            let to_class = |i: usize| class_d2.as_ref().map_or(f64::INFINITY, |d| d[i].sqrt() * res).min(max_cost);
            // The cost of a random guess: the class's mean cost over the known map.
            let mean_known_cost = if known_cells == 0 {
                max_cost
            } else {
                (0..n).filter(|&i| map.class[i] != UNKNOWN_CLASS).map(to_class).sum::<f64>() / known_cells as f64
            };
            let unknown_cost = params.unknown_cost_factor * mean_known_cost;
            unknown_cost_m.push(unknown_cost as f32);
            for (i, level) in plane.iter_mut().enumerate() {
                if map.class[i] == UNKNOWN_CLASS {
                    *level = UNKNOWN_COST_LEVEL;
                    continue;
                }
                let via_unknown = unknown_d2.as_ref().map_or(f64::INFINITY, |d| d[i].sqrt() * res + unknown_cost);
                let cost = to_class(i).min(via_unknown);
                *level = (cost * level_per_m).round().clamp(0.0, MAX_KNOWN_LEVEL as f64) as u8;
            }
        }

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
            fingerprint: fingerprint(&map.class),
            table: table.clone(),
            slots,
            planes,
            ground_cells,
            cells_of_slot,
            metres_per_level: (max_cost / MAX_KNOWN_LEVEL as f64) as f32,
            unknown_cost_m,
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
}
