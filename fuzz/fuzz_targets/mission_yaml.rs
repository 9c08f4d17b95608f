//! Fuzz target `mission_yaml`: see [`spomp_fuzz::mission_yaml`].
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| spomp_fuzz::mission_yaml(data));
