//! `cargo fuzz run start_request`: [`motorbench::fuzz::start_request`] under libFuzzer.
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| motorbench::fuzz::start_request(data));
