//! Fuzz target `mission_bytes`: see [`spomp_fuzz::mission_bytes`].
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| spomp_fuzz::mission_bytes(data));
