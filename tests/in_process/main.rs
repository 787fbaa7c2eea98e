//! The tests that run the library in-process: the bench on the simulated
//! rig, the safety supervisor, and the identification and diagnosis
//! numerics (including the `#[ignore]`d accuracy suites that
//! `scripts/accuracy-suites.sh` runs), as one test binary: each former
//! `tests/*.rs` file is a module, so the crate is linked once.
//! Run one file's tests with a filter: `cargo test --test in_process safety::`.

#[path = "../common/mod.rs"]
mod common;

mod coastdown;
mod diagnose_dc_blind;
mod diagnose_im;
mod fuzz_corpus;
mod identify_coverage;
mod identify_methods;
mod identify_property;
mod im_coverage;
mod im_lab_record;
mod im_paper_study;
mod im_standard_rig;
mod im_sweep_rig;
mod run_supervised;
mod safety;
mod sequencer;
mod supervisor;
mod supervisor_im;
