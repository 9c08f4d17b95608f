//! The ground side of the match: a semantic panorama projected top-down around the robot into a
//! sparse local grid at the aerial map's resolution.
//!
//! Each pixel with a return is taken to robot-frame (x, y, z) with its row's elevation angle and
//! its column's azimuth (panorama convention, docs/design.md §5). Ground-class points are kept when
//! they lie near the ground plane, obstacle-class points when they are low (walls near their
//! base), people and unweighted classes never. Each (cell, class) pair is kept once, so the
//! dense returns near the robot do not outweigh the sparse far ones; the result is a list of
//! cell centres grouped by class, built once per panorama and then only rotated and translated
//! per particle.

use spomp_core::{PanoramaFrame, PanoramaGeometry};

use crate::error::LocalizationError;
use crate::field::{ClassSlots, NO_SLOT};
use crate::params::LocalizationParams;

/// Largest side of the local grid, cells (keeps the scratch mask bounded).
const MAX_LOCAL_GRID_SIDE: usize = 4096;
/// Ground cells within this distance of the robot tell which class it stands on.
const UNDER_ROBOT_RADIUS_M: f64 = 2.0;
/// Pixels tested at once for a return when a row is read whole.
const SKIP_BLOCK: usize = 16;

/// Whether a range is a return: NaN, infinite, zero (no return) and negative ranges are not.
#[inline]
fn has_return(range: f32) -> bool {
    (range > 0.0) & (range < f32::MAX)
}

/// One panorama row's pixels, with the azimuth cosine and sine of each column.
struct RowPixels<'a> {
    ranges: &'a [f32],
    labels: &'a [u8],
    col_cos: &'a [f32],
    col_sin: &'a [f32],
}

/// What projecting a pixel of one row into the local grid needs: the row's elevation (cosine,
/// sine), the sensor height, the range and height limits, and the grid's scale and size.
struct RowProjection {
    c_el: f32,
    s_el: f32,
    h: f32,
    min_r: f32,
    max_r: f32,
    band: f32,
    top: f32,
    inv_res: f32,
    half_f: f32,
    side_f: f32,
    side: usize,
}

impl RowProjection {
    /// Files pixel `col` of `row` under its class, once per (cell, class): a return in range,
    /// near the ground plane for a ground class, low for an obstacle class, inside the grid.
    /// (Inlined into the row loops, so the row's constants stay in registers.)
    #[inline(always)]
    fn take(
        &self,
        row: &RowPixels<'_>,
        col: usize,
        slots: &ClassSlots,
        mask: &mut [u32],
        per_slot: &mut [Vec<ObservedCell>],
    ) {
        let (Some(&range), Some(&label), Some(&c_az), Some(&s_az)) =
            (row.ranges.get(col), row.labels.get(col), row.col_cos.get(col), row.col_sin.get(col))
        else {
            return;
        };
        // NaN, infinite, zero (no return) and negative ranges all fail this test.
        if !has_return(range) {
            return;
        }
        let slot = slots.slot_of_class[label as usize];
        if slot == NO_SLOT {
            return;
        }
        let r = range * self.c_el;
        if r < self.min_r || r > self.max_r {
            return;
        }
        let z = self.h + range * self.s_el;
        let keep = if slots.is_ground.get(slot as usize).copied().unwrap_or(false) {
            z.abs() <= self.band
        } else {
            z >= -self.band && z <= self.top
        };
        if !keep {
            return;
        }
        let u = (r * c_az) * self.inv_res + self.half_f;
        let v = (r * s_az) * self.inv_res + self.half_f;
        if !(u >= 0.0 && v >= 0.0 && u < self.side_f && v < self.side_f) {
            return;
        }
        // Through u32 (u and v are below the grid's side, at most 4096): a float to and from a
        // 64-bit unsigned integer is a branchy sequence on x86-64.
        let (iu, iv) = (u as u32, v as u32);
        let Some(bits) = mask.get_mut(iv as usize * self.side + iu as usize) else {
            return;
        };
        let bit = 1u32 << slot;
        if *bits & bit == 0 {
            *bits |= bit;
            if let Some(list) = per_slot.get_mut(slot as usize) {
                list.push(ObservedCell { x: iu as f32 - self.half_f + 0.5, y: iv as f32 - self.half_f + 0.5 });
            }
        }
    }
}

/// One observed cell: its centre in the robot frame, in map cells.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct ObservedCell {
    /// Forward, cells.
    pub x: f32,
    /// Left, cells.
    pub y: f32,
}

/// A run of observed cells of one class.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Segment {
    /// Slot of the class.
    pub slot: usize,
    /// First cell in [`LocalObservation::cells`].
    pub start: usize,
    /// One past the last cell.
    pub end: usize,
}

/// Per-geometry trigonometry, recomputed only when the panorama shape changes.
#[derive(Clone, Debug)]
struct TrigTables {
    geometry: PanoramaGeometry,
    row_sin: Vec<f32>,
    row_cos: Vec<f32>,
    col_cos: Vec<f32>,
    col_sin: Vec<f32>,
}

impl TrigTables {
    fn new(geometry: PanoramaGeometry) -> Self {
        let (row_sin, row_cos) = (0..geometry.rows)
            .map(|r| {
                let (s, c) = geometry.elevation_of_row(r).sin_cos();
                (s as f32, c as f32)
            })
            .unzip();
        let (col_sin, col_cos) = (0..geometry.cols)
            .map(|c| {
                let (s, co) = geometry.azimuth_of_col(c).sin_cos();
                (s as f32, co as f32)
            })
            .unzip();
        TrigTables { geometry, row_sin, row_cos, col_cos, col_sin }
    }
}

/// The sparse local grid of one panorama, and the scratch space to build it without allocating.
#[derive(Clone, Debug, Default)]
pub(crate) struct LocalObservation {
    /// Observed cells, grouped by class (see [`Self::segments`]).
    pub cells: Vec<ObservedCell>,
    /// Class runs in [`Self::cells`].
    pub segments: Vec<Segment>,
    /// Σ over observed cells of their class weight.
    pub total_weight: f64,
    /// Slot of the ground class seen most around the robot's feet, if any.
    pub under_robot_slot: Option<usize>,
    per_slot: Vec<Vec<ObservedCell>>,
    mask: Vec<u32>,
    trig: Option<TrigTables>,
}

/// Checks a panorama frame's shapes and numbers.
pub(crate) fn check_frame(frame: &PanoramaFrame) -> Result<(), LocalizationError> {
    let bad = |m: String| Err(LocalizationError::InvalidPanorama(m));
    let g = frame.depth.geometry;
    if g != frame.semantic.geometry {
        return bad(format!("depth geometry {:?} differs from semantic geometry {:?}", g, frame.semantic.geometry));
    }
    if g.rows == 0 || g.cols == 0 {
        return bad(format!("empty panorama {}×{}", g.rows, g.cols));
    }
    let Some(len) = g.rows.checked_mul(g.cols) else {
        return bad(format!("panorama {}×{} is too large", g.rows, g.cols));
    };
    if frame.depth.range_m.len() != len {
        return bad(format!("{} ranges for a {}×{} panorama", frame.depth.range_m.len(), g.rows, g.cols));
    }
    if frame.semantic.class.len() != len {
        return bad(format!("{} labels for a {}×{} panorama", frame.semantic.class.len(), g.rows, g.cols));
    }
    if !(g.v_fov_rad.is_finite() && g.v_fov_rad > 0.0 && g.v_fov_rad <= std::f64::consts::PI) {
        return bad(format!("vertical field of view {} rad is not in (0, π]", g.v_fov_rad));
    }
    if !frame.sensor_height_m.is_finite() || frame.sensor_height_m.abs() > 100.0 {
        return Err(LocalizationError::NonFinite("sensor_height_m"));
    }
    let p = frame.odom_pose;
    if !(p.x.is_finite() && p.y.is_finite() && p.yaw.is_finite()) {
        return Err(LocalizationError::NonFinite("odom_pose"));
    }
    Ok(())
}

impl LocalObservation {
    /// Number of observed cells.
    pub fn len(&self) -> usize {
        self.cells.len()
    }

    /// Whether nothing usable was observed.
    pub fn is_empty(&self) -> bool {
        self.cells.is_empty()
    }

    /// Keeps only the observed cells for which `keep(cell, slot)` holds (in place, order
    /// preserved); returns the fraction of the class-weighted observation kept.
    pub fn retain(&mut self, weights: &[f32], mut keep: impl FnMut(&ObservedCell, usize) -> bool) -> f64 {
        let before = self.total_weight;
        let mut write = 0;
        let mut kept_segments = 0;
        self.total_weight = 0.0;
        for s in 0..self.segments.len() {
            let Segment { slot, start, end } = self.segments[s];
            let first = write;
            for read in start..end {
                let cell = self.cells[read];
                if keep(&cell, slot) {
                    self.cells[write] = cell;
                    write += 1;
                }
            }
            if write > first {
                self.segments[kept_segments] = Segment { slot, start: first, end: write };
                kept_segments += 1;
                self.total_weight += (write - first) as f64 * weights.get(slot).copied().unwrap_or(0.0) as f64;
            }
        }
        self.cells.truncate(write);
        self.segments.truncate(kept_segments);
        if before > 0.0 { self.total_weight / before } else { 0.0 }
    }

    /// Projects a (checked) panorama into the sparse local grid at `resolution_m` per cell.
    pub fn build(
        &mut self,
        frame: &PanoramaFrame,
        slots: &ClassSlots,
        resolution_m: f64,
        params: &LocalizationParams,
    ) -> Result<(), LocalizationError> {
        check_frame(frame)?;
        let half = (params.max_range_m / resolution_m).ceil();
        if !half.is_finite() || half < 1.0 || 2.0 * half > MAX_LOCAL_GRID_SIDE as f64 {
            return Err(LocalizationError::InvalidParams(format!(
                "max_range_m {} at {} m per cell needs a local grid wider than {MAX_LOCAL_GRID_SIDE} cells",
                params.max_range_m, resolution_m
            )));
        }
        let half = half as usize;
        let side = 2 * half;
        self.mask.clear();
        self.mask.resize(side * side, 0);
        self.per_slot.resize_with(slots.len(), Vec::new);
        self.per_slot.iter_mut().for_each(Vec::clear);

        let geometry = frame.depth.geometry;
        if self.trig.as_ref().is_none_or(|t| t.geometry != geometry) {
            self.trig = Some(TrigTables::new(geometry));
        }
        let Some(trig) = self.trig.as_ref() else {
            return Ok(());
        };

        let inv_res = (1.0 / resolution_m) as f32;
        let h = frame.sensor_height_m as f32;
        let min_r = params.min_range_m as f32;
        let max_r = params.max_range_m as f32;
        let band = params.ground_band_m as f32;
        let top = params.obstacle_max_height_m as f32;
        let half_f = half as f32;
        let side_f = side as f32;
        let ranges = &frame.depth.range_m;
        let labels = &frame.semantic.class;

        let col_step = geometry.col_step_rad();
        for (row, (&s_el, &c_el)) in trig.row_sin.iter().zip(&trig.row_cos).enumerate() {
            let start = row * geometry.cols;
            let row_ranges = ranges.get(start..start + geometry.cols).unwrap_or(&[]);
            let row_labels = labels.get(start..start + geometry.cols).unwrap_or(&[]);
            // Rows looking down at the ground near the robot put many neighbouring pixels in one
            // cell; sample them about every half cell of flat-ground arc instead of every pixel.
            // Anything nearer than flat ground (walls) is denser still, so nothing is missed
            // there; rows at or above the horizon are read whole.
            let stride = if s_el < 0.0 && frame.sensor_height_m > 0.0 {
                let flat_range = frame.sensor_height_m * c_el as f64 / -(s_el as f64);
                ((0.5 * resolution_m / (flat_range * col_step)).floor() as usize).clamp(1, geometry.cols)
            } else {
                1
            };
            let projection = RowProjection { c_el, s_el, h, min_r, max_r, band, top, inv_res, half_f, side_f, side };
            let row =
                RowPixels { ranges: row_ranges, labels: row_labels, col_cos: &trig.col_cos, col_sin: &trig.col_sin };
            let (mask, per_slot) = (&mut self.mask, &mut self.per_slot);
            let cols = row_ranges.len();
            if stride == 1 {
                // Rows read whole are mostly sky: skip blocks without a return in one test.
                let mut start = 0;
                for block in row_ranges.chunks(SKIP_BLOCK) {
                    if block.iter().fold(false, |any, &range| any | has_return(range)) {
                        for col in start..start + block.len() {
                            projection.take(&row, col, slots, mask, per_slot);
                        }
                    }
                    start += block.len();
                }
            } else {
                for col in (0..cols).step_by(stride) {
                    projection.take(&row, col, slots, mask, per_slot);
                }
            }
        }

        self.cells.clear();
        self.segments.clear();
        self.total_weight = 0.0;
        self.under_robot_slot = None;
        let feet_radius2 = (UNDER_ROBOT_RADIUS_M / resolution_m).powi(2) as f32;
        let mut most_seen = 0usize;
        for (slot, list) in self.per_slot.iter().enumerate() {
            if list.is_empty() {
                continue;
            }
            if slots.is_ground.get(slot).copied().unwrap_or(false) {
                let seen = list.iter().filter(|c| c.x * c.x + c.y * c.y <= feet_radius2).count();
                if seen > most_seen {
                    most_seen = seen;
                    self.under_robot_slot = Some(slot);
                }
            }
            let start = self.cells.len();
            self.cells.extend_from_slice(list);
            self.segments.push(Segment { slot, start, end: self.cells.len() });
            self.total_weight += list.len() as f64 * slots.weight.get(slot).copied().unwrap_or(0.0) as f64;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use spomp_core::{ClassTable, DepthPanorama, Pose2, SemanticPanorama, Time, UNKNOWN_CLASS};
    use std::f64::consts::FRAC_PI_2;
    use std::sync::Arc;

    fn frame(geometry: PanoramaGeometry, ranges: Vec<f32>, classes: Vec<u8>, h: f64) -> PanoramaFrame {
        PanoramaFrame {
            seq: 0,
            stamp: Time::ZERO,
            odom_pose: Pose2::default(),
            sensor_height_m: h,
            depth: Arc::new(DepthPanorama { geometry, range_m: ranges }),
            semantic: Arc::new(SemanticPanorama { geometry, class: classes }),
        }
    }

    fn slots(params: &LocalizationParams) -> ClassSlots {
        ClassSlots::resolve(params, &ClassTable::default_table()).unwrap()
    }

    #[test]
    fn a_ground_pixel_lands_where_the_convention_says() {
        // 5 rows over 90°: row 3 looks 22.5° down. 8 columns: column 2 looks along −y.
        let g = PanoramaGeometry { rows: 5, cols: 8, v_fov_rad: FRAC_PI_2 };
        let h = 1.0;
        let el = g.elevation_of_row(3);
        let mut ranges = vec![0.0; 40];
        let mut classes = vec![UNKNOWN_CLASS; 40];
        ranges[3 * 8 + 2] = (h / (-el).sin()) as f32;
        classes[3 * 8 + 2] = 0; // road
        let params = LocalizationParams::default();
        let s = slots(&params);
        let mut obs = LocalObservation::default();
        obs.build(&frame(g, ranges, classes, h), &s, 0.5, &params).unwrap();
        assert_eq!(obs.len(), 1);
        let expected_y = -(h / (-el).tan()); // ≈ −2.414 m: to the robot's right
        let cell = obs.cells[0];
        assert_eq!(cell.x, 0.5, "x = 0 m falls in the cell [0, 0.5) m, centre 0.25 m = 0.5 cells");
        assert_eq!(cell.y, (expected_y / 0.5).floor() as f32 + 0.5);
        assert_eq!(obs.segments, vec![Segment { slot: s.slot_of_class[0] as usize, start: 0, end: 1 }]);
        assert!((obs.total_weight - 1.0).abs() < 1e-9);
    }

    #[test]
    fn filters_people_high_points_no_returns_and_duplicates() {
        let g = PanoramaGeometry { rows: 3, cols: 4, v_fov_rad: FRAC_PI_2 };
        // Row 0 looks 45° up, row 1 level, row 2 45° down; sensor 1 m up.
        let classes = vec![2, 2, 5, 0, 2, 2, 5, 0, 0, 0, 1, 3];
        let d = 2f32.sqrt();
        #[rustfmt::skip]
        let ranges = vec![
            // Up: a wall point 8 m high (dropped), one 1.7 m high (kept), a person, a road
            // point in the air (dropped).
            10.0, 1.0, 10.0, 10.0,
            // Level: a wall (kept), NaN (dropped), a person (dropped), a road point 1 m above
            // the ground (dropped).
            5.0, f32::NAN, 5.0, 5.0,
            // Down: road on the ground ahead and to the right (kept), no return, grass on the
            // ground to the left (kept).
            d, d, 0.0, d,
        ];
        let params = LocalizationParams::default();
        let s = slots(&params);
        let mut obs = LocalObservation::default();
        obs.build(&frame(g, ranges, classes, 1.0), &s, 0.5, &params).unwrap();
        let building = s.slot_of_class[2] as usize;
        let road = s.slot_of_class[0] as usize;
        let grass = s.slot_of_class[3] as usize;
        let count = |slot: usize| obs.segments.iter().find(|seg| seg.slot == slot).map_or(0, |seg| seg.end - seg.start);
        assert_eq!(count(building), 2, "the two low wall points");
        assert_eq!(count(road), 2);
        assert_eq!(count(grass), 1);
        // Same pixel twice in the same cell is kept once.
        let g1 = PanoramaGeometry { rows: 2, cols: 1, v_fov_rad: 0.01 };
        let mut obs1 = LocalObservation::default();
        obs1.build(&frame(g1, vec![5.0, 5.0], vec![2, 2], 0.0), &s, 0.5, &params).unwrap();
        assert_eq!(obs1.len(), 1);
    }

    #[test]
    fn retain_compacts_cells_and_segments() {
        let mut obs = LocalObservation::default();
        for (slot, xs) in [(0usize, [1.0f32, 2.0, 3.0]), (2, [4.0, 5.0, 6.0]), (3, [7.0, 8.0, 9.0])] {
            let start = obs.cells.len();
            obs.cells.extend(xs.iter().map(|&x| ObservedCell { x, y: 0.0 }));
            obs.segments.push(Segment { slot, start, end: obs.cells.len() });
        }
        let weights = [1.0, 0.0, 2.0, 1.0];
        obs.total_weight = 3.0 + 6.0 + 3.0;
        let kept = obs.retain(&weights, |c, slot| slot != 2 && c.x as i32 % 2 == 1);
        assert_eq!(obs.cells.iter().map(|c| c.x).collect::<Vec<_>>(), vec![1.0, 3.0, 7.0, 9.0]);
        assert_eq!(obs.segments, vec![Segment { slot: 0, start: 0, end: 2 }, Segment { slot: 3, start: 2, end: 4 }]);
        assert!((obs.total_weight - 4.0).abs() < 1e-12);
        assert!((kept - 4.0 / 12.0).abs() < 1e-12);
    }

    #[test]
    fn malformed_frames_are_errors() {
        let g = PanoramaGeometry { rows: 2, cols: 2, v_fov_rad: 1.0 };
        let params = LocalizationParams::default();
        let s = slots(&params);
        let mut obs = LocalObservation::default();
        let short = frame(g, vec![1.0; 3], vec![0; 4], 0.4);
        assert!(matches!(obs.build(&short, &s, 0.5, &params), Err(LocalizationError::InvalidPanorama(_))));
        let nan_h = frame(g, vec![1.0; 4], vec![0; 4], f64::NAN);
        assert!(matches!(obs.build(&nan_h, &s, 0.5, &params), Err(LocalizationError::NonFinite(_))));
        let bad_fov = frame(PanoramaGeometry { v_fov_rad: f64::NAN, ..g }, vec![1.0; 4], vec![0; 4], 0.4);
        assert!(obs.build(&bad_fov, &s, 0.5, &params).is_err());
        assert!(obs.build(&frame(g, vec![1.0; 4], vec![0; 4], 0.4), &s, 1e-6, &params).is_err());
    }
}
