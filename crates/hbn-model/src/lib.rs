//! hbn-model
