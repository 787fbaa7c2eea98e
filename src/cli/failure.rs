//! A failed subcommand: what to tell the user and the exit code that
//! says which kind of failure it was (see the module docs of
//! [`crate::cli`]).

use std::process::ExitCode;

/// A failure with its exit code.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{message}")]
pub struct Failure {
    /// The exit code.
    pub code: u8,
    /// What went wrong, on one line.
    pub message: String,
}

impl Failure {
    /// Bad input (usage, configuration, CSV, MCAP): exit code 2.
    pub fn bad_input(e: impl std::fmt::Display) -> Failure {
        Failure {
            code: 2,
            message: e.to_string(),
        }
    }

    /// A runtime failure (I/O, recording, the rig): exit code 1.
    pub fn runtime(e: impl std::fmt::Display) -> Failure {
        Failure {
            code: 1,
            message: e.to_string(),
        }
    }

    /// The test was aborted, the rig made safe: exit code 3.
    pub fn aborted(reason: impl std::fmt::Display) -> Failure {
        Failure {
            code: 3,
            message: format!("test aborted: {reason}"),
        }
    }

    /// The exit code of `result`, saying the failure on stderr.
    pub fn exit(result: Result<(), Failure>) -> ExitCode {
        match result {
            Ok(()) => ExitCode::SUCCESS,
            Err(f) => {
                eprintln!("motorbench: {}", f.message);
                ExitCode::from(f.code)
            }
        }
    }
}
