//! One typed report per command: the JSON files, report.md and report.html are renderings
//! of the same value, so what the text says and what the JSON holds cannot drift apart.
//! Numbers in text go through [`mod@format`].
pub mod calibrate;
pub mod design;
pub mod fit;
pub mod format;
pub mod paper;
pub mod refine;
