//! `cargo fuzz run dbc`: [`motorbench::fuzz::dbc`] under libFuzzer.
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| motorbench::fuzz::dbc(data));
