//! Scoring poses against the cost planes: the hot loop of the filter.
//!
//! Poses are grouped by heading bin; for each bin the observed cells are rotated once into
//! integer cell offsets, and every pose of the bin then only adds its own cell index and
//! gathers one byte per observed cell. The bin width is chosen so that the farthest observed
//! cell moves by at most half a cell across a bin; the pose's position is taken at the centre
//! of its map cell. Both quantisations stay below the map's own resolution.
//!
//! A score is therefore a function of (heading bin, map cell) alone, and a tracking cloud puts
//! many of its particles in the same few cells and bins: poses are sorted by bin and then by
//! cell, and a pose on the cell of the one before it takes that pose's score (the same sums in
//! the same order, so the same bits) instead of gathering again.

use std::f64::consts::TAU;

#[cfg(test)]
use spomp_core::Pose2;

use crate::field::{MatchField, UNKNOWN_COST_LEVEL};
use crate::filter::Particle;
use crate::observation::LocalObservation;

/// How well one pose explains the local observation.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub(crate) struct PoseScore {
    /// Σ weight · cost, metres.
    pub weighted_cost: f64,
    /// Σ weight over cells landing on known aerial cells.
    pub known_weight: f64,
    /// Σ weight over known-landing cells whose cost is within the agreement distance.
    pub agree_weight: f64,
}

/// Cell coordinates are clamped to this magnitude so that offset arithmetic cannot overflow.
const MAX_CELL_COORD: f64 = (1u64 << 40) as f64;

/// Scratch space for scoring, reused across calls.
#[derive(Clone, Debug, Default)]
pub(crate) struct Scorer {
    /// (heading bin, map cell, pose index), sorted: poses on the same bin and cell score alike.
    keyed: Vec<(u32, PoseCell, u32)>,
    /// Rotated integer offsets (cols, rows) of the observed cells for the current bin.
    offsets: Vec<(i32, i32)>,
    /// The same offsets as row-major index offsets.
    linear: Vec<i64>,
}

/// The map cell a pose stands in (row, column; clamped to [`MAX_CELL_COORD`]), or
/// [`PoseCell::NOWHERE`] for a non-finite position. Ordered by row first, like the map.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
struct PoseCell(i64, i64);

impl PoseCell {
    /// A pose whose position is not finite: every cell lands on unknown.
    const NOWHERE: PoseCell = PoseCell(i64::MAX, i64::MAX);
}

/// Sums of one class run.
#[derive(Clone, Copy, Default)]
struct RunSums {
    levels: u32,
    unknown: u32,
    agree: u32,
}

impl RunSums {
    #[inline]
    fn add(&mut self, level: u8, agree_level: u8) {
        self.levels += level as u32;
        self.unknown += u32::from(level == UNKNOWN_COST_LEVEL);
        self.agree += u32::from(level <= agree_level);
    }
}

/// The three sums of a run packed in one `u64` (levels in the low 24 bits, then 20 bits each
/// of unknown and agreeing cells), so that a cell costs one table lookup and one add. Runs of
/// at most [`MAX_PACKED_RUN`] cells cannot carry from one field into the next.
struct PackedLevels {
    /// Per level, its increment of the packed sums.
    increment: [u64; 256],
}

const PACKED_LEVEL_BITS: u32 = 24;
const PACKED_COUNT_BITS: u32 = 20;
/// 65536 × 255 < 2^24 and 65536 < 2^20.
const MAX_PACKED_RUN: usize = 1 << 16;

impl PackedLevels {
    fn new(agree_level: u8) -> Self {
        let mut increment = [0u64; 256];
        for (level, inc) in increment.iter_mut().enumerate() {
            let unknown = u64::from(level == UNKNOWN_COST_LEVEL as usize);
            let agree = u64::from(level <= agree_level as usize);
            *inc = level as u64 | unknown << PACKED_LEVEL_BITS | agree << (PACKED_LEVEL_BITS + PACKED_COUNT_BITS);
        }
        PackedLevels { increment }
    }

    #[inline]
    fn unpack(packed: u64) -> RunSums {
        let count_mask = (1u64 << PACKED_COUNT_BITS) - 1;
        RunSums {
            levels: (packed & ((1u64 << PACKED_LEVEL_BITS) - 1)) as u32,
            unknown: ((packed >> PACKED_LEVEL_BITS) & count_mask) as u32,
            agree: ((packed >> (PACKED_LEVEL_BITS + PACKED_COUNT_BITS)) & count_mask) as u32,
        }
    }
}

impl Scorer {
    /// Scores every pose; `out[i]` belongs to `poses[i]`.
    pub fn score_all(
        &mut self,
        field: &MatchField,
        obs: &LocalObservation,
        poses: &[Particle],
        agree_level: u8,
        out: &mut Vec<PoseScore>,
    ) {
        out.clear();
        out.resize(poses.len(), PoseScore::default());
        if obs.is_empty() || poses.is_empty() {
            return;
        }
        let reach = obs.cells.iter().map(|c| c.x.hypot(c.y)).fold(1.0f32, f32::max) as f64;
        // Farthest cell moves ≤ ½ cell across a bin: bin width 0.5 / reach radians.
        let bins = ((TAU * reach / 0.5).ceil() as usize).clamp(8, 1 << 20);
        let bin_width = TAU / bins as f64;
        let spec = &field.spec;
        let inv_res = 1.0 / spec.resolution_m;
        let (width, height) = (spec.width as i64, spec.height as i64);
        self.keyed.clear();
        for (i, p) in poses.iter().enumerate() {
            let bin = (p.yaw.rem_euclid(TAU) / bin_width).round() as usize % bins;
            let fc = ((p.x - spec.origin.x) * inv_res).floor();
            let fr = ((p.y - spec.origin.y) * inv_res).floor();
            let cell = if fc.is_finite() && fr.is_finite() {
                PoseCell(
                    fr.clamp(-MAX_CELL_COORD, MAX_CELL_COORD) as i64,
                    fc.clamp(-MAX_CELL_COORD, MAX_CELL_COORD) as i64,
                )
            } else {
                PoseCell::NOWHERE
            };
            self.keyed.push((bin as u32, cell, i as u32));
        }
        self.keyed.sort_unstable();

        let packed = PackedLevels::new(agree_level);
        let mut start = 0;
        while start < self.keyed.len() {
            let bin = self.keyed[start].0;
            let end = start + self.keyed[start..].iter().take_while(|k| k.0 == bin).count();
            let (s, c) = (bin as f64 * bin_width).sin_cos();
            // One plain pass per output so that the rotation runs on whole vectors (written as
            // they are computed: zeroing the buffer first was a `memset` per bin).
            self.offsets.clear();
            self.offsets.extend(obs.cells.iter().map(|cell| {
                let (x, y) = (cell.x as f64, cell.y as f64);
                // The pose sits at its cell's centre (0.5, 0.5) within the cell.
                (floor_small(0.5 + c * x - s * y), floor_small(0.5 + s * x + c * y))
            }));
            let (mut min_c, mut max_c, mut min_r, mut max_r) = (i32::MAX, i32::MIN, i32::MAX, i32::MIN);
            for &(dc, dr) in &self.offsets {
                min_c = min_c.min(dc);
                max_c = max_c.max(dc);
                min_r = min_r.min(dr);
                max_r = max_r.max(dr);
            }
            self.linear.clear();
            self.linear.extend(self.offsets.iter().map(|&(dc, dr)| dr as i64 * width + dc as i64));
            // The previous pose of this bin, its cell and score.
            let mut previous: Option<(PoseCell, PoseScore)> = None;
            for &(_, cell, index) in &self.keyed[start..end] {
                let score = if let Some((_, score)) = previous.filter(|&(seen, _)| seen == cell) {
                    score
                } else if cell != PoseCell::NOWHERE {
                    let PoseCell(row, col) = cell;
                    let inside = col + min_c as i64 >= 0
                        && col + (max_c as i64) < width
                        && row + min_r as i64 >= 0
                        && row + (max_r as i64) < height;
                    if inside {
                        self.score_inside(field, obs, row * width + col, agree_level, &packed)
                    } else {
                        self.score_at_edge(field, obs, col, row, agree_level)
                    }
                } else {
                    unknown_everywhere(field, obs)
                };
                previous = Some((cell, score));
                if let Some(slot) = out.get_mut(index as usize) {
                    *slot = score;
                }
            }
            start = end;
        }
    }

    /// All observed cells land on the map: one add and one gather per cell.
    fn score_inside(
        &self,
        field: &MatchField,
        obs: &LocalObservation,
        base: i64,
        agree_level: u8,
        packed: &PackedLevels,
    ) -> PoseScore {
        let mut score = PoseScore::default();
        for seg in &obs.segments {
            let plane = field.plane(seg.slot);
            let offsets = self.linear.get(seg.start..seg.end).unwrap_or(&[]);
            let level_at = |offset: i64| plane.get((base + offset) as usize).copied().unwrap_or(UNKNOWN_COST_LEVEL);
            let sums = if offsets.len() <= MAX_PACKED_RUN {
                PackedLevels::unpack(
                    offsets.iter().fold(0u64, |sum, &offset| sum + packed.increment[level_at(offset) as usize]),
                )
            } else {
                let mut sums = RunSums::default();
                for &offset in offsets {
                    sums.add(level_at(offset), agree_level);
                }
                sums
            };
            accumulate(&mut score, field, seg.slot, seg.end - seg.start, sums);
        }
        score
    }

    /// Some observed cells may fall off the map: bounds-check each.
    fn score_at_edge(
        &self,
        field: &MatchField,
        obs: &LocalObservation,
        col: i64,
        row: i64,
        agree_level: u8,
    ) -> PoseScore {
        let spec = &field.spec;
        let (width, height) = (spec.width as i64, spec.height as i64);
        let mut score = PoseScore::default();
        for seg in &obs.segments {
            let plane = field.plane(seg.slot);
            let mut sums = RunSums::default();
            for &(dc, dr) in self.offsets.get(seg.start..seg.end).unwrap_or(&[]) {
                let (u, v) = (col + dc as i64, row + dr as i64);
                let level = if u >= 0 && v >= 0 && u < width && v < height {
                    plane.get((v * width + u) as usize).copied().unwrap_or(UNKNOWN_COST_LEVEL)
                } else {
                    UNKNOWN_COST_LEVEL
                };
                sums.add(level, agree_level);
            }
            accumulate(&mut score, field, seg.slot, seg.end - seg.start, sums);
        }
        score
    }
}

/// `floor` for |v| < 2^20 without a libm call (x86-64 without SSE4.1 has no rounding
/// instruction): shift to positive, truncate, shift back. The local grid is far smaller. The
/// shifted value is below 2^21, so truncating to `i32` (a packed instruction) is exact.
#[inline]
fn floor_small(v: f64) -> i32 {
    const SHIFT: f64 = (1 << 20) as f64;
    (v + SHIFT) as i32 - (1 << 20)
}

/// The score of a pose all of whose cells land on unknown.
fn unknown_everywhere(field: &MatchField, obs: &LocalObservation) -> PoseScore {
    let mut score = PoseScore::default();
    for seg in &obs.segments {
        let n = (seg.end - seg.start) as u32;
        let sums = RunSums { levels: n * UNKNOWN_COST_LEVEL as u32, unknown: n, agree: 0 };
        accumulate(&mut score, field, seg.slot, seg.end - seg.start, sums);
    }
    score
}

/// Adds one class run to a score: known levels in metres, unknown cells at the class's
/// random-guess cost, all times the class weight.
#[inline]
fn accumulate(score: &mut PoseScore, field: &MatchField, slot: usize, len: usize, sums: RunSums) {
    let weight = field.slots.weight.get(slot).copied().unwrap_or(0.0) as f64;
    let unknown_cost = field.unknown_cost_m.get(slot).copied().unwrap_or(0.0) as f64;
    let known = len as u32 - sums.unknown;
    let known_levels = (sums.levels - UNKNOWN_COST_LEVEL as u32 * sums.unknown) as f64;
    let cost = known_levels * field.metres_per_level as f64 + sums.unknown as f64 * unknown_cost;
    score.weighted_cost += weight * cost;
    score.known_weight += weight * known as f64;
    score.agree_weight += weight * sums.agree as f64;
}

/// Reference scoring of one pose with exact floating-point transforms (no binning): what the
/// binned scorer approximates.
#[cfg(test)]
pub(crate) fn score_pose_exact(field: &MatchField, obs: &LocalObservation, pose: Pose2, agree_level: u8) -> PoseScore {
    let spec = &field.spec;
    let inv_res = 1.0 / spec.resolution_m;
    let ox = (pose.x - spec.origin.x) * inv_res;
    let oy = (pose.y - spec.origin.y) * inv_res;
    let (s, c) = pose.yaw.sin_cos();
    let mut score = PoseScore::default();
    for seg in &obs.segments {
        let plane = field.plane(seg.slot);
        let mut sums = RunSums::default();
        for cell in &obs.cells[seg.start..seg.end] {
            let u = (ox + c * cell.x as f64 - s * cell.y as f64).floor();
            let v = (oy + s * cell.x as f64 + c * cell.y as f64).floor();
            let level = if spec.contains(u as i64, v as i64) {
                plane[v as usize * spec.width as usize + u as usize]
            } else {
                UNKNOWN_COST_LEVEL
            };
            sums.add(level, agree_level);
        }
        accumulate(&mut score, field, seg.slot, seg.end - seg.start, sums);
    }
    score
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::observation::{ObservedCell, Segment};
    use crate::params::LocalizationParams;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;
    use spomp_core::{AerialMap, ClassTable, GridSpec, Point2};

    /// A 60 × 50 map of random blocks of road, grass and building.
    fn blocky_map(rng: &mut ChaCha8Rng) -> AerialMap {
        let spec = GridSpec::new(Point2::new(-5.0, 3.0), 0.5, 60, 50);
        let mut map = AerialMap::unknown(spec);
        for row in 0..50u32 {
            for col in 0..60u32 {
                let block = (col / 7 + 3 * (row / 5)) as usize;
                map.class[spec.index(spomp_core::Cell::new(col, row))] = [0, 3, 2, 3, 0, 6, 3][(block * 5 + 1) % 7];
            }
        }
        for _ in 0..200 {
            let i = rng.random_range(0..map.class.len());
            map.class[i] = 255;
        }
        map
    }

    fn observation(rng: &mut ChaCha8Rng, field: &MatchField) -> LocalObservation {
        let mut obs = LocalObservation::default();
        for slot in 0..3 {
            let start = obs.cells.len();
            for _ in 0..40 {
                let x = rng.random_range(-24i32..24) as f32 + 0.5;
                let y = rng.random_range(-24i32..24) as f32 + 0.5;
                obs.cells.push(ObservedCell { x, y });
            }
            obs.segments.push(Segment { slot, start, end: obs.cells.len() });
            obs.total_weight += 40.0 * field.slots.weight[slot] as f64;
        }
        obs
    }

    #[test]
    fn binned_scores_match_exact_ones_at_cell_centres_and_heading_zero() {
        let mut rng = ChaCha8Rng::seed_from_u64(9);
        let map = blocky_map(&mut rng);
        let field = MatchField::build(&map, &ClassTable::default_table(), &LocalizationParams::default()).unwrap();
        let obs = observation(&mut rng, &field);
        let mut scorer = Scorer::default();
        let mut out = Vec::new();
        // Cell centres at heading 0 (a bin centre, exact trigonometry): identical.
        let poses: Vec<Particle> = [(3.25, 10.75, 0.0), (-4.75, 3.25, 0.0), (200.25, 7.25, 0.0)]
            .iter()
            .map(|&(x, y, yaw)| Particle { x, y, yaw })
            .collect();
        scorer.score_all(&field, &obs, &poses, 1, &mut out);
        for (p, s) in poses.iter().zip(&out) {
            let exact = score_pose_exact(&field, &obs, p.pose(), 1);
            assert!((s.weighted_cost - exact.weighted_cost).abs() < 1e-6, "{p:?}: {s:?} vs {exact:?}");
            assert_eq!(s.known_weight, exact.known_weight);
            assert_eq!(s.agree_weight, exact.agree_weight);
        }
        assert_eq!(out[2].known_weight, 0.0, "off the map: all unknown");
    }

    #[test]
    fn poses_sharing_a_cell_and_bin_score_as_if_scored_alone() {
        let mut rng = ChaCha8Rng::seed_from_u64(11);
        let map = blocky_map(&mut rng);
        let field = MatchField::build(&map, &ClassTable::default_table(), &LocalizationParams::default()).unwrap();
        let obs = observation(&mut rng, &field);
        // A tight cloud (many poses per cell and heading bin), a few off the map and non-finite.
        let mut poses: Vec<Particle> = (0..300)
            .map(|_| Particle {
                x: 10.0 + rng.random_range(-0.6..0.6),
                y: 15.0 + rng.random_range(-0.6..0.6),
                yaw: 0.3 + rng.random_range(-0.01..0.01),
            })
            .collect();
        poses.push(Particle { x: -4.9, y: 3.1, yaw: 0.3 });
        poses.push(Particle { x: -4.9, y: 3.1, yaw: 0.3 });
        poses.push(Particle { x: f64::NAN, y: 3.1, yaw: 0.3 });
        let mut scorer = Scorer::default();
        let mut together = Vec::new();
        scorer.score_all(&field, &obs, &poses, 1, &mut together);
        let mut alone = Vec::new();
        for (p, s) in poses.iter().zip(&together) {
            scorer.score_all(&field, &obs, std::slice::from_ref(p), 1, &mut alone);
            assert_eq!(alone[0].weighted_cost.to_bits(), s.weighted_cost.to_bits(), "{p:?}");
            assert_eq!(alone[0].known_weight.to_bits(), s.known_weight.to_bits(), "{p:?}");
            assert_eq!(alone[0].agree_weight.to_bits(), s.agree_weight.to_bits(), "{p:?}");
        }
    }

    #[test]
    fn binned_scores_stay_close_to_exact_ones_anywhere() {
        let mut rng = ChaCha8Rng::seed_from_u64(10);
        let map = blocky_map(&mut rng);
        let field = MatchField::build(&map, &ClassTable::default_table(), &LocalizationParams::default()).unwrap();
        let obs = observation(&mut rng, &field);
        let poses: Vec<Particle> = (0..200)
            .map(|_| Particle {
                x: rng.random_range(-10.0..30.0),
                y: rng.random_range(0.0..30.0),
                yaw: rng.random_range(-7.0..7.0),
            })
            .collect();
        let mut scorer = Scorer::default();
        let mut out = Vec::new();
        scorer.score_all(&field, &obs, &poses, 1, &mut out);
        let mut total_gap = 0.0;
        for (p, s) in poses.iter().zip(&out) {
            let exact = score_pose_exact(&field, &obs, p.pose(), 1);
            // Mean cost per unit weight differs by less than a cell.
            let gap = (s.weighted_cost - exact.weighted_cost).abs() / obs.total_weight;
            assert!(gap < 0.5, "{p:?}: mean cost differs by {gap} m");
            total_gap += gap;
        }
        assert!(total_gap / 200.0 < 0.15, "average gap {} m", total_gap / 200.0);
    }
}
