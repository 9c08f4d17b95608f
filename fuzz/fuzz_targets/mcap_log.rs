//! Fuzz target `mcap_log`: see [`spomp_fuzz::mcap_log`].
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| spomp_fuzz::mcap_log(data));
