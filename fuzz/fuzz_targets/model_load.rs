#![no_main]
//! Fuzz target `model_load`: see `fuzz/src/entries.rs`.

libfuzzer_sys::fuzz_target!(|data: &[u8]| hbn_fuzz::model_load(data));
