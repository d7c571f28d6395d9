//! `cargo fuzz run decode`: see vbim_format::fuzz::decode.
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| vbim_format::fuzz::decode(data));
