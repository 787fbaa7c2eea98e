//! `motorbench recover`: finish the readable part of records cut by a
//! killed process as files with a summary and an index, so that indexed
//! (seeking) MCAP readers open them too; the cut file is kept (see
//! [`crate::record::recover_record`]).

use std::path::PathBuf;

use clap::Args;

use super::Failure;
use crate::record::{recover_record, RecordError, Recovered};

/// `motorbench recover`.
#[derive(Debug, Args)]
pub struct RecoverArgs {
    /// The records (MCAP files); a whole one is left as it is.
    #[arg(required = true)]
    pub records: Vec<PathBuf>,
    /// Write the finished copy here and leave the record untouched (one
    /// record only). Without it the copy takes the record's name and the
    /// cut file is kept as `<record>.damaged`.
    #[arg(long)]
    pub out: Option<PathBuf>,
}

/// Recover every record of `args`; the first failure's exit code once all
/// have been tried (2 for a file that is no readable record, 1 for I/O).
pub fn recover(args: RecoverArgs) -> Result<(), Failure> {
    if args.out.is_some() && args.records.len() > 1 {
        return Err(Failure::bad_input("--out takes one record"));
    }
    let mut first_failure = None;
    for path in &args.records {
        match recover_record(path, args.out.as_deref()) {
            Ok(Recovered::Whole) => {
                println!("{}: whole (has its summary), left as it is", path.display());
            }
            Ok(Recovered::Copied {
                out,
                original,
                messages,
                reason,
            }) => {
                println!(
                    "{}: {messages} messages finished with a summary and index into {}; \
                     the cut file is {} ({reason})",
                    path.display(),
                    out.display(),
                    original.display()
                );
            }
            Err(e) => {
                eprintln!("motorbench: {e}");
                let failure = match e {
                    RecordError::Io { .. } | RecordError::Mcap { .. } => Failure::runtime(&e),
                    _ => Failure::bad_input(&e),
                };
                first_failure.get_or_insert(failure);
            }
        }
    }
    first_failure.map_or(Ok(()), Err)
}
