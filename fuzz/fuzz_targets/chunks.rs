//! `cargo fuzz run chunks`: see vbim_format::fuzz::chunks.
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| vbim_format::fuzz::chunks(data));
