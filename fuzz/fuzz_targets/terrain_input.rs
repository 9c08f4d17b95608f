//! Fuzz target `terrain_input`: see [`spomp_fuzz::terrain_input`].
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| spomp_fuzz::terrain_input(data));
