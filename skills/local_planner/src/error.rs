//! Errors of the local planner.

use spomp_core::PanoramaGeometry;
use thiserror::Error;

/// A parameter set that cannot be used.
#[derive(Clone, Debug, PartialEq, Error)]
#[error("invalid parameter `{name}`: {reason}")]
pub struct ParamsError {
    /// Field name of the offending parameter.
    pub name: &'static str,
    /// What is wrong with it.
    pub reason: &'static str,
}

impl ParamsError {
    pub(crate) fn new(name: &'static str, reason: &'static str) -> Self {
        ParamsError { name, reason }
    }
}

/// Checks that `value` is finite and strictly positive.
pub(crate) fn positive(name: &'static str, value: f64) -> Result<(), ParamsError> {
    if value.is_finite() && value > 0.0 { Ok(()) } else { Err(ParamsError::new(name, "must be finite and > 0")) }
}

/// Checks that `value` is finite and not negative.
pub(crate) fn non_negative(name: &'static str, value: f64) -> Result<(), ParamsError> {
    if value.is_finite() && value >= 0.0 { Ok(()) } else { Err(ParamsError::new(name, "must be finite and >= 0")) }
}

/// Why terrain analysis could not run.
#[derive(Clone, Debug, PartialEq, Error)]
pub enum TerrainError {
    /// The analyzer was built for another panorama shape.
    #[error("panorama geometry {found:?} does not match the analyzer's {expected:?}")]
    GeometryMismatch {
        /// Geometry the analyzer was built for.
        expected: PanoramaGeometry,
        /// Geometry of the panorama passed in.
        found: PanoramaGeometry,
    },
    /// The panorama's range buffer does not hold rows × cols values.
    #[error("panorama holds {found} ranges, its geometry needs {expected}")]
    BufferLength {
        /// rows × cols.
        expected: usize,
        /// Length of the range buffer.
        found: usize,
    },
    /// The geometry cannot be analysed (too small or too large, or a bad field of view).
    #[error("unusable panorama geometry {0:?}: needs 2+ rows, 3+ columns, at most 2^22 pixels and 0 < v_fov ≤ π")]
    BadGeometry(PanoramaGeometry),
    /// A parameter is out of range.
    #[error(transparent)]
    Params(#[from] ParamsError),
}

/// Why a safe region could not be built.
#[derive(Clone, Debug, PartialEq, Error)]
pub enum RegionError {
    /// No bins, or the range and obstacle vectors differ in length.
    #[error("reachability scan is inconsistent: {ranges} ranges, {obstacles} obstacle flags")]
    Inconsistent {
        /// Number of ranges.
        ranges: usize,
        /// Number of obstacle flags.
        obstacles: usize,
    },
    /// A parameter is out of range.
    #[error(transparent)]
    Params(#[from] ParamsError),
}
