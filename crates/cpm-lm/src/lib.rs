//! cpm-lm (work in progress).
