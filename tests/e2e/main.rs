//! The end-to-end tests that go through the `motorbench` binary, the daemon
//! or a real protocol stack (Modbus, serial, SLCAN, SocketCAN, the Python
//! peers), as one test binary: each former `tests/*.rs` file is a module,
//! so the crate and its dependencies are linked once, not once per file.
//! Run one file's tests with a filter: `cargo test --test e2e daemon::`.

#[path = "../common/mod.rs"]
mod common;
#[path = "../mcap_corpus/mod.rs"]
mod mcap_corpus;

mod bad_input;
mod blind_benchmark;
mod daemon;
mod daemon_modbus;
mod daemon_page;
mod daemon_web;
mod dc_one_file;
mod dc_step;
mod degenerate_dc;
mod diagnose_cli;
mod diagnose_dc_shaft;
mod early_result;
mod export;
mod fault_matrix;
mod foxglove_layout;
mod identify_csv;
mod im_identify_cli;
mod im_run_cli;
mod im_standard_modbus;
mod im_standard_run;
mod im_standard_tests_cli;
mod modbus_stage;
mod peers_modbus;
mod peers_serial;
mod peers_slcan;
mod record_v2;
mod recover;
mod shell_docs;
mod sim_can;
mod sim_merged_sensors;
mod sim_modbus;
mod sim_modbus_im;
mod socketcan;
mod systemd_unit;
