//! hbn-gp
