//! `cargo fuzz run package`: see vbim_format::fuzz::package.
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| vbim_format::fuzz::package(data));
