//! The paper reproduction's files ([`cpm_report::paper_files`]) staged in an [`OutputSet`].
use std::path::Path;

use cpm_calib::paper::PaperReproduction;
pub use cpm_report::paper_files::{
    designed_files, files, limited_files, report_md, summary_json, DESIGNED_GAUGE,
};

use crate::output::OutputSet;
use crate::report::figures::PlotError;

/// Stages every output file of the reproduction ([`files`]) into `out`, under `dir`.
pub fn render(r: &PaperReproduction, dir: &Path, out: &mut OutputSet) -> Result<(), PlotError> {
    for (name, text) in files(r)? {
        out.add(dir.join(name), text);
    }
    Ok(())
}

/// Stages the campaign under limits ([`limited_files`]) under `dir/designed/`; nothing when
/// it was not run.
pub fn render_limited(
    r: &PaperReproduction,
    dir: &Path,
    out: &mut OutputSet,
) -> Result<(), String> {
    for (name, text) in limited_files(r, dir)? {
        out.add(dir.join(name), text);
    }
    Ok(())
}
