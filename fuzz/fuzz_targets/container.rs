//! `cargo fuzz run container`: see vbim_format::fuzz::container.
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| vbim_format::fuzz::container(data));
