//! cpm-report: every report of `cpm` as typed data, and its renderings.
//!
//! One typed value per command: the JSON files (`calibration.json`, `refinement.json`,
//! `validation.json`, `design.json`, `summary.json`), report.md, report.html and the `--json`
//! summaries are renderings of the same value, so what the text says and what the JSON holds
//! cannot drift apart. Numbers in text go through [`mod@format`].
//!
//! The reports take cpm-calib and cpm-io values (and, for a fit, a [`fit::FitInputs`] the
//! caller fills); nothing here parses arguments, reads files or writes them. Without features
//! the crate depends on the calibration crates, serde and serde_json only; `svg` adds the
//! figures ([`figures`], plotters), `html` the self-contained pages ([`html`], pulldown-cmark).
#![forbid(unsafe_code)]

pub mod calibrate;
pub mod commands;
pub mod design;
pub mod fit;
pub mod format;
pub mod identifiability;
pub mod paper;
pub mod refine;
pub mod residuals;
pub mod validate;

#[cfg(feature = "svg")]
pub mod figures;
#[cfg(feature = "html")]
pub mod html;
#[cfg(all(feature = "svg", feature = "html"))]
pub mod paper_files;

/// The examples of the crate's README.md, run as doctests.
#[cfg(doctest)]
#[doc = include_str!("../README.md")]
pub struct ReadmeDoctests;
