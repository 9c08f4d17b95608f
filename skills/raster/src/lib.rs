//! Raster algorithms shared by several skills (see the crate README).

mod edt;
mod fingerprint;

pub use edt::{FAR, SquaredEdt};
pub use fingerprint::fingerprint;
