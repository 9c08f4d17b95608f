//! Fuzz target `qgc_plan`: see [`spomp_fuzz::qgc_plan`].
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| spomp_fuzz::qgc_plan(data));
