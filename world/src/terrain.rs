//! Ground-truth traversability from geometry alone (step height and slope under the robot's
//! footprint). The simulator uses it to move robots, and the tools that judge a UGV's start pose
//! ([`UgvLimits::stand_at`]: `spomp validate`'s world stage, `spomp world import`) use its one
//! rule of where a UGV can stand; the robots' own planners never see it.

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};
use spomp_core::classes::IMPASSABLE_RANK;
use spomp_core::{ClassId, Grid, Point2};

use crate::world::World;

/// What a ground robot can physically drive over.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct UgvLimits {
    /// Highest step the robot can climb, metres (a 0.15 m curb is too high).
    pub max_step_m: f64,
    /// Highest step the robot can drive down, metres: a skid-steer robot rolls off a 0.15 m
    /// curb, which it cannot climb back up.
    pub max_drop_m: f64,
    /// Steepest ground under the footprint, rise over run (height spread over the diameter).
    pub max_slope: f64,
    /// Radius of the robot's disc footprint, metres.
    pub radius_m: f64,
}

impl Default for UgvLimits {
    fn default() -> Self {
        UgvLimits { max_step_m: 0.1, max_drop_m: 0.2, max_slope: 0.3, radius_m: 0.5 }
    }
}

/// Heights under a footprint.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FootprintHeights {
    /// Lowest cell, metres.
    pub min_m: f32,
    /// Highest cell, metres.
    pub max_m: f32,
    /// Cell under the centre, metres.
    pub center_m: f32,
}

/// Heights of the cells a disc of `radius_m` at `p` touches; `None` if any of them is off the
/// world (the world's edge is a wall).
pub fn footprint_heights(world: &World, p: Point2, radius_m: f64) -> Option<FootprintHeights> {
    let spec = world.spec();
    let res = spec.resolution_m;
    let center_m = world.elevation_at(p)?;
    let (fx, fy) = ((p.x - spec.origin.x) / res, (p.y - spec.origin.y) / res);
    let r_cells = radius_m.max(0.0) / res;
    let (c0, c1) = ((fx - r_cells).floor() as i64, (fx + r_cells).floor() as i64);
    let (r0, r1) = ((fy - r_cells).floor() as i64, (fy + r_cells).floor() as i64);
    let r2 = r_cells * r_cells;
    let (mut min_m, mut max_m) = (center_m, center_m);
    for row in r0..=r1 {
        // Nearest point of the cell's row band to the centre, in cells.
        let dy = gap_to_cell(fy, row);
        for col in c0..=c1 {
            let dx = gap_to_cell(fx, col);
            if dx * dx + dy * dy >= r2 {
                continue;
            }
            let e = world.elevation_cell(col, row)?;
            min_m = min_m.min(e);
            max_m = max_m.max(e);
        }
    }
    Some(FootprintHeights { min_m, max_m, center_m })
}

/// Why a UGV cannot stand where it is put ([`UgvLimits::stand_at`]).
#[derive(Clone, Copy, Debug, PartialEq, thiserror::Error)]
pub enum StandError {
    /// The place is on an impassable class: geometry alone would let a robot stand on a roof.
    #[error("({x:.2}, {y:.2}) is on an impassable class")]
    Impassable {
        /// East, metres.
        x: f64,
        /// North, metres.
        y: f64,
    },
    /// The ground under the footprint is too uneven or steep (or outside the world).
    #[error("the robot cannot stand at ({x:.2}, {y:.2})")]
    CannotStand {
        /// East, metres.
        x: f64,
        /// North, metres.
        y: f64,
    },
}

impl UgvLimits {
    /// Where a UGV with these limits stands when it is put at `p` (a start pose): the base
    /// height under it, or why it cannot stand there. The one rule of a standable start, for the
    /// simulator's UGV and for the tools that judge start poses without a simulator.
    pub fn stand_at(&self, world: &World, p: Point2) -> Result<f32, StandError> {
        let impassable = world.class_at(p).is_some_and(|c| world.classes().rank(c) >= IMPASSABLE_RANK);
        if impassable {
            return Err(StandError::Impassable { x: p.x, y: p.y });
        }
        let base = world.elevation_at(p).unwrap_or(f32::NAN);
        self.admits(world, p, base).ok_or(StandError::CannotStand { x: p.x, y: p.y })
    }

    /// Whether the robot, standing at base height `base_m`, may place its footprint at `p`:
    /// every touched cell within a step of the base and of the cell under the new centre, and
    /// the ground under it no steeper than the slope limit. Returns the new base height (the cell under the centre) when it may.
    pub fn admits(&self, world: &World, p: Point2, base_m: f32) -> Option<f32> {
        let f = footprint_heights(world, p, self.radius_m)?;
        let step = self.max_step_m as f32 + 1e-4;
        let diameter = (2.0 * self.radius_m).max(world.spec().resolution_m) as f32;
        let slope_ok = (f.max_m - f.min_m) / diameter <= self.max_slope as f32 + 1e-4;
        let near_base = f.max_m - base_m <= step && base_m - f.min_m <= step;
        let near_center = f.max_m - f.center_m <= step && f.center_m - f.min_m <= step;
        if near_base && near_center && slope_ok { Some(f.center_m) } else { None }
    }

    /// Whether the robot, standing at `from` at base height `base_m`, may move its footprint to
    /// `to` (a short move: the simulator's substeps and cell-to-cell moves). Only the ground the
    /// footprint newly covers is judged, so the rule has a direction: a cell coming under the
    /// footprint may be at most a climb step above the base and a drop step below it, and the
    /// ground under the new footprint no steeper than the slope limit. A robot rolling off a curb
    /// keeps the curb under its rear until it has left it; one on the road cannot drive into the
    /// curb. Returns the new base height (the cell under the new centre) when it may.
    pub fn admits_move(&self, world: &World, from: Point2, to: Point2, base_m: f32) -> Option<f32> {
        let spec = world.spec();
        let res = spec.resolution_m;
        let center_m = world.elevation_at(to)?;
        let (climb, drop) = (self.max_step_m as f32 + 1e-4, self.max_drop_m as f32 + 1e-4);
        if center_m - base_m > climb || base_m - center_m > drop {
            return None;
        }
        let cells = |p: Point2| ((p.x - spec.origin.x) / res, (p.y - spec.origin.y) / res);
        let ((fx, fy), (ox, oy)) = (cells(to), cells(from));
        let r_cells = self.radius_m.max(0.0) / res;
        let r2 = r_cells * r_cells;
        let (c0, c1) = ((fx - r_cells).floor() as i64, (fx + r_cells).floor() as i64);
        let (r0, r1) = ((fy - r_cells).floor() as i64, (fy + r_cells).floor() as i64);
        let (mut min_m, mut max_m) = (center_m, center_m);
        for row in r0..=r1 {
            let (dy, old_dy) = (gap_to_cell(fy, row), gap_to_cell(oy, row));
            for col in c0..=c1 {
                let dx = gap_to_cell(fx, col);
                if dx * dx + dy * dy >= r2 {
                    continue;
                }
                let e = world.elevation_cell(col, row)?;
                min_m = min_m.min(e);
                max_m = max_m.max(e);
                let old_dx = gap_to_cell(ox, col);
                let newly_covered = old_dx * old_dx + old_dy * old_dy >= r2;
                if newly_covered && (e - base_m > climb || base_m - e > drop) {
                    return None;
                }
            }
        }
        let diameter = (2.0 * self.radius_m).max(res) as f32;
        ((max_m - min_m) / diameter <= self.max_slope as f32 + 1e-4).then_some(center_m)
    }

    /// Whether a robot could stand at `p` (its footprint fits the ground there).
    pub fn can_stand(&self, world: &World, p: Point2) -> bool {
        world.elevation_at(p).is_some_and(|base| self.admits(world, p, base).is_some())
    }
}

/// The ground-truth traversability of every cell: can the robot stand centred there.
pub fn ground_truth_traversability(world: &World, limits: &UgvLimits) -> Grid<bool> {
    let spec = *world.spec();
    let data = (0..spec.len()).map(|i| limits.can_stand(world, spec.center(spec.cell_of_index(i)))).collect();
    Grid { spec, data }
}

/// Every cell a robot starting at `start` can drive to, moving between 4-neighbouring cell
/// centres under `limits` ([`UgvLimits::admits_move`]: down a curb but not up it; ground truth
/// for scoring and for checking generated worlds).
/// Empty if the robot cannot stand at `start`.
pub fn reachable_cells(world: &World, limits: &UgvLimits, start: Point2) -> Grid<bool> {
    let spec = *world.spec();
    let mut reached = Grid::filled(spec, false);
    let Some(start_cell) = spec.cell_at(start) else { return reached };
    let start_center = spec.center(start_cell);
    let Some(base) = world.elevation_at(start_center).and_then(|b| limits.admits(world, start_center, b)) else {
        return reached;
    };
    let mut queue = std::collections::VecDeque::new();
    *reached.at_mut(start_cell) = true;
    queue.push_back((start_cell, base));
    while let Some((cell, base)) = queue.pop_front() {
        let (c, r) = (cell.col as i64, cell.row as i64);
        for (nc, nr) in [(c + 1, r), (c - 1, r), (c, r + 1), (c, r - 1)] {
            if !spec.contains(nc, nr) {
                continue;
            }
            let next = spomp_core::Cell::new(nc as u32, nr as u32);
            if *reached.at(next) {
                continue;
            }
            if let Some(b) = limits.admits_move(world, spec.center(cell), spec.center(next), base) {
                *reached.at_mut(next) = true;
                queue.push_back((next, b));
            }
        }
    }
    reached
}

/// A moving upright cylinder the world does not hold: another robot. The UGV model refuses
/// moves into one, and the panorama renderer can draw them over a render.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Obstacle {
    /// Centre, map frame.
    pub center: Point2,
    /// Radius, metres.
    pub radius_m: f64,
    /// Elevation of its bottom, metres.
    pub bottom_m: f32,
    /// Elevation of its top, metres.
    pub top_m: f32,
    /// Label it gets in semantic panoramas.
    pub class: ClassId,
}

/// Distance, in cells, from coordinate `f` (in cell units) to the band `[i, i + 1)`; 0 inside.
fn gap_to_cell(f: f64, i: i64) -> f64 {
    let (lo, hi) = (i as f64, (i + 1) as f64);
    if f < lo {
        lo - f
    } else if f > hi {
        f - hi
    } else {
        0.0
    }
}
