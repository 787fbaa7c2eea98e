//! Recording and reading records: the MCAP layout of the data contract
//! (`shared/spec/data-format.md`), the recorder thread, and CSV import.
//!
//! - [`Recorder`] writes a test to MCAP off the async reactor.
//! - [`read_mcap`] reads it back (also a truncated file) into a [`Record`];
//!   [`recover_record`] finishes a cut file's readable part as a new file
//!   with a summary and index (`motorbench recover`).
//! - [`RecordBuilder`] turns entries into a [`Record`]; the live bench and
//!   the reader share it, so a replay gives bit-identical data. The
//!   analysis reads a long step segment's first samples ([`Resolution`]),
//!   so a test's memory does not grow with its length.
//! - [`read_dc_csv`] imports one DC segment from CSV, [`read_im_csv`] one
//!   induction-machine slip sweep, [`read_dc_resistance_csv`] and
//!   [`read_supply_test_csv`] its standard tests (DC resistance, no load,
//!   locked rotor); a [`ColumnMap`] reads the user's own column names as
//!   the contract's.
//! - [`export`] writes a record as contract CSV (one file per segment)
//!   and as one Parquet file (`motorbench export`).
//! - [`schema`] holds the topic and schema names and the JSON Schemas.
//! - [`TestStart`] is the wall-clock start, the origin of a version 2
//!   record's `log_time`; [`log_event`] the events' `foxglove.Log` shape.

mod builder;
mod columns;
mod csv;
mod csv_im;
mod csv_im_tests;
mod error;
pub mod export;
mod files;
mod im_tests;
pub mod log_event;
mod mcap_walk;
mod reader;
mod recover;
pub mod schema;
mod start;
mod thinning;
mod types;
mod writer;

pub use builder::{RecordBuilder, INCOMPLETE_SUFFIX};
pub use columns::{ColumnMap, ColumnMapError, CONTRACT_COLUMNS};
pub use csv::{data_lines, read_dc_csv};
pub use csv_im::{read_im_csv, ImCsvSegment};
pub use csv_im_tests::{
    im_file_kind, read_dc_resistance_csv, read_supply_test_csv, ImTestCsvSegment, COL_DC_CURRENT,
    COL_DC_VOLTAGE, COL_WINDING_TEMPERATURE,
};
pub use error::{LoadError, RecordError};
pub use files::load_record_files;
pub use reader::{
    build_record, read_each, read_entries, read_mcap, read_outline, read_record, refuse_if_empty,
    Entries, Outline,
};
pub use recover::{recover_record, Recovered, DAMAGED_SUFFIX};
pub use start::TestStart;
pub use thinning::{Resolution, HEAD_SAMPLES, TAIL_SAMPLES};
pub use types::*;
pub use writer::{library_name, Recorder, RecorderBacklog, RecorderStats, QUEUE_CAPACITY};
