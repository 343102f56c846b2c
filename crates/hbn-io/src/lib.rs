//! hbn-io
