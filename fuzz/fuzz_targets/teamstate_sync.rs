//! Fuzz target `teamstate_sync`: see [`spomp_fuzz::teamstate_sync`].
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| spomp_fuzz::teamstate_sync(data));
