//! What this build of `spomp` holds. The default build is the simulator and every tool around
//! it; the `deploy` feature adds what robots run: the ROS 2 node (DDS), the Zenoh team link and
//! the Foxglove live view — about half of a clean build's compile time (docs/building.md). The
//! README's test command builds with it, so the tests cover the whole product.

use std::process::ExitCode;

/// Whether this build has the `deploy` feature.
pub(crate) const BUILT: bool = cfg!(feature = "deploy");

/// `spomp --version`: the version and which build this is, so a missing command is explained
/// before it is tried.
pub(crate) const VERSION: &str = if BUILT {
    concat!(env!("CARGO_PKG_VERSION"), " (deploy build: simulator, tools, ROS 2, team link, live view)")
} else {
    concat!(env!("CARGO_PKG_VERSION"), " (default build: simulator and tools; robots need --features deploy)")
};

/// How to get a build that can do `what`.
const REBUILD: &str =
    "cargo build --release --features deploy (or cargo install --path . --features deploy; docs/building.md)";

/// The error of a command or option this build left out: a usage error (exit 2), with how to
/// rebuild.
pub(crate) fn not_built(what: &str) -> anyhow::Result<ExitCode> {
    errln!("error: {}", not_built_error(what));
    Ok(ExitCode::from(2))
}

/// The same, as an error value for code that cannot return an exit code.
pub(crate) fn not_built_error(what: &str) -> anyhow::Error {
    anyhow::anyhow!(
        "{what} needs spomp built with the `deploy` feature (ROS 2, the Zenoh team link, the live view); this build is the simulator and its tools. Build it with: {REBUILD}"
    )
}
