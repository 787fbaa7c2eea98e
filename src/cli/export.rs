//! `motorbench export REC.mcap`: the record as files users' own tools
//! read: each segment as contract CSV (for `motorbench identify`, a
//! spreadsheet, MATLAB's `readtable`) and every channel in one Parquet
//! file (pandas, polars, MATLAB's `parquetread`). See
//! [`crate::record::export`].

use crate::cli::stdout::outln;
use std::path::PathBuf;

use clap::{Args, ValueEnum};

use super::Failure;
use crate::config::recorded_im_model;
use crate::record::export::{export_record, ExportError, Exported, Formats};

/// `motorbench export`.
#[derive(Debug, Args)]
pub struct ExportArgs {
    /// The record (MCAP).
    pub record: PathBuf,
    /// Where to write the files (created if missing); default: beside the
    /// record.
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// What to write.
    #[arg(long, value_enum, default_value = "all")]
    pub format: FormatArg,
    /// Print what was written as JSON (`files`, and the `identify` command
    /// that reads the CSV files back).
    #[arg(long)]
    pub json: bool,
}

/// What `export` writes.
#[derive(Debug, Clone, Copy, ValueEnum)]
pub enum FormatArg {
    /// The CSV files, the nameplate and the Parquet file.
    All,
    /// One contract CSV file per segment, and the nameplate (JSON).
    Csv,
    /// One Parquet file: a column per channel, plus the segment index.
    Parquet,
}

/// Export `args.record`; prints the files written, one per line, then
/// (on standard error) how to identify from the CSV files.
pub fn export(args: ExportArgs) -> Result<(), Failure> {
    let out_dir = args.out.clone().unwrap_or_else(|| {
        args.record
            .parent()
            .map_or_else(|| PathBuf::from("."), |p| p.to_path_buf())
    });
    let formats = match args.format {
        FormatArg::All => Formats {
            csv: true,
            parquet: true,
        },
        FormatArg::Csv => Formats {
            csv: true,
            parquet: false,
        },
        FormatArg::Parquet => Formats {
            csv: false,
            parquet: true,
        },
    };
    let exported = export_record(&args.record, &out_dir, formats).map_err(|e| match e {
        ExportError::Read(e) => Failure::bad_input(e),
        other => Failure::runtime(other),
    })?;
    if let Some(r) = &exported.recovery {
        eprintln!(
            "export: warning: {} is damaged; exported what was read before the damage ({r})",
            args.record.display()
        );
    }
    let identify = identify_command(&exported);
    if args.json {
        let v = serde_json::json!({
            "files": exported.files(),
            "identify": identify,
        });
        outln!(
            "{}",
            serde_json::to_string_pretty(&v).expect("JSON serialises")
        );
    } else {
        for f in exported.files() {
            outln!("{}", f.display());
        }
        if let Some(cmd) = &identify {
            eprintln!(
                "export: identify from the CSV files with: {}",
                cmd.join(" ")
            );
        }
    }
    Ok(())
}

/// `motorbench identify --kind K [--model M] --nameplate N FILES…`, when
/// CSV files were written: an induction machine's record fits the
/// equivalent circuit its configuration named, as a replay does.
fn identify_command(e: &Exported) -> Option<Vec<String>> {
    let meta = e.meta.as_ref()?;
    if e.csv.is_empty() {
        return None;
    }
    let mut cmd = vec![
        "motorbench".to_string(),
        "identify".to_string(),
        "--kind".to_string(),
        meta.kind.as_str().to_string(),
    ];
    // The circuit the test's configuration named (an induction machine's;
    // `identify` fits its default, single cage with iron loss, otherwise).
    if let Some(model) = recorded_im_model(&meta.config) {
        cmd.push("--model".to_string());
        cmd.push(model.as_str().to_string());
    }
    if let Some(n) = &e.nameplate {
        cmd.push("--nameplate".to_string());
        cmd.push(n.display().to_string());
    }
    cmd.extend(e.csv.iter().map(|p| p.display().to_string()));
    Some(cmd)
}
