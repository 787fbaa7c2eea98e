//! `cargo fuzz run identify_segment`: [`motorbench::fuzz::identify_segment`] under libFuzzer.
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| motorbench::fuzz::identify_segment(data));
