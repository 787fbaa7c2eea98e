//! `cargo fuzz run nameplate`: [`motorbench::fuzz::nameplate`] under libFuzzer.
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| motorbench::fuzz::nameplate(data));
