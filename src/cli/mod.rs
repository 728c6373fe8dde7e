//! The `cpm` command line: argument parsing (clap), the commands, exit codes and messages.
//!
//! Each command lives in its own module; [`run`] parses the arguments, runs the command and
//! turns the outcome into an exit code (`docs/cli.md`):
//!
//! | code | meaning |
//! |---|---|
//! | 0 | success |
//! | 1 | the computation failed or reported trouble (e.g. the solver did not converge) |
//! | 2 | usage error (unknown option, missing argument, conflicting options) |
//! | 3 | bad input file (robot description or measurement file) |
//! | 4 | I/O error (a file could not be read or written) |
//!
//! Errors go to stderr as `error: <file>:<line>: field <name>: <what>` where the problem is
//! in a file. Outputs are staged in memory and written only after everything succeeded, so a
//! failing command leaves no partial output.
use std::ffi::OsString;
use std::io::{IsTerminal, Write};
use std::time::Duration;

use clap::{Parser, Subcommand};

pub mod calibrate;
pub mod common;
pub mod compensate;
pub mod design;
pub mod export;
pub mod formulation;
/// Readings against the declared gauges (the workflow layer's).
pub use cpm_workflow::gauges;
pub mod identifiability;
/// The figures of a fit (moved to [`crate::report::figures::fit`]).
pub use crate::report::figures::fit as plots;
pub mod refine;
pub mod simulate;
pub mod validate;

/// Exit codes, the errors of the commands and their rendering: the workflow layer's.
pub use cpm_workflow::error::{
    exit_kind, input_error, render_error, trouble, usage_error, ExitKind, JobError,
    JobError as CliError,
};

/// `cpm`: calibration of parallel manipulators.
#[derive(Debug, Parser)]
#[command(
    name = "cpm",
    version,
    about = "Calibration of parallel manipulators (Gough-Stewart platforms): simulate, analyse, calibrate, compensate",
    long_about = "Calibration of parallel manipulators (six-link Gough-Stewart platforms): finds the \
3D installation errors of every base and platform joint, plus declared effects (link offsets, \
scales, ...), from length-sensor readings or tracker pose measurements, and says which errors the \
data determine and how precisely.\n\nUnits: mm and degrees in files, um for installation errors. \
File formats: docs/formats.md. Exit codes: 0 ok, 1 computation trouble (e.g. no convergence), \
2 usage error, 3 bad input file, 4 I/O error.",
    arg_required_else_help = true,
    after_help = "Examples:\n  cpm simulate --robot examples/hexapod_66.toml --random 40 --truth examples/hexapod_66_truth.toml --out data.csv\n  cpm identifiability --robot examples/hexapod_66.toml --data data.csv\n  cpm calibrate --robot examples/hexapod_66.toml --data data.csv --out cal/\n  cpm compensate --robot cal/calibrated.toml --poses examples/targets.csv --out commands.csv\n  cpm export --format linuxcnc --robot cal/calibrated.toml\n  cpm design --robot examples/hexapod_66.toml --readings 360 --out design/"
)]
pub struct Cli {
    /// No progress display and no notes on stderr (results and errors are still printed).
    #[arg(long, short, global = true)]
    pub quiet: bool,
    /// The command.
    #[command(subcommand)]
    pub command: Command,
}

/// The commands.
#[derive(Debug, Subcommand)]
pub enum Command {
    /// Simulate a measurement campaign (marked simulated) from a robot, a plan and a truth.
    Simulate(simulate::SimulateArgs),
    /// What a campaign or plan can identify: rank, singular values, blind directions, bounds.
    Identifiability(identifiability::IdentifiabilityArgs),
    /// Fit installation errors and declared effects to measurements; write the results.
    Calibrate(calibrate::CalibrateArgs),
    /// Actuator commands for target poses from a calibrated robot description.
    Compensate(compensate::CompensateArgs),
    /// Export a (calibrated) robot's joints for a machine controller (LinuxCNC genhexkins).
    Export(export::ExportArgs),
    /// Calibrate, then add the effects the residual asks for, one at a time, with tests.
    Refine(refine::RefineArgs),
    /// Choose sensor sockets and poses for a campaign (experiment design).
    Design(design::DesignArgs),
    /// Check a calibrated robot on held-out measurements against a reference robot.
    Validate(validate::ValidateArgs),
}

/// What a command gives back when it did not fail.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Outcome {
    /// All well.
    Done,
    /// Finished and wrote its outputs, but reports trouble (exit code 1), e.g. no
    /// convergence.
    Trouble(String),
}

/// What a command needs besides its arguments: where results go, and the progress display.
pub struct Ctx<'a> {
    /// Standard output (results, `--json`).
    pub out: &'a mut dyn Write,
    /// `--quiet`.
    pub quiet: bool,
    progress: Option<indicatif::ProgressBar>,
}

impl<'a> Ctx<'a> {
    /// A context writing results to `out`; progress is shown on stderr only when it is a
    /// terminal and `quiet` is off.
    pub fn new(out: &'a mut dyn Write, quiet: bool) -> Self {
        let progress = (!quiet && std::io::stderr().is_terminal()).then(|| {
            let bar = indicatif::ProgressBar::new_spinner();
            if let Ok(style) =
                indicatif::ProgressStyle::with_template("{spinner} [{elapsed_precise}] {msg}")
            {
                bar.set_style(style);
            }
            bar.enable_steady_tick(Duration::from_millis(120));
            bar
        });
        Self {
            out,
            quiet,
            progress,
        }
    }

    /// Shows what is being done now.
    pub fn stage(&self, message: impl Into<String>) {
        if let Some(b) = &self.progress {
            b.set_message(message.into());
        }
    }

    /// A note on stderr (not with `--quiet`).
    pub fn note(&self, message: impl AsRef<str>) {
        if self.quiet {
            return;
        }
        match &self.progress {
            Some(b) => b.println(format!("note: {}", message.as_ref())),
            None => eprintln!("note: {}", message.as_ref()),
        }
    }

    /// A status line (`wrote FILE`) on stderr, for a command whose standard output carries
    /// data (not with `--quiet`).
    pub fn status(&self, message: impl AsRef<str>) {
        if self.quiet {
            return;
        }
        match &self.progress {
            Some(b) => b.println(message.as_ref()),
            None => eprintln!("{}", message.as_ref()),
        }
    }

    /// Removes the progress display.
    pub fn finish(&mut self) {
        if let Some(b) = self.progress.take() {
            b.finish_and_clear();
        }
    }
}

/// The command line shows a job's progress: its stage on the spinner, its notes on stderr.
impl cpm_workflow::Progress for Ctx<'_> {
    fn stage(&self, message: &str) {
        Ctx::stage(self, message);
    }
    fn note(&self, message: &str) {
        Ctx::note(self, message);
    }
    fn warn(&self, message: &str) {
        Ctx::status(self, format!("warning: {message}"));
    }
}

impl Drop for Ctx<'_> {
    fn drop(&mut self) {
        self.finish();
    }
}

/// Runs a parsed command.
pub fn execute(cli: &Cli, ctx: &mut Ctx<'_>) -> anyhow::Result<Outcome> {
    match &cli.command {
        Command::Simulate(a) => simulate::run(a, ctx),
        Command::Identifiability(a) => identifiability::run(a, ctx),
        Command::Calibrate(a) => calibrate::run(a, ctx),
        Command::Compensate(a) => compensate::run(a, ctx),
        Command::Export(a) => export::run(a, ctx),
        Command::Refine(a) => refine::run(a, ctx),
        Command::Design(a) => design::run(a, ctx),
        Command::Validate(a) => validate::run(a, ctx),
    }
}

/// Parses `args` (the program name first), runs the command, prints errors to stderr and
/// returns the exit code.
pub fn run<I, T>(args: I) -> i32
where
    I: IntoIterator<Item = T>,
    T: Into<OsString> + Clone,
{
    let cli = match Cli::try_parse_from(args) {
        Ok(c) => c,
        Err(e) => {
            // A value the workflow's parsers refuse (`--robust pink:3`) says so in their
            // words, as the job would: `error: --robust "pink:3": unknown loss ...`.
            if let Some(refused) = option_error(&e) {
                eprintln!("error: {refused}");
                return ExitKind::Usage as i32;
            }
            let _ = e.print();
            return e.exit_code();
        }
    };
    let stdout = std::io::stdout();
    // A closed standard output would swallow the results silently (Rust ignores writes to a
    // closed descriptor 1), and a file opened later could take its number: stop first.
    if stdout_closed(&stdout) {
        eprintln!("error: standard output is closed; the results would be lost");
        return ExitKind::Io as i32;
    }
    let mut lock = stdout.lock();
    let result = {
        let mut ctx = Ctx::new(&mut lock, cli.quiet);
        let r = execute(&cli, &mut ctx);
        ctx.finish();
        r
    };
    let flushed = lock.flush();
    let result = match (result, flushed) {
        (Ok(_), Err(e)) if e.kind() != std::io::ErrorKind::BrokenPipe => {
            Err(anyhow::Error::new(e).context("writing to standard output"))
        }
        (r, _) => r,
    };
    match result {
        Ok(Outcome::Done) => ExitKind::Success as i32,
        Ok(Outcome::Trouble(msg)) => {
            eprintln!("error: {msg}");
            ExitKind::Trouble as i32
        }
        Err(e) if broken_pipe(&e) => ExitKind::Success as i32,
        Err(e) => {
            eprintln!("error: {}", render_error(&e));
            exit_kind(&e) as i32
        }
    }
}

/// The workflow's refusal of an option's value ([`cpm_workflow::options`]) behind a clap
/// error, if that is what it is.
fn option_error(e: &clap::Error) -> Option<&cpm_workflow::options::OptionError> {
    if e.kind() != clap::error::ErrorKind::ValueValidation {
        return None;
    }
    std::error::Error::source(e)?.downcast_ref()
}

/// Whether descriptor 1 was open when the process started, as recorded by
/// [`record_stdout_at_start`]: 0 not recorded, 1 open, 2 closed.
static STDOUT_AT_START: std::sync::atomic::AtomicU8 = std::sync::atomic::AtomicU8::new(0);

/// Records whether descriptor 1 is open now (Linux, with `/proc` mounted; else nothing is
/// recorded). The `cpm` binary calls it from an `.init_array` entry, before the Rust runtime
/// reopens a closed standard descriptor on `/dev/null`; [`run`] then tells `cpm ... >&-`
/// (refused) from a parent's read-write `/dev/null` such as Python's `subprocess.DEVNULL`
/// (accepted). Opens no descriptor (it must not take the number 1 itself).
pub fn record_stdout_at_start() {
    #[cfg(target_os = "linux")]
    {
        use std::sync::atomic::Ordering;
        if std::fs::symlink_metadata("/proc/self/fd").is_ok() {
            let open = std::fs::symlink_metadata("/proc/self/fd/1").is_ok();
            STDOUT_AT_START.store(if open { 1 } else { 2 }, Ordering::Relaxed);
        }
    }
}

/// True when descriptor 1 was closed when `cpm` started (`cpm ... >&-`).
///
/// The Rust runtime opens `/dev/null` read-write on a closed standard descriptor before
/// `main`. When [`record_stdout_at_start`] ran before it (the `cpm` binary on Linux), its
/// record decides. Otherwise (`/proc` not mounted, [`run`] called from another program) the
/// guess is best-effort: `/dev/null` open for reading and writing counts as closed (a shell's
/// `>/dev/null` opens it write-only, which is fine; a parent's read-write `/dev/null` is
/// then refused too).
fn stdout_closed(stdout: &std::io::Stdout) -> bool {
    match STDOUT_AT_START.load(std::sync::atomic::Ordering::Relaxed) {
        1 => return false,
        2 => return true,
        _ => {}
    }
    #[cfg(target_os = "linux")]
    {
        use rustix::fs::{fcntl_getfl, fstat, major, minor, FileType, OFlags};
        use std::os::fd::AsFd as _;
        let fd = stdout.as_fd();
        let (Ok(flags), Ok(st)) = (fcntl_getfl(fd), fstat(fd)) else {
            return true;
        };
        let read_write = (flags & OFlags::ACCMODE) == OFlags::RDWR;
        let dev_null = FileType::from_raw_mode(st.st_mode) == FileType::CharacterDevice
            && major(st.st_rdev) == 1
            && minor(st.st_rdev) == 3;
        read_write && dev_null
    }
    #[cfg(not(target_os = "linux"))]
    {
        let _ = stdout;
        false
    }
}

/// True when stdout was closed by its reader (`cpm ... | head`): not worth a message.
fn broken_pipe(err: &anyhow::Error) -> bool {
    err.chain().any(|c| {
        c.downcast_ref::<std::io::Error>()
            .is_some_and(|e| e.kind() == std::io::ErrorKind::BrokenPipe)
    })
}
