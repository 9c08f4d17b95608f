//! Fuzz target `world`: see [`spomp_fuzz::world`].
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| spomp_fuzz::world(data));
