//! Fuzz target `teamlink_receive`: see [`spomp_fuzz::teamlink_receive`].
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| spomp_fuzz::teamlink_receive(data));
