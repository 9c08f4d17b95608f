//! The fuzz targets' kept inputs (`fuzz/corpus/`, `fuzz/regressions/`) through their target
//! functions, in the workspace's own test build.
//!
//! The fuzz crate is a workspace of its own (sanitizer flags, its own lock file), so replaying
//! its inputs with `cargo test --manifest-path fuzz/Cargo.toml` resolved features anew and rebuilt
//! the shared dependencies: 3.6–4.1 min of each CI run. The targets' bodies are compiled here from
//! the same file instead; `cargo fuzz` still builds them through the fuzz crate (fuzz/README.md).

#![allow(clippy::unwrap_used, clippy::expect_used)] // tests fail loudly by design

#[path = "../../fuzz/src/lib.rs"]
mod targets;
