//! `motorbench export`: a record as files users' own tools read.
//!
//! - [`csv`]: each segment as the contract's CSV import file, so that
//!   `motorbench identify` on the exported files gives the report a replay
//!   of the record gives (with the exported nameplate); the DC segments'
//!   files are written as the record is read (`dc_stream`), so a long
//!   record is never held whole for them either;
//! - [`parquet`]: every channel of the record in one Parquet file, a
//!   column per channel and the segment index ([`table`]), for pandas,
//!   polars or MATLAB in one call;
//! - the nameplate as JSON, for `identify --nameplate`.
//!
//! Files are named after the record (`<stem>.parquet`,
//! `<stem>.segment-<index>.csv`, `<stem>.nameplate.json`) and replace
//! earlier exports of the same record.

pub mod csv;
mod dc_stream;
pub mod parquet;
pub mod table;

use std::path::{Path, PathBuf};

use super::{
    read_each, read_outline, read_record, refuse_if_empty, Outline, RecordBuilder, RecordError,
    Resolution,
};
use dc_stream::{DcStream, Streamed};
use table::{segment_spans, TableRows};

/// What can go wrong in an export.
#[derive(Debug, thiserror::Error)]
pub enum ExportError {
    /// The record could not be read.
    #[error(transparent)]
    Read(#[from] RecordError),
    /// An output file could not be written.
    #[error("{}: {source}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// The operating system's error.
        #[source]
        source: std::io::Error,
    },
    /// The Parquet writer failed.
    #[error("{}: Parquet: {source}", path.display())]
    Parquet {
        /// The file.
        path: PathBuf,
        /// The writer's error.
        #[source]
        source: ::parquet::errors::ParquetError,
    },
    /// A column name the Parquet schema refused.
    #[error("Parquet schema: {0}")]
    Schema(#[source] ::parquet::errors::ParquetError),
}

/// Which files to write.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Formats {
    /// The segments as contract CSV (and the nameplate).
    pub csv: bool,
    /// The channels as one Parquet file.
    pub parquet: bool,
}

/// What an export wrote.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Exported {
    /// The Parquet file, when asked for.
    pub parquet: Option<PathBuf>,
    /// The CSV files, one per segment with data, in index order.
    pub csv: Vec<PathBuf>,
    /// The nameplate, with the CSV files.
    pub nameplate: Option<PathBuf>,
    /// The record's metadata (its `kind` is `identify --kind`).
    pub meta: Option<super::TestMeta>,
    /// Set when the record was damaged: what was exported is what was read
    /// before the damage.
    pub recovery: Option<super::Recovery>,
}

impl Exported {
    /// Every file written.
    pub fn files(&self) -> Vec<PathBuf> {
        self.parquet
            .iter()
            .chain(&self.csv)
            .chain(&self.nameplate)
            .cloned()
            .collect()
    }
}

/// Writes the record's segments as CSV files into `out_dir`, in index
/// order: the DC segments as the record is read ([`dc_stream`]), the
/// induction machine's from `outline`'s entries. A record whose readings
/// of a series go back in time is read whole instead.
fn write_csv(
    record_path: &Path,
    outline: &Outline,
    out_dir: &Path,
    stem: &str,
    source: &str,
) -> Result<Vec<PathBuf>, ExportError> {
    let write = |file: csv::CsvFile| {
        let path = out_dir.join(format!("{stem}.segment-{}.csv", file.segment));
        std::fs::write(&path, file.text).map_err(|source| ExportError::Io {
            path: path.clone(),
            source,
        })?;
        Ok::<_, ExportError>((file.segment, path))
    };
    // The record of every entry but the samples: the segments' kinds and
    // labels as the markers give them, the sweeps' points and the
    // standard tests' readings (entries of their own).
    let mut builder = RecordBuilder::new(None, outline.channels.clone());
    for entry in &outline.entries {
        builder.push(entry);
    }
    let outline_record = builder.finish();
    let mut stream = DcStream::new(
        &outline.channels,
        &outline.entries,
        &outline_record.segments,
        out_dir,
        stem,
        source,
    );
    read_each(record_path, &mut |entry| stream.push(&entry))?;
    let mut files = match stream.finish()? {
        Streamed::Files(mut files) => {
            for file in csv::other_files(&outline_record, source) {
                files.push(write(file)?);
            }
            files
        }
        Streamed::OutOfOrder => {
            let record = read_record(record_path, Resolution::Full)?;
            csv::segment_files(&record, source)
                .map(write)
                .collect::<Result<_, _>>()?
        }
    };
    // Stable: a DC segment's file before another of the same index.
    files.sort_by_key(|(segment, _)| *segment);
    Ok(files.into_iter().map(|(_, path)| path).collect())
}

/// Exports the record at `record_path` into `out_dir` (created if
/// missing).
pub fn export_record(
    record_path: &Path,
    out_dir: &Path,
    formats: Formats,
) -> Result<Exported, ExportError> {
    let stem = record_path
        .file_stem()
        .map_or_else(|| "record".into(), |s| s.to_string_lossy().into_owned());
    let source = record_path
        .file_name()
        .map_or_else(|| stem.clone(), |s| s.to_string_lossy().into_owned());
    let io = |path: &Path| {
        let path = path.to_path_buf();
        move |source| ExportError::Io { path, source }
    };
    std::fs::create_dir_all(out_dir).map_err(io(out_dir))?;
    // The markers first (a row's segment is known once its segment's
    // end is), then the samples, written as they come: a long record is
    // never held whole for the Parquet file.
    let outline = read_outline(record_path)?;
    // A file cut before its first message has nothing to export.
    refuse_if_empty(record_path, outline.recovery.as_ref())?;
    let meta = outline.meta.clone();
    let mut out = Exported {
        meta: Some(meta.clone()),
        recovery: outline.recovery.clone(),
        ..Exported::default()
    };
    if formats.parquet {
        let path = out_dir.join(format!("{stem}.parquet"));
        let mut rows = TableRows::new(&outline.channels, segment_spans(&outline.entries));
        let mut file = parquet::ParquetFile::create(&path, &rows.take(), &meta)?;
        let mut failed = None;
        read_each(record_path, &mut |entry| {
            if failed.is_some() {
                return;
            }
            rows.push(&entry);
            if rows.rows() >= parquet::ROW_GROUP_ROWS {
                failed = file.write(&rows.take()).err();
            }
        })?;
        if let Some(e) = failed {
            return Err(e);
        }
        file.write(&rows.finish())?;
        file.close()?;
        out.parquet = Some(path);
    }
    if formats.csv {
        out.csv = write_csv(record_path, &outline, out_dir, &stem, &source)?;
        let path = out_dir.join(format!("{stem}.nameplate.json"));
        let text = serde_json::to_string_pretty(&meta.nameplate).expect("JSON serialises");
        std::fs::write(&path, text + "\n").map_err(io(&path))?;
        out.nameplate = Some(path);
    }
    Ok(out)
}
