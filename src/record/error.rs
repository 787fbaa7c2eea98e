//! Errors of the record module.
//!
//! Every message fits on one line and names the file it is about; CSV
//! errors also name the line and the column, e.g.
//! `data.csv:17: column armature_current_A: "abc" is not a number`.

use std::path::{Path, PathBuf};

/// What can go wrong while recording, reading or importing a record.
#[derive(Debug, thiserror::Error)]
pub enum RecordError {
    /// The file could not be created, read or written.
    #[error("{}: {source}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// The operating system's error.
        #[source]
        source: std::io::Error,
    },

    /// The MCAP library could not write or decode the file.
    #[error("{}: MCAP: {source}", path.display())]
    Mcap {
        /// The file.
        path: PathBuf,
        /// The library's error.
        #[source]
        source: mcap::McapError,
    },

    /// A CSV file is malformed.
    #[error("{}:{line}: {}{reason}", path.display(), column_prefix(column))]
    Csv {
        /// The file.
        path: PathBuf,
        /// Line number, from 1.
        line: usize,
        /// Column name, where the problem is in one column.
        column: Option<String>,
        /// What is wrong.
        reason: String,
    },

    /// An MCAP file is damaged (cut, a flipped bit, a length or CRC that
    /// does not match) where nothing usable can be read before the damage.
    #[error("{}: {reason}", path.display())]
    Damaged {
        /// The file.
        path: PathBuf,
        /// The byte offset of the record (or chunk) found damaged.
        offset: u64,
        /// Where the damage is and what is wrong there, e.g. `damaged at
        /// byte 8 of 1200 (0.7 % read): …`.
        reason: String,
    },

    /// A message in an MCAP file does not decode as its topic's schema.
    #[error("{}: topic {topic} at log_time {log_time}: {reason}", path.display())]
    BadMessage {
        /// The file.
        path: PathBuf,
        /// The message's topic.
        topic: String,
        /// The message's `log_time` as the file has it.
        log_time: u64,
        /// What is wrong.
        reason: String,
    },

    /// The file is readable but is not a motorbench record (no
    /// `motorbench.test` metadata, a missing key, a channel without its
    /// metadata, …).
    #[error("{}: not a motorbench record: {reason}", path.display())]
    NotMotorbench {
        /// The file.
        path: PathBuf,
        /// What is missing or wrong.
        reason: String,
    },

    /// The record was written under a contract version this build does
    /// not read.
    #[error(
        "{}: schema_version \"{found}\" is not supported (this build reads schema_version {})",
        path.display(),
        crate::contract::READ_SCHEMA_VERSIONS.map(|v| format!("\"{v}\"")).join(" and ")
    )]
    UnsupportedVersion {
        /// The file.
        path: PathBuf,
        /// The `schema_version` found in the file.
        found: String,
    },

    /// The input is valid but asks for something not implemented yet.
    #[error("{}: {reason}", path.display())]
    Unsupported {
        /// The file.
        path: PathBuf,
        /// What is not supported.
        reason: String,
    },

    /// The caller handed the recorder something it cannot record (a channel
    /// index out of range, a channel whose topic does not match its
    /// quantity, …). Nothing was written for it.
    #[error("{}: {reason}", path.display())]
    InvalidInput {
        /// The record file.
        path: PathBuf,
        /// What is wrong.
        reason: String,
    },

    /// The recorder's writer thread failed (or died); the message is its
    /// error.
    #[error("recorder thread for {} failed: {reason}", path.display())]
    WriterFailed {
        /// The record file.
        path: PathBuf,
        /// The thread's error.
        reason: String,
    },
}

/// Why the files named on a command line do not load as one record.
#[derive(Debug, thiserror::Error)]
pub enum LoadError {
    /// One of the files could not be read as a record or a segment.
    #[error(transparent)]
    Record(#[from] RecordError),
    /// The nameplate file could not be read.
    #[error("{}: {source}", path.display())]
    NameplateIo {
        /// The nameplate file.
        path: PathBuf,
        /// The operating system's error.
        #[source]
        source: std::io::Error,
    },
    /// The nameplate file is not JSON.
    #[error("{}:{}: {source}", path.display(), source.line())]
    NameplateJson {
        /// The nameplate file.
        path: PathBuf,
        /// The parser's error, with its line.
        #[source]
        source: serde_json::Error,
    },
    /// The nameplate is JSON but not an object.
    #[error("{}: a nameplate must be a JSON object", path.display())]
    NameplateNotObject {
        /// The nameplate file.
        path: PathBuf,
    },
    /// More than one MCAP file, or an MCAP file among CSV files.
    #[error("give either one MCAP file or any number of CSV files")]
    MixedFiles,
    /// Two CSV files declare the same segment index.
    #[error("{}: segment index {index} is already used by {}", path.display(), other.display())]
    DuplicateSegment {
        /// The file declaring the index a second time.
        path: PathBuf,
        /// The segment index.
        index: u32,
        /// The file that declared it first.
        other: PathBuf,
    },
}

/// Why a CSV row's time is refused (the caller names the file, the line
/// and the column).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub(crate) enum TimeError {
    /// Beyond ±[`MAX_CSV_TIME_S`](crate::bounds::MAX_CSV_TIME_S).
    #[error(
        "time {t:e} s is beyond ±{max:e} s (seconds since the start of the record, or a Unix time)",
        max = crate::bounds::MAX_CSV_TIME_S
    )]
    OutOfRange {
        /// The time, s.
        t: f64,
    },
    /// Not after the previous row's time.
    #[error("time {t} is not after the previous row's {previous} (line {previous_line}); time must increase strictly")]
    NotIncreasing {
        /// The time, s.
        t: f64,
        /// The previous row's time, s.
        previous: f64,
        /// The previous row's line.
        previous_line: usize,
    },
    /// A step outside the sampling steps a record can have.
    #[error(
        "a step of {step:e} s after the previous row (line {previous_line}) is outside {min:e} to {max} s, the sampling steps a record can have",
        min = crate::bounds::MIN_CSV_STEP_S,
        max = crate::bounds::MAX_CSV_STEP_S
    )]
    Step {
        /// The step, s.
        step: f64,
        /// The previous row's line.
        previous_line: usize,
    },
}

/// Why a CSV segment declaration (`<index> kind=<kind> label=<text>`) is
/// refused (the caller names the file and the line).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub(crate) enum DeclarationError {
    /// No index.
    #[error("segment declaration without a segment index")]
    NoIndex,
    /// The index is not a number.
    #[error("segment declaration: {quoted} is not a segment index (0, 1, 2, …)")]
    BadIndex {
        /// The index as written, quoted.
        quoted: String,
    },
    /// An unknown kind.
    #[error("segment declaration: kind {quoted} is not dc_step, dc_coastdown or im_slip_sweep")]
    BadKind {
        /// The kind as written, quoted.
        quoted: String,
    },
    /// Text that is neither a kind nor a label.
    #[error("segment declaration: unexpected {quoted} (want `<index> kind=<kind> label=<text>`)")]
    Unexpected {
        /// The text, quoted.
        quoted: String,
    },
}

/// Why a walk over an MCAP file's records stopped (the caller says where
/// in the file).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub(crate) enum WalkError {
    /// A record's length-prefixed string runs past the record's end.
    #[error("record of opcode {opcode:#04x} ({len} bytes) declares a string longer than itself")]
    StringOverrun {
        /// The record's opcode.
        opcode: u8,
        /// The record's length, bytes.
        len: usize,
    },
    /// The MCAP library refused a record: its error and causes, on one
    /// line.
    #[error("{0}")]
    Mcap(String),
    /// Damage inside a chunk.
    #[error("in the chunk: {0}")]
    InChunk(Box<WalkError>),
}

/// Why a message does not decode as its topic's JSON payload (the caller
/// names the file, the topic and the log time).
#[derive(Debug, thiserror::Error)]
#[error("cannot decode {shown:?}{}: {source}", if *.cut { "…" } else { "" })]
pub(crate) struct DecodeError {
    /// The message's first 80 characters.
    pub shown: String,
    /// Whether the message is longer than what is shown.
    pub cut: bool,
    /// The parser's error.
    #[source]
    pub source: serde_json::Error,
}

fn column_prefix(column: &Option<String>) -> String {
    match column {
        Some(c) => format!("column {c}: "),
        None => String::new(),
    }
}

impl RecordError {
    /// An I/O error on `path`.
    pub(crate) fn io(path: &Path, source: std::io::Error) -> RecordError {
        RecordError::Io {
            path: path.to_path_buf(),
            source,
        }
    }

    /// An MCAP library error on `path`.
    pub(crate) fn mcap(path: &Path, source: mcap::McapError) -> RecordError {
        RecordError::Mcap {
            path: path.to_path_buf(),
            source,
        }
    }

    /// A "not a motorbench record" error on `path`.
    pub(crate) fn not_motorbench(path: &Path, reason: impl Into<String>) -> RecordError {
        RecordError::NotMotorbench {
            path: path.to_path_buf(),
            reason: reason.into(),
        }
    }

    /// A CSV error at `line` (from 1), in `column` if given.
    pub(crate) fn csv(
        path: &Path,
        line: usize,
        column: Option<&str>,
        reason: impl Into<String>,
    ) -> RecordError {
        RecordError::Csv {
            path: path.to_path_buf(),
            line,
            column: column.map(str::to_string),
            reason: reason.into(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn csv_message_names_file_line_and_column() {
        let e = RecordError::csv(
            Path::new("data.csv"),
            17,
            Some("armature_current_A"),
            "\"abc\" is not a number",
        );
        assert_eq!(
            e.to_string(),
            "data.csv:17: column armature_current_A: \"abc\" is not a number"
        );
        let e = RecordError::csv(Path::new("data.csv"), 3, None, "no data rows");
        assert_eq!(e.to_string(), "data.csv:3: no data rows");
    }

    #[test]
    fn version_message_is_clear() {
        let e = RecordError::UnsupportedVersion {
            path: PathBuf::from("run.mcap"),
            found: "3".into(),
        };
        let s = e.to_string();
        assert!(s.starts_with("run.mcap: schema_version \"3\" is not supported"));
        assert!(s.ends_with("reads schema_version \"1\" and \"2\")"), "{s}");
        assert!(!s.contains('\n'));
    }

    #[test]
    fn io_and_not_motorbench_name_the_file() {
        let e = RecordError::io(
            Path::new("x.mcap"),
            std::io::Error::new(std::io::ErrorKind::NotFound, "gone"),
        );
        assert_eq!(e.to_string(), "x.mcap: gone");
        let e = RecordError::not_motorbench(Path::new("x.mcap"), "no motorbench.test metadata");
        assert_eq!(
            e.to_string(),
            "x.mcap: not a motorbench record: no motorbench.test metadata"
        );
    }

    #[test]
    fn error_is_send_sync() {
        fn assert_send_sync<T: Send + Sync + 'static>() {}
        assert_send_sync::<RecordError>();
    }
}
