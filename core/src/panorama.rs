//! Depth and semantic panoramas, following the convention of docs/design.md §5.
//!
//! Row 0 looks up at +v_fov/2, the last row down at −v_fov/2, rows evenly spaced. Column 0 looks
//! along the robot's +x axis and azimuth decreases with the column index (clockwise seen from
//! above), 2π/A per column. A depth value is the range along the ray in metres, 0 for no return.
//! On disk: a 16-bit PNG of range counts, 1/512 m per count by default.

use std::f64::consts::TAU;
use std::sync::Arc;

use serde::{Deserialize, Serialize};

use crate::classes::ClassId;
use crate::geometry::Pose2;
use crate::time::Time;

/// Default metres per count of a 16-bit depth PNG.
pub const DEFAULT_RANGE_SCALE_M: f64 = 1.0 / 512.0;

/// One range as a 16-bit PNG count (`scale_m` metres per count): 0 for no return (0, negative
/// or not finite), otherwise at least 1 and saturating at 65535.
#[inline]
pub fn range_to_count(range_m: f32, scale_m: f64) -> u16 {
    if range_m.is_finite() && range_m > 0.0 {
        (range_m as f64 / scale_m).round().clamp(1.0, u16::MAX as f64) as u16
    } else {
        0
    }
}

/// The shape and angles of a panorama.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct PanoramaGeometry {
    /// Number of rows E (elevation).
    pub rows: usize,
    /// Number of columns A (azimuth).
    pub cols: usize,
    /// Vertical field of view, radians.
    pub v_fov_rad: f64,
}

impl PanoramaGeometry {
    /// The default geometry: 256 × 1024, 90° vertical field of view.
    pub fn default_lidar() -> Self {
        PanoramaGeometry { rows: 256, cols: 1024, v_fov_rad: std::f64::consts::FRAC_PI_2 }
    }

    /// Number of pixels.
    pub fn len(&self) -> usize {
        self.rows * self.cols
    }

    /// Whether the panorama has no pixels.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Angle between successive rows, radians.
    pub fn row_step_rad(&self) -> f64 {
        if self.rows > 1 { self.v_fov_rad / (self.rows - 1) as f64 } else { 0.0 }
    }

    /// Angle between successive columns, radians (2π/A).
    pub fn col_step_rad(&self) -> f64 {
        TAU / self.cols as f64
    }

    /// Elevation of a row above the horizontal, radians (positive looks up).
    #[inline]
    pub fn elevation_of_row(&self, row: usize) -> f64 {
        self.v_fov_rad / 2.0 - row as f64 * self.row_step_rad()
    }

    /// Azimuth of a column in the robot frame, radians, counter-clockwise from +x, in (−2π, 0].
    #[inline]
    pub fn azimuth_of_col(&self, col: usize) -> f64 {
        -(col as f64) * self.col_step_rad()
    }

    /// The column whose ray is nearest to a robot-frame azimuth (any angle).
    #[inline]
    pub fn col_of_azimuth(&self, azimuth: f64) -> usize {
        let c = (-azimuth / self.col_step_rad()).round().rem_euclid(self.cols as f64);
        (c as usize) % self.cols
    }

    /// The row whose ray is nearest to an elevation angle, if inside the field of view.
    #[inline]
    pub fn row_of_elevation(&self, elevation: f64) -> Option<usize> {
        let r = ((self.v_fov_rad / 2.0 - elevation) / self.row_step_rad()).round();
        if r < 0.0 || r >= self.rows as f64 { None } else { Some(r as usize) }
    }
}

/// A depth panorama: range in metres per pixel, row-major, 0 = no return.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct DepthPanorama {
    /// Shape and angles.
    pub geometry: PanoramaGeometry,
    /// Row-major ranges, metres.
    pub range_m: Vec<f32>,
}

impl DepthPanorama {
    /// An all-no-return panorama.
    pub fn empty(geometry: PanoramaGeometry) -> Self {
        DepthPanorama { range_m: vec![0.0; geometry.len()], geometry }
    }

    /// Range at (row, col).
    #[inline]
    pub fn at(&self, row: usize, col: usize) -> f32 {
        self.range_m[row * self.geometry.cols + col]
    }

    /// Range counts for a 16-bit PNG (`scale_m` metres per count), saturating at 65535.
    pub fn to_counts(&self, scale_m: f64) -> Vec<u16> {
        self.range_m.iter().map(|&r| range_to_count(r, scale_m)).collect()
    }

    /// A panorama from 16-bit range counts; `None` if the count of values does not match.
    pub fn from_counts(geometry: PanoramaGeometry, counts: &[u16], scale_m: f64) -> Option<Self> {
        if counts.len() != geometry.len() {
            return None;
        }
        let range_m = counts.iter().map(|&c| (c as f64 * scale_m) as f32).collect();
        Some(DepthPanorama { geometry, range_m })
    }
}

/// A semantic panorama: class label per pixel, aligned with a depth panorama.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SemanticPanorama {
    /// Shape and angles.
    pub geometry: PanoramaGeometry,
    /// Row-major labels ([`crate::UNKNOWN_CLASS`] where there is no return).
    pub class: Vec<ClassId>,
}

/// One panorama as a robot receives it: depth, labels and the odometry pose it was taken at.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PanoramaFrame {
    /// Increases by one per panorama of a robot.
    pub seq: u64,
    /// When it was taken.
    pub stamp: Time,
    /// Odometry-frame pose of the sensor's robot when it was taken.
    pub odom_pose: Pose2,
    /// Height of the sensor above the ground under the robot, metres.
    pub sensor_height_m: f64,
    /// Ranges.
    pub depth: Arc<DepthPanorama>,
    /// Labels.
    pub semantic: Arc<SemanticPanorama>,
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::{FRAC_PI_2, FRAC_PI_4, PI};

    #[test]
    fn angles_follow_the_convention() {
        let g = PanoramaGeometry::default_lidar();
        assert!((g.elevation_of_row(0) - FRAC_PI_4).abs() < 1e-12);
        assert!((g.elevation_of_row(255) + FRAC_PI_4).abs() < 1e-12);
        assert_eq!(g.azimuth_of_col(0), 0.0);
        // A quarter turn of columns looks to the robot's right (−y): clockwise from above.
        assert!((g.azimuth_of_col(256) + FRAC_PI_2).abs() < 1e-12);
        assert_eq!(g.col_of_azimuth(-FRAC_PI_2), 256);
        assert_eq!(g.col_of_azimuth(FRAC_PI_2), 768);
        assert_eq!(g.col_of_azimuth(PI), 512);
        assert_eq!(g.col_of_azimuth(1e-6), 0);
        assert_eq!(g.row_of_elevation(FRAC_PI_4), Some(0));
        assert_eq!(g.row_of_elevation(-1.0), None);
    }

    #[test]
    fn counts_round_trip_within_a_count() {
        let g = PanoramaGeometry { rows: 2, cols: 3, v_fov_rad: 1.0 };
        let p = DepthPanorama { geometry: g, range_m: vec![0.0, 1.0, 2.5, 100.0, 200.0, f32::NAN] };
        let counts = p.to_counts(DEFAULT_RANGE_SCALE_M);
        assert_eq!(counts, vec![0, 512, 1280, 51200, 65535, 0]);
        let back = DepthPanorama::from_counts(g, &counts, DEFAULT_RANGE_SCALE_M).unwrap();
        assert_eq!(back.range_m[2], 2.5);
        assert!(DepthPanorama::from_counts(g, &counts[..5], DEFAULT_RANGE_SCALE_M).is_none());
    }
}
