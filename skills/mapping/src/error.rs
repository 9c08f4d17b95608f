//! Errors of the mapping skill.

/// What mapping operations can fail with.
#[derive(Debug, thiserror::Error)]
pub enum MappingError {
    /// A parameter is out of range.
    #[error("invalid mapping parameter `{name}`: {reason}")]
    InvalidParams {
        /// Field name.
        name: &'static str,
        /// What is wrong with it.
        reason: String,
    },
    /// The detection class is not in the class table.
    #[error("class `{name}` is not in the class table (known: {known})")]
    UnknownClass {
        /// The name asked for.
        name: String,
        /// The names available.
        known: String,
    },
    /// Map layers have inconsistent sizes, or a region lies outside the map.
    #[error("inconsistent map: {0}")]
    InconsistentMap(String),
    /// A compressed blob does not decode or does not match its header.
    #[error("corrupt compressed map: {0}")]
    CorruptBlob(String),
    /// PNG encoding failed.
    #[error("PNG encoding failed: {0}")]
    Encode(String),
}
