//! Errors of the simulator.

use spomp_world::WorldError;

/// Why a world could not be built, loaded or saved, or a model could not be set up.
#[derive(Debug, thiserror::Error)]
pub enum SimError {
    /// The world (`spomp-world`'s error, shown as it is).
    #[error(transparent)]
    World(#[from] WorldError),
    /// A value is out of its allowed range.
    #[error("invalid {what}: {message}")]
    Invalid {
        /// What was checked.
        what: &'static str,
        /// Why it was rejected.
        message: String,
    },
}

impl SimError {
    /// A shorthand for [`SimError::Invalid`].
    pub(crate) fn invalid(what: &'static str, message: impl Into<String>) -> Self {
        SimError::Invalid { what, message: message.into() }
    }
}
