//! `cargo fuzz run device_profile`: [`motorbench::fuzz::device_profile`] under libFuzzer.
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| motorbench::fuzz::device_profile(data));
