//! `cargo fuzz run serial_stream`: [`motorbench::fuzz::serial_stream`] under libFuzzer.
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| motorbench::fuzz::serial_stream(data));
