//! `cargo fuzz run mcap_record`: [`motorbench::fuzz::mcap_record`] under libFuzzer.
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| motorbench::fuzz::mcap_record(data));
