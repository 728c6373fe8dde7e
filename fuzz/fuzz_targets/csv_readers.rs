//! cargo-fuzz target: `cpm::fuzzing::csv_readers` on arbitrary bytes (see fuzz/README.md).
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| cpm::fuzzing::csv_readers(data));
