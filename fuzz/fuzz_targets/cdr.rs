#![no_main]
//! Fuzz target `cdr`: see `fuzz/src/entries.rs`.

libfuzzer_sys::fuzz_target!(|data: &[u8]| hbn_fuzz::cdr(data));
