//! `cargo fuzz run rig_config`: [`motorbench::fuzz::rig_config`] under libFuzzer.
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| motorbench::fuzz::rig_config(data));
