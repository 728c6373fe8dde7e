//! cpm-geometry (work in progress).
