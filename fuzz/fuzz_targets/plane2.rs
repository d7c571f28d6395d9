//! `cargo fuzz run plane2`: see vbim_format::fuzz::plane2.
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| vbim_format::fuzz::plane2(data));
