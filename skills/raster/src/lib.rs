//! Raster algorithms shared by several skills (see the crate README).

mod edt;

pub use edt::{FAR, SquaredEdt};
