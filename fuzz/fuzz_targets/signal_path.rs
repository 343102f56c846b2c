#![no_main]
//! Fuzz target `signal_path`: see `fuzz/src/entries.rs`.

libfuzzer_sys::fuzz_target!(|data: &[u8]| hbn_fuzz::signal_path(data));
