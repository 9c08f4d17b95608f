//! Raster algorithms shared by several skills (see the crate README).

mod edt;
mod fingerprint;
mod shared;

pub use edt::{FAR, SquaredEdt};
pub use fingerprint::fingerprint;
pub use shared::{SharedList, SharedMemo};
