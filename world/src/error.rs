//! Errors of the world model.

use std::path::PathBuf;

/// Why a world could not be built, loaded or saved.
#[derive(Debug, thiserror::Error)]
pub enum WorldError {
    /// A file could not be read or written.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// What the operating system said.
        source: std::io::Error,
    },
    /// `world.yaml` does not parse, has unknown keys or a value out of range.
    #[error("{}: bad world description: {message}", located(path, *line, *column))]
    BadYaml {
        /// The file.
        path: PathBuf,
        /// Line of the offending value, from 1 (0 when the place is not known).
        line: u32,
        /// Column of the offending value, from 1 (0 when the place is not known).
        column: u32,
        /// Field path of the offending value (`origin.x`, `meta.start_poses[2].yaw`); empty when
        /// the problem is not one field's.
        field: String,
        /// What is wrong.
        message: String,
    },
    /// A layer file the world description needs is not there.
    #[error("{path}: missing {layer} layer file")]
    MissingLayer {
        /// Which layer (`class`, `elevation`, `color`).
        layer: &'static str,
        /// Where it was expected.
        path: PathBuf,
    },
    /// A PNG could not be decoded or encoded.
    #[error("{path}: bad image: {message}")]
    BadImage {
        /// The file.
        path: PathBuf,
        /// The decoder's message.
        message: String,
    },
    /// A layer's size differs from the world's.
    #[error("{path}: {layer} layer is {got_width}x{got_height} pixels, the world is {width}x{height}")]
    WrongSize {
        /// Which layer.
        layer: &'static str,
        /// The file.
        path: PathBuf,
        /// Expected width, cells.
        width: u32,
        /// Expected height, cells.
        height: u32,
        /// Width of the file, pixels.
        got_width: u32,
        /// Height of the file, pixels.
        got_height: u32,
    },
    /// A class-raster pixel has a colour that no class in the table has.
    #[error("{path}: pixel (x {x}, y {y}) has colour {color:?}, which is not in the class table")]
    UnknownColor {
        /// The file.
        path: PathBuf,
        /// Pixel column (from the left of the image).
        x: u32,
        /// Pixel row (from the top of the image).
        y: u32,
        /// The colour found.
        color: [u8; 3],
    },
    /// The class table is invalid.
    #[error("class table: {0}")]
    ClassTable(#[from] spomp_core::ClassTableError),
    /// A value is out of its allowed range.
    #[error("invalid {what}: {message}")]
    Invalid {
        /// What was checked.
        what: &'static str,
        /// Why it was rejected.
        message: String,
    },
}

/// `path:line:column`, or just `path` when the place is not known.
fn located(path: &std::path::Path, line: u32, column: u32) -> String {
    if line == 0 { path.display().to_string() } else { format!("{}:{line}:{column}", path.display()) }
}

impl WorldError {
    /// A shorthand for [`WorldError::Invalid`].
    pub(crate) fn invalid(what: &'static str, message: impl Into<String>) -> Self {
        WorldError::Invalid { what, message: message.into() }
    }
}
