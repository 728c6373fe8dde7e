//! The `cpm` command: calibration of parallel manipulators (see `docs/cli.md`).

/// The command's allocator (see the `mimalloc` dependency in Cargo.toml).
#[global_allocator]
static ALLOCATOR: mimalloc::MiMalloc = mimalloc::MiMalloc;

fn main() {
    std::process::exit(cpm::cli::run(std::env::args_os()));
}

/// Records whether standard output was open when the process started, before the Rust
/// runtime reopens a closed descriptor 1 on `/dev/null` (read-write, exactly as a parent's
/// `subprocess.DEVNULL`): the loader runs `.init_array` entries before `main`'s runtime
/// set-up. The only unsafe-code lint in the workspace, for the `link_section` attribute: the
/// function itself is safe code (it only looks at `/proc/self/fd`, opens nothing).
#[cfg(target_os = "linux")]
#[used]
#[allow(unsafe_code)]
#[link_section = ".init_array"]
static RECORD_STDOUT_AT_START: extern "C" fn() = record_stdout_at_start;

#[cfg(target_os = "linux")]
extern "C" fn record_stdout_at_start() {
    cpm::cli::record_stdout_at_start();
}
