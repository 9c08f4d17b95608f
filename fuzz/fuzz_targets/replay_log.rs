//! Fuzz target `replay_log`: see [`spomp_fuzz::replay_log`].
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| spomp_fuzz::replay_log(data));
