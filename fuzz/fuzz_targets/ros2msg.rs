#![no_main]
//! Fuzz target `ros2msg`: see `fuzz/src/entries.rs`.

libfuzzer_sys::fuzz_target!(|data: &[u8]| hbn_fuzz::ros2msg(data));
