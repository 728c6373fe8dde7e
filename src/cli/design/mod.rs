//! `cpm design`: choose sensor sockets and poses for a calibration campaign, and write the
//! poses, the sockets and a robot description with the chosen sensors. The job is
//! [`cpm_workflow::design::design`]; this module is its arguments, the commit and the printing.

use super::common;
use super::{Ctx, Outcome};

pub mod args;
pub use crate::io::sockets::{read_sockets, read_sockets_from, MAX_SOCKETS, SOCKET_PAIR_COLUMNS};
pub use args::{CriterionArg, DesignArgs, GaugeArg};
pub use cpm_workflow::design::sockets_of;

/// Runs `cpm design`.
pub fn run(args: &DesignArgs, ctx: &mut Ctx<'_>) -> anyhow::Result<Outcome> {
    let d = cpm_workflow::design::design(&args.options(), ctx)?;
    let inputs: Vec<&std::path::Path> = d.inputs.iter().map(|p| p.as_path()).collect();
    let written = common::commit_dir(d.outputs, &args.out, &inputs, "design", ctx)?;
    ctx.finish();
    if args.json {
        writeln!(ctx.out, "{}", d.json)?;
    } else {
        writeln!(ctx.out, "{}", d.summary)?;
        for w in &written {
            writeln!(ctx.out, "wrote {}", w.display())?;
        }
    }
    Ok(Outcome::Done)
}
