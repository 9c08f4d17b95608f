//! Errors of the localizer. Malformed input yields one of these, never a panic.

/// Why a localizer call was rejected.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum LocalizationError {
    /// A parameter is out of range.
    #[error("invalid localization parameters: {0}")]
    InvalidParams(String),
    /// None of the ground classes named in the parameters is in the class table.
    #[error(
        "none of the ground classes `{name}` of the localization parameters is in the class table (classes: {known})"
    )]
    UnknownClassName {
        /// The ground class names, none of which was found.
        name: String,
        /// The names the table has.
        known: String,
    },
    /// More classes carry a weight than the matcher can hold.
    #[error("{0} classes carry a weight; at most {max} can", max = crate::field::MAX_WEIGHTED_CLASSES)]
    TooManyWeightedClasses(usize),
    /// The panorama is malformed (sizes, field of view).
    #[error("invalid panorama: {0}")]
    InvalidPanorama(String),
    /// The aerial map is malformed.
    #[error("invalid aerial map: {0}")]
    InvalidMap(String),
    /// A pose or height is NaN or infinite.
    #[error("non-finite input: {0}")]
    NonFinite(&'static str),
    /// The filter has no particles yet: initialise it from a prior or globally first.
    #[error("the localizer is not initialised")]
    NotInitialized,
    /// Global initialisation needs known cells of a ground class in the map.
    #[error("the aerial map has no known cells of a ground class to spread particles over")]
    NoGroundCells,
}
