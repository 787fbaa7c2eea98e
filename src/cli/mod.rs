//! The bodies of the `motorbench` subcommands that drive a test or read a
//! record (`run`, `probe`, `replay`, `identify`) or document the command
//! line itself (`completions`, `man`), with their clap arguments; `src/main.rs` only parses the command line and dispatches.
//! (`diagnose`, `blind`, `serve` and `ctl` live beside what they drive:
//! [`crate::diagnose::cli`], [`crate::serve::cli`].)
//!
//! Exit codes: 0 success; 1 runtime failure (I/O, recording); 2 bad input
//! (usage, configuration, CSV or MCAP); 3 the test was aborted (the rig
//! was put in its safe state; the record is still written); 4 no
//! identification method applied to the data; 5 `replay --check` found a
//! result that differs from the recorded one.

mod export;
mod failure;
mod identify;
mod output;
mod probe;
mod progress_bar;
mod record_input;
mod recover;
mod replay;
mod run;
mod shell_docs;
mod signal;
pub(crate) mod stdout;

pub use export::{export, ExportArgs};
pub use failure::Failure;
pub use identify::{identify, IdentifyArgs};
pub use probe::{probe, ProbeArgs};
pub use record_input::RecordInput;
pub use recover::{recover, RecoverArgs};
pub use replay::{replay, ReplayArgs};
pub use run::{run, RunArgs};
pub use shell_docs::{completions, man, CompletionsArgs, ManArgs};
pub use signal::stop_signal;
