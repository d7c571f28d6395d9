//! `cargo fuzz run player_decoder`: see vbim_player::bench::fuzz_decoder.
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| vbim_player::bench::fuzz_decoder(data));
