//! Writes a [`SampleTable`] as one Parquet file, which pandas
//! (`pd.read_parquet`), polars (`pl.read_parquet`) and MATLAB
//! (`parquetread`) read in one call.
//!
//! Columns, in order: `time_s` (DOUBLE, s since the start of the test),
//! `time` (INT64 TIMESTAMP(NANOS, UTC): the wall clock, the start plus
//! `time_s`; only when the record's start is known), `segment` (INT32,
//! null outside every segment), then one nullable DOUBLE per channel
//! (see [`super::table`]). The file's key-value metadata carries
//! `motorbench.test` (the record's metadata as a JSON object: `kind`,
//! `motor_id`, `started_at`, `nameplate`, …) and `motorbench.units`
//! (column → SI unit, a JSON object).
//!
//! Written with the `parquet` crate's low-level writer, without Arrow and
//! without compression (the crate's default features cost several minutes
//! of build): plain and dictionary encodings only; the file is about as
//! large as its numbers.

use std::fs::File;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use parquet::basic::{LogicalType, Repetition, TimeUnit, Type as PhysicalType};
use parquet::data_type::{DoubleType, Int32Type, Int64Type};
use parquet::errors::ParquetError;
use parquet::file::metadata::KeyValue;
use parquet::file::properties::WriterProperties;
use parquet::file::writer::SerializedFileWriter;
use parquet::schema::types::Type;

use super::table::SampleTable;
use super::ExportError;
use crate::record::{library_name, TestMeta, TestStart};

/// Rows per row group: bounds the memory a reader needs per group.
pub const ROW_GROUP_ROWS: usize = 1 << 18;

/// Writes `table` of the record described by `meta` to `path`
/// (replacing a file there).
pub fn write_parquet(path: &Path, table: &SampleTable, meta: &TestMeta) -> Result<(), ExportError> {
    let mut file = ParquetFile::create(path, table, meta)?;
    file.write(table)?;
    file.close()
}

/// A Parquet file being written, a row group at a time.
pub struct ParquetFile {
    path: PathBuf,
    start: Option<TestStart>,
    writer: SerializedFileWriter<File>,
}

impl ParquetFile {
    /// Creates `path` (replacing a file there) for the columns of `table`
    /// (its rows are not written) of the record described by `meta`.
    pub fn create(
        path: &Path,
        table: &SampleTable,
        meta: &TestMeta,
    ) -> Result<ParquetFile, ExportError> {
        let start = TestStart::parse_rfc3339(&meta.started_at);
        let file = File::create(path).map_err(|source| ExportError::Io {
            path: path.to_path_buf(),
            source,
        })?;
        let props = WriterProperties::builder()
            .set_created_by(library_name())
            .set_key_value_metadata(Some(key_values(table, meta)))
            .build();
        let writer =
            SerializedFileWriter::new(file, schema(table, start.is_some())?, Arc::new(props))
                .map_err(parquet_error(path))?;
        Ok(ParquetFile {
            path: path.to_path_buf(),
            start,
            writer,
        })
    }

    /// Writes the rows of `table` (the columns [`ParquetFile::create`]
    /// was given), in row groups of at most [`ROW_GROUP_ROWS`].
    pub fn write(&mut self, table: &SampleTable) -> Result<(), ExportError> {
        let pq = parquet_error(&self.path);
        let start = self.start;
        for from in (0..table.rows()).step_by(ROW_GROUP_ROWS) {
            let rows = from..(from + ROW_GROUP_ROWS).min(table.rows());
            let mut group = self.writer.next_row_group().map_err(&pq)?;
            let mut column = |write: &mut dyn FnMut(
                &mut parquet::file::writer::SerializedColumnWriter<'_>,
            ) -> Result<usize, ParquetError>|
             -> Result<(), ParquetError> {
                let mut c = group.next_column()?.expect("a column per schema field");
                write(&mut c)?;
                c.close()
            };
            let times: Vec<f64> = table.t_ns[rows.clone()]
                .iter()
                .map(|&t| t as f64 * 1e-9)
                .collect();
            column(&mut |c| c.typed::<DoubleType>().write_batch(&times, None, None))
                .map_err(&pq)?;
            if let Some(start) = start {
                let wall: Vec<i64> = table.t_ns[rows.clone()]
                    .iter()
                    .map(|&t| i64::try_from(start.unix_ns().saturating_add(t)).unwrap_or(i64::MAX))
                    .collect();
                column(&mut |c| c.typed::<Int64Type>().write_batch(&wall, None, None))
                    .map_err(&pq)?;
            }
            let (values, levels) = nullable(&table.segment[rows.clone()], |s| s as i32);
            column(&mut |c| {
                c.typed::<Int32Type>()
                    .write_batch(&values, Some(&levels), None)
            })
            .map_err(&pq)?;
            for channel in &table.channels {
                let (values, levels) = nullable(&channel.cells[rows.clone()], |v| v);
                column(&mut |c| {
                    c.typed::<DoubleType>()
                        .write_batch(&values, Some(&levels), None)
                })
                .map_err(&pq)?;
            }
            group.close().map_err(&pq)?;
        }
        Ok(())
    }

    /// Finishes the file.
    pub fn close(self) -> Result<(), ExportError> {
        self.writer.close().map_err(parquet_error(&self.path))?;
        Ok(())
    }
}

/// The [`ExportError`] of a Parquet failure writing `path`.
fn parquet_error(path: &Path) -> impl Fn(ParquetError) -> ExportError + '_ {
    move |source| ExportError::Parquet {
        path: path.to_path_buf(),
        source,
    }
}

/// The present values of `cells` and the definition level of every cell
/// (1 present, 0 null).
fn nullable<T: Copy, U>(cells: &[Option<T>], f: impl Fn(T) -> U) -> (Vec<U>, Vec<i16>) {
    let values = cells.iter().flatten().map(|&v| f(v)).collect();
    let levels = cells.iter().map(|c| i16::from(c.is_some())).collect();
    (values, levels)
}

/// The file's schema: see the module docs.
fn schema(table: &SampleTable, wall_clock: bool) -> Result<Arc<Type>, ExportError> {
    let field = |name: &str, physical, repetition, logical| {
        Type::primitive_type_builder(name, physical)
            .with_repetition(repetition)
            .with_logical_type(logical)
            .build()
            .map(Arc::new)
    };
    let mut fields = vec![field(
        "time_s",
        PhysicalType::DOUBLE,
        Repetition::REQUIRED,
        None,
    )];
    if wall_clock {
        fields.push(field(
            "time",
            PhysicalType::INT64,
            Repetition::REQUIRED,
            Some(LogicalType::timestamp(true, TimeUnit::NANOS)),
        ));
    }
    fields.push(field(
        "segment",
        PhysicalType::INT32,
        Repetition::OPTIONAL,
        Some(LogicalType::integer(32, true)),
    ));
    for c in &table.channels {
        fields.push(field(
            &c.name,
            PhysicalType::DOUBLE,
            Repetition::OPTIONAL,
            None,
        ));
    }
    let fields = fields
        .into_iter()
        .collect::<Result<Vec<_>, _>>()
        .map_err(ExportError::Schema)?;
    Type::group_type_builder("motorbench_record")
        .with_fields(fields)
        .build()
        .map(Arc::new)
        .map_err(ExportError::Schema)
}

/// `motorbench.test` and `motorbench.units`.
fn key_values(table: &SampleTable, meta: &TestMeta) -> Vec<KeyValue> {
    let test = serde_json::json!({
        "schema_version": meta.schema_version,
        "kind": meta.kind.as_str(),
        "motor_id": meta.motor_id,
        "started_at": meta.started_at,
        "nameplate": meta.nameplate,
        "config": meta.config,
    });
    let mut units = serde_json::Map::new();
    units.insert("time_s".into(), "s".into());
    for c in &table.channels {
        units.insert(c.name.clone(), c.unit.clone().into());
    }
    vec![
        KeyValue::new("motorbench.test".into(), test.to_string()),
        KeyValue::new(
            "motorbench.units".into(),
            serde_json::Value::Object(units).to_string(),
        ),
    ]
}
