//! `cargo fuzz run slcan_line`: [`motorbench::fuzz::slcan_line`] under libFuzzer.
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| motorbench::fuzz::slcan_line(data));
