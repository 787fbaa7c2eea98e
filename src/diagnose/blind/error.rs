//! Why a blind suite could not be written or scored: each error names
//! the suite's file it concerns, so a user can fix or regenerate it.

use std::path::PathBuf;

use crate::record::LoadError;

/// A blind suite could not be written or scored.
#[derive(Debug, thiserror::Error)]
pub enum SuiteError {
    /// The suite's directory exists already (no old case may survive
    /// beside new ones).
    #[error("{}: already exists; give a new directory for the suite", .0.display())]
    Exists(PathBuf),
    /// A file or directory could not be read or written.
    #[error("{}: {source}", path.display())]
    Io {
        /// The file or directory.
        path: PathBuf,
        /// The operating system's error.
        source: std::io::Error,
    },
    /// A suite file is not the JSON it should be.
    #[error("{}:{}: {source}", path.display(), source.line())]
    Json {
        /// The file.
        path: PathBuf,
        /// The parser's error (it names the line).
        source: serde_json::Error,
    },
    /// A case names a test kind motorbench does not know.
    #[error("{}: case {case}: unknown kind {kind:?}", manifest.display())]
    UnknownKind {
        /// The suite's `cases.json`.
        manifest: PathBuf,
        /// The case.
        case: String,
        /// Its kind as written.
        kind: String,
    },
    /// A case's files could not be loaded.
    #[error(transparent)]
    Case(#[from] LoadError),
    /// The truth file has no entry for a case.
    #[error("{}: no truth for {case}", truth.display())]
    NoTruth {
        /// The suite's `truth.json`.
        truth: PathBuf,
        /// The case.
        case: String,
    },
}

impl SuiteError {
    /// The I/O error `source` on `path`.
    pub fn io(path: impl Into<PathBuf>) -> impl FnOnce(std::io::Error) -> SuiteError {
        let path = path.into();
        move |source| SuiteError::Io { path, source }
    }
}
