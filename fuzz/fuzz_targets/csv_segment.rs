//! `cargo fuzz run csv_segment`: [`motorbench::fuzz::csv_segment`] under libFuzzer.
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| motorbench::fuzz::csv_segment(data));
