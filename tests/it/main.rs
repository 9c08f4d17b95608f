//! The command line's tests and the fixture checks, one module per former test file, in one test
//! binary: each integration-test file is a binary that links the whole CLI (about 80 MB with its
//! dependencies), so thirteen of them cost thirteen links in every test build (docs/building.md).
//!
//! Tests that start several `spomp` processes over DDS or the team link (their domain ids and
//! ports derive from the test process's id) stay in binaries of their own in `tests/`: cargo runs
//! test binaries one after another, and so they never run beside each other.
//!
//! Run one module's tests with `cargo test --workspace --test it -- cli_sim::`.

mod cli;
mod cli_experiment;
mod cli_harden;
mod cli_operator;
mod cli_replay;
mod cli_sim;
mod cli_sites;
mod cli_tools;
mod cli_validate_memory;
mod cli_validate_world;
mod cli_world_import;
mod experiment_fixtures;
mod fuzz_replay;
mod mission_fixtures;
mod team_traffic;

use std::path::Path;

use assert_cmd::Command;

/// The `spomp` binary of this build, as a command to run.
#[allow(clippy::unwrap_used)] // tests fail loudly by design
fn spomp() -> Command {
    Command::cargo_bin("spomp").unwrap()
}

/// The workspace's root folder (the root package's): the shipped missions and the fixtures.
fn root() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}
