//! cpm-calib (work in progress).
