//! cpm-clearance (work in progress).
