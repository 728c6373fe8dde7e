//! The `cpm` command: calibration of parallel manipulators (see `docs/cli.md`).
fn main() {
    std::process::exit(cpm::cli::run(std::env::args_os()));
}
