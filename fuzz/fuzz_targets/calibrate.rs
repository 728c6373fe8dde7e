//! cargo-fuzz target: `cpm::fuzzing::calibrate` on arbitrary bytes (see fuzz/README.md).
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| cpm::fuzzing::calibrate(data));
