//! Goal detection in the aerial class map (paper §High-Level Coordination, docs/design.md §5).
//!
//! 1. Binary mask of the goal class.
//! 2. Morphological open (removes specks), then close (dilate, erode) with a disk of half the
//!    merge distance. docs/design.md fixes this order (the paper's text says close then open).
//! 3. Clusters: 8-connected components of the *dilated* mask (the first half of the close), so
//!    that blobs whose gap is at most the merge distance join; closing alone would not join
//!    thin objects such as a row of cars, because the eroding disk fits through the gap beside
//!    them. Each cluster is the closed mask within one such component; it counts if the larger
//!    side of its bounding box is at least the minimum size. One goal per cluster.
//! 4. Placement: among known cells within the placement region of the component that are not
//!    obstacles (impassable rank, unknown, or the goal class itself), try classes from easiest
//!    to hardest rank; the first class with a cell at least `min_clearance_m` from every
//!    obstacle gives the goal, at its cell farthest from obstacles (Euclidean distance
//!    transform). Without such a cell the clearest admissible cell of any class is used.
//! 5. Goals within the deconfliction radius of a known goal, or of a goal detected before them
//!    in the same pass, are dropped.

use std::sync::Arc;

use image::{GrayImage, Luma};
use imageproc::distance_transform::Norm;
use imageproc::morphology::{dilate, erode, open_mut};
use imageproc::region_labelling::{Connectivity, connected_components};
use spomp_core::{AerialMap, Cell, ClassId, ClassTable, GridSpec, Point2, UNKNOWN_CLASS};
use spomp_raster::{SharedList, SquaredEdt};

use crate::error::MappingError;
use crate::params::GoalDetectionParams;

/// A goal found in the map.
#[derive(Clone, Debug, PartialEq)]
pub struct DetectedGoal {
    /// Map-frame position (cell centre).
    pub position: Point2,
    /// The cell.
    pub cell: Cell,
    /// Class of the cell the goal is on.
    pub class: ClassId,
    /// Distance from the goal to the nearest obstacle, metres.
    pub clearance_m: f64,
    /// Centroid of the cluster (after merging).
    pub cluster_centroid: Point2,
    /// Larger side of the cluster's bounding box, metres.
    pub cluster_size_m: f64,
    /// Cells of goal class inside the cluster.
    pub class_cells: usize,
}

/// What one detection pass found.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Detection {
    /// New goals, in raster order of their clusters.
    pub goals: Vec<DetectedGoal>,
    /// Clusters smaller than the minimum size.
    pub too_small: usize,
    /// Clusters with no admissible cell in their placement region.
    pub unplaceable: usize,
    /// Goals dropped because a known (or earlier detected) goal is within the deconfliction
    /// radius.
    pub duplicates: usize,
}

/// The goals a map holds before deconfliction (steps 1–4), in raster order of their clusters:
/// a pure function of the class layer, its placement and the detector's setup.
#[derive(Debug)]
struct Candidates {
    /// What they were found from.
    key: CandidatesKey,
    found: Found,
}

/// What steps 1–4 found in a map.
#[derive(Debug, Default)]
struct Found {
    goals: Vec<DetectedGoal>,
    too_small: usize,
    unplaceable: usize,
}

/// What a set of [`Candidates`] was found from: two sets with equal keys are equal.
#[derive(Clone, Debug, PartialEq)]
struct CandidatesKey {
    spec: GridSpec,
    /// Fingerprints of the class layer under [`CONTENT_SEEDS`].
    content: [u64; 2],
    setup: DetectorSetup,
}

/// A detector's setup: its parameters and what it resolved from the class table.
#[derive(Clone, Debug, PartialEq)]
struct DetectorSetup {
    params: GoalDetectionParams,
    target: ClassId,
    placement_order: Vec<ClassId>,
    obstacle_lut: [bool; 256],
}

/// Seeds of the two independent class-layer fingerprints of a [`CandidatesKey`].
const CONTENT_SEEDS: [u64; 2] = [0x1F83_D9AB_FB41_BD6B, 0x5BE0_CD19_137E_2179];

/// Every set of candidates alive in the process, found by what it was found from: the robots
/// of a team (and trials run side by side) receive the same map versions from the UAV, and
/// each ran the whole detection on each of them (about 3 % of a simulated team's run). The
/// candidates are a pure function of the key, so sharing them changes no result.
static SHARED_CANDIDATES: SharedList<Candidates> = SharedList::new();

/// Per-component statistics gathered in one raster pass.
#[derive(Clone, Copy, Debug)]
struct Component {
    min_c: u32,
    min_r: u32,
    max_c: u32,
    max_r: u32,
    cells: usize,
    class_cells: usize,
    sum_c: f64,
    sum_r: f64,
}

/// Finds goals in aerial maps. Holds the resolved class and rank tables and reusable buffers.
#[derive(Clone, Debug)]
pub struct GoalDetector {
    params: GoalDetectionParams,
    target: ClassId,
    /// Candidate classes for placement, easiest first.
    placement_order: Vec<ClassId>,
    /// Obstacle flag per class index (impassable rank, unknown, the target class).
    obstacle_lut: [bool; 256],
    /// Scratch: component statistics.
    components: Vec<Component>,
    /// Scratch: the distance transform's buffers (map-sized; given back after each pass).
    edt: SquaredEdt,
    /// The candidates of the last pass, kept so that other detectors can share them.
    last: Option<Arc<Candidates>>,
}

impl GoalDetector {
    /// A detector for `params.class` from `classes`.
    pub fn new(params: GoalDetectionParams, classes: &ClassTable) -> Result<Self, MappingError> {
        params.validate()?;
        let target = classes
            .by_name(&params.class)
            .ok_or_else(|| MappingError::UnknownClass {
                name: params.class.clone(),
                known: classes.names().join(", "),
            })?
            .index;
        let rank = classes.rank_lut();
        let impassable = spomp_core::classes::IMPASSABLE_RANK;
        let mut obstacle_lut = [false; 256];
        for (i, flag) in obstacle_lut.iter_mut().enumerate() {
            *flag = rank[i] >= impassable || i == target as usize || i == UNKNOWN_CLASS as usize;
        }
        let placement_order = classes.easiest_first().into_iter().filter(|&c| !obstacle_lut[c as usize]).collect();
        Ok(GoalDetector {
            params,
            target,
            placement_order,
            obstacle_lut,
            components: Vec::new(),
            edt: SquaredEdt::default(),
            last: None,
        })
    }

    /// The parameters.
    pub fn params(&self) -> &GoalDetectionParams {
        &self.params
    }

    /// Detects goals in `map`, dropping those within the deconfliction radius of `known_goals`
    /// (and of a goal detected before them in the same pass).
    pub fn detect(&mut self, map: &AerialMap, known_goals: &[Point2]) -> Result<Detection, MappingError> {
        let candidates = self.shared_candidates(map)?;
        let radius = self.params.deconfliction_radius_m;
        let found = &candidates.found;
        let mut detection =
            Detection { too_small: found.too_small, unplaceable: found.unplaceable, ..Detection::default() };
        let mut accepted: Vec<Point2> = Vec::new();
        for goal in &found.goals {
            if known_goals.iter().chain(&accepted).any(|g| g.distance(goal.position) <= radius) {
                detection.duplicates += 1;
                continue;
            }
            accepted.push(goal.position);
            detection.goals.push(goal.clone());
        }
        self.last = Some(candidates);
        Ok(detection)
    }

    /// The candidates of `map`: those another detector in the process already found for the
    /// same class layer with the same setup, or found now (then offered to the others).
    fn shared_candidates(&mut self, map: &AerialMap) -> Result<Arc<Candidates>, MappingError> {
        let key = CandidatesKey {
            spec: map.spec,
            content: CONTENT_SEEDS.map(|seed| spomp_raster::fingerprint(&map.class, seed)),
            setup: self.setup(),
        };
        if let Some(shared) = SHARED_CANDIDATES.find(|c| c.key == key) {
            return Ok(shared);
        }
        let found = self.find_candidates(map);
        // The distance transform's buffers are map-sized; a pass runs only when the map
        // changes, and every robot of a team holds a detector.
        self.edt = SquaredEdt::default();
        let candidates = Arc::new(Candidates { key: key.clone(), found: found? });
        Ok(SHARED_CANDIDATES.share(candidates, |c| c.key == key))
    }

    /// What, besides the map, the candidates depend on.
    fn setup(&self) -> DetectorSetup {
        DetectorSetup {
            params: self.params.clone(),
            target: self.target,
            placement_order: self.placement_order.clone(),
            obstacle_lut: self.obstacle_lut,
        }
    }

    /// Whether this detector's last pass used the same candidates (found once) as `other`'s.
    #[cfg(test)]
    fn shares_last_candidates_with(&self, other: &GoalDetector) -> bool {
        self.last.as_ref().zip(other.last.as_ref()).is_some_and(|(a, b)| Arc::ptr_eq(a, b))
    }

    fn find_candidates(&mut self, map: &AerialMap) -> Result<Found, MappingError> {
        let spec = map.spec;
        let (w, h) = (spec.width, spec.height);
        if map.class.len() != spec.len() {
            return Err(MappingError::InconsistentMap("class layer does not match the grid".into()));
        }
        let res = spec.resolution_m;
        if !(res.is_finite() && res > 0.0) {
            return Err(MappingError::InconsistentMap(format!("resolution {res} m")));
        }
        let mut found = Found::default();
        // A goal is placed on a passable cell beside a cluster, so a one-cell map has none (and
        // imageproc's labelling indexes past its forest on a lone foreground pixel).
        if spec.is_empty() || spec.len() == 1 {
            return Ok(found);
        }

        // 1–2. Class mask, open, close.
        let mask: Vec<u8> = map.class.iter().map(|&c| if c == self.target { 255 } else { 0 }).collect();
        let Some(mut mask) = GrayImage::from_raw(w, h, mask) else {
            return Err(MappingError::InconsistentMap("grid too large".into()));
        };
        let to_px = |m: f64| (m / res).round().clamp(0.0, 255.0) as u8;
        let open_px = to_px(self.params.open_radius_m);
        if open_px > 0 {
            // imageproc rounds L2 distances up, so for radii ≤ 2 L1 gives the same disk and its
            // integer two-pass transform is much cheaper than the exact Euclidean one.
            let norm = if open_px <= 2 { Norm::L1 } else { Norm::L2 };
            open_mut(&mut mask, norm, open_px);
        }
        let close_px = to_px(self.params.merge_distance_m / 2.0);
        let (dilated, closed) = if close_px > 0 {
            let dilated = dilate(&mask, Norm::L2, close_px);
            let closed = erode(&dilated, Norm::L2, close_px);
            (dilated, closed)
        } else {
            (mask.clone(), mask)
        };

        // 3. Clusters: components of the dilated mask, restricted to the closed mask.
        let labels = connected_components(&dilated, Connectivity::Eight, Luma([0u8]));
        self.components.clear();
        for (i, (&label, &inside)) in labels.as_raw().iter().zip(closed.as_raw()).enumerate() {
            if label == 0 || inside == 0 {
                continue;
            }
            let (c, r) = ((i % w as usize) as u32, (i / w as usize) as u32);
            let k = label as usize - 1;
            if self.components.len() <= k {
                let empty = Component {
                    min_c: u32::MAX,
                    min_r: u32::MAX,
                    max_c: 0,
                    max_r: 0,
                    cells: 0,
                    class_cells: 0,
                    sum_c: 0.0,
                    sum_r: 0.0,
                };
                self.components.resize(k + 1, empty);
            }
            let comp = &mut self.components[k];
            comp.min_c = comp.min_c.min(c);
            comp.min_r = comp.min_r.min(r);
            comp.max_c = comp.max_c.max(c);
            comp.max_r = comp.max_r.max(r);
            comp.cells += 1;
            comp.class_cells += usize::from(map.class.get(i) == Some(&self.target));
            comp.sum_c += c as f64;
            comp.sum_r += r as f64;
        }
        if self.components.iter().all(|c| c.cells == 0) {
            return Ok(found);
        }

        // Clearance: distance from every cell to the nearest obstacle.
        let obstacles: Vec<u8> =
            map.class.iter().map(|&c| if self.obstacle_lut[c as usize] { 255 } else { 0 }).collect();
        let clearance_sq = self.edt.of_mask(&obstacles, w as usize, h as usize);

        let region_px = self.params.placement_region_m / res;
        let margin = region_px.ceil() as i64 + 1;
        let min_clear_sq = (self.params.min_clearance_m / res).powi(2);

        for (k, comp) in self.components.iter().enumerate() {
            if comp.cells == 0 {
                continue;
            }
            let size_m = ((comp.max_c - comp.min_c).max(comp.max_r - comp.min_r) + 1) as f64 * res;
            if size_m < self.params.min_size_m {
                found.too_small += 1;
                continue;
            }
            let label = k as u32 + 1;
            // Crop around the component, grown by the placement region.
            let c0 = (comp.min_c as i64 - margin).max(0) as u32;
            let r0 = (comp.min_r as i64 - margin).max(0) as u32;
            let c1 = (comp.max_c as i64 + margin).min(w as i64 - 1) as u32;
            let r1 = (comp.max_r as i64 + margin).min(h as i64 - 1) as u32;
            let (cw, ch) = (c1 - c0 + 1, r1 - r0 + 1);
            let crop = GrayImage::from_fn(cw, ch, |x, y| {
                let member = labels.get_pixel(x + c0, y + r0)[0] == label && closed.get_pixel(x + c0, y + r0)[0] != 0;
                Luma([if member { 255 } else { 0 }])
            });
            let to_cluster_sq = self.edt.of_mask(crop.as_raw(), cw as usize, ch as usize);
            let centroid = (comp.sum_c / comp.cells as f64, comp.sum_r / comp.cells as f64);

            // Best cell per class: (clearance², −distance² to centroid, cell) maximised.
            let mut best: Vec<Option<(f64, f64, Cell)>> = vec![None; self.placement_order.len()];
            for y in 0..ch {
                for x in 0..cw {
                    let to_cluster = to_cluster_sq.get(y as usize * cw as usize + x as usize).copied();
                    if to_cluster.is_none_or(|d| d > region_px * region_px) {
                        continue;
                    }
                    let (c, r) = (x + c0, y + r0);
                    let i = r as usize * w as usize + c as usize;
                    let class = map.class.get(i).copied().unwrap_or(UNKNOWN_CLASS);
                    let Some(slot) = self.placement_order.iter().position(|&p| p == class) else {
                        continue;
                    };
                    let clear = clearance_sq.get(i).copied().unwrap_or(0.0);
                    let d_centroid = (c as f64 - centroid.0).powi(2) + (r as f64 - centroid.1).powi(2);
                    let better = match best[slot] {
                        None => true,
                        Some((bc, bd, _)) => clear > bc || (clear == bc && d_centroid < bd),
                    };
                    if better {
                        best[slot] = Some((clear, d_centroid, Cell::new(c, r)));
                    }
                }
            }
            let chosen = best
                .iter()
                .flatten()
                .find(|b| b.0 >= min_clear_sq)
                .or_else(|| best.iter().flatten().max_by(|a, b| a.0.total_cmp(&b.0).then_with(|| b.1.total_cmp(&a.1))))
                .copied();
            let Some((clear_sq, _, cell)) = chosen else {
                found.unplaceable += 1;
                continue;
            };
            let position = spec.center(cell);
            let class = map.class_at(cell);
            found.goals.push(DetectedGoal {
                position,
                cell,
                class,
                clearance_m: clear_sq.sqrt() * res,
                cluster_centroid: Point2::new(
                    spec.origin.x + (centroid.0 + 0.5) * res,
                    spec.origin.y + (centroid.1 + 0.5) * res,
                ),
                cluster_size_m: size_m,
                class_cells: comp.class_cells,
            });
        }
        Ok(found)
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;
    use crate::params::GoalDetectionParams;
    use spomp_core::GridSpec;

    /// A 100 × 60 m road map with two rows of four vehicles 50 m apart.
    fn parking(table: &ClassTable) -> AerialMap {
        let (road, vehicle) = (table.by_name("road").unwrap().index, table.by_name("vehicle").unwrap().index);
        let mut map = AerialMap::unknown(GridSpec::new(Point2::new(0.0, 0.0), 0.5, 200, 120));
        map.class.fill(road);
        for x0 in [10.0, 60.0] {
            for k in 0..4 {
                let x = x0 + k as f64 * 6.0;
                for r in 60..64 {
                    for c in (x / 0.5) as usize..((x + 4.5) / 0.5) as usize {
                        map.class[r * 200 + c] = vehicle;
                    }
                }
            }
        }
        map.version = 3;
        map
    }

    #[test]
    fn detectors_share_the_candidates_of_one_map_and_deconflict_each_against_its_own_goals() {
        let table = ClassTable::default_table();
        let map = parking(&table);
        let (mut a, mut b) = (
            GoalDetector::new(GoalDetectionParams::default(), &table).unwrap(),
            GoalDetector::new(GoalDetectionParams::default(), &table).unwrap(),
        );
        let all = a.detect(&map, &[]).unwrap();
        assert_eq!(all.goals.len(), 2, "{all:?}");
        // Another robot's copy of the same map, with one of the goals already known.
        let copy = map.clone();
        let known = [all.goals[0].position];
        let some = b.detect(&copy, &known).unwrap();
        assert!(a.shares_last_candidates_with(&b), "the second detection reused the first's candidates");
        assert_eq!((some.goals.len(), some.duplicates), (1, 1));
        assert_eq!(some.goals[0], all.goals[1]);
        // The same result as a detector that found everything itself.
        let mut fresh = GoalDetector::new(GoalDetectionParams::default(), &table).unwrap();
        let own = fresh.find_candidates(&map).unwrap();
        assert_eq!(own.goals, all.goals);
    }

    #[test]
    fn another_class_layer_or_setup_is_never_served_shared_candidates() {
        let table = ClassTable::default_table();
        let map = parking(&table);
        let mut a = GoalDetector::new(GoalDetectionParams::default(), &table).unwrap();
        let before = a.detect(&map, &[]).unwrap();
        // Same version, one vehicle paved over: one cluster's goal moves (or goes).
        let mut changed = map.clone();
        let road = table.by_name("road").unwrap().index;
        for r in 60..64 {
            for c in 20..80 {
                changed.class[r * 200 + c] = road;
            }
        }
        let mut b = GoalDetector::new(GoalDetectionParams::default(), &table).unwrap();
        let after = b.detect(&changed, &[]).unwrap();
        assert!(!a.shares_last_candidates_with(&b));
        assert_ne!(after, before);
        assert_eq!(after.goals, b.find_candidates(&changed).unwrap().goals);
        // Same map, other parameters.
        let wide = GoalDetectionParams { merge_distance_m: 60.0, ..GoalDetectionParams::default() };
        let mut c = GoalDetector::new(wide, &table).unwrap();
        let merged = c.detect(&map, &[]).unwrap();
        assert!(!a.shares_last_candidates_with(&c));
        assert_eq!(merged.goals.len(), 1, "the two rows are one cluster at a 60 m merge distance");
    }
}
