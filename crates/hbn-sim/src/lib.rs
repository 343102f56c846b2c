//! hbn-sim
