#![no_main]
//! Fuzz target `mcap_ingest`: see `fuzz/src/entries.rs`.

libfuzzer_sys::fuzz_target!(|data: &[u8]| hbn_fuzz::mcap_ingest(data));
