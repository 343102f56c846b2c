//! Entry functions of hbn's fuzz targets (see `entries.rs`, shared with the stable replay test
//! `tests/fuzz_replay.rs` at the workspace root).
#![allow(clippy::needless_range_loop)]

include!("entries.rs");
