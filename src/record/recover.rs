//! Recovery of a cut record (`motorbench recover`): a process killed while
//! recording leaves an MCAP file without its summary and footer, which
//! motorbench and the non-seeking readers read up to the last flushed
//! chunk but indexed (seeking) readers refuse. [`recover_record`] copies
//! every readable record of such a file — its header's profile and
//! library, schemas, channels (ids kept), metadata and messages, in file
//! order, bytes unchanged — into a new file finished with a summary and
//! an index, and adds a [`METADATA_RECOVERY`] metadata record saying what
//! was cut, so motorbench reads the copy exactly as it read the cut file
//! (the same damage warning, the same report).
//!
//! Nothing is lost: the copy is written beside the file under a temporary
//! name and synced, and only then does the cut file move aside (to
//! `<file>.damaged`) and the copy take its name; with an explicit output
//! the cut file is not touched at all. A whole file is left as it is.

use std::collections::BTreeMap;
use std::fs::OpenOptions;
use std::io::BufWriter;
use std::path::{Path, PathBuf};

use mcap::records::{MessageHeader, Metadata, Record as McapRecord};
use mcap::{Compression, WriteOptions};

use super::error::RecordError;
use super::mcap_walk::walk_records;
use super::reader::{read_outline, refuse_if_empty};
use super::schema::{METADATA_RECOVERY, RECOVERY_MESSAGES, RECOVERY_OFFSET, RECOVERY_REASON};
use super::writer::library_name;

/// The suffix the cut file takes once its recovered copy has its name.
pub const DAMAGED_SUFFIX: &str = "damaged";

/// What [`recover_record`] did.
#[derive(Debug, Clone, PartialEq)]
pub enum Recovered {
    /// The file is whole (it has its summary); nothing was written.
    Whole,
    /// The readable part was copied into a finished file.
    Copied {
        /// The finished file.
        out: PathBuf,
        /// Where the cut file is now (itself when an output was given).
        original: PathBuf,
        /// Messages copied.
        messages: u64,
        /// Where the cut was and what the reader found there.
        reason: String,
    },
}

/// Copy the readable part of the cut record `path` into a finished file:
/// `out` when given (the cut file stays as it is), else `path` itself,
/// the cut file moved to `<path>.damaged` once the copy is complete. A
/// whole file is left alone ([`Recovered::Whole`]); a file that is not a
/// motorbench record, or has not one message before its damage, is
/// refused as [`super::read_entries`] refuses it.
pub fn recover_record(path: &Path, out: Option<&Path>) -> Result<Recovered, RecordError> {
    let recovery = read_outline(path)?.recovery;
    let bytes = std::fs::read(path).map_err(|e| RecordError::io(path, e))?;
    // Whole: no damage (a recovered copy reads with its cut file's).
    let Some(recovery) = recovery.filter(|_| walk_records(&bytes, &mut |_| {}).is_some()) else {
        return Ok(Recovered::Whole);
    };
    refuse_if_empty(path, Some(&recovery))?;
    let target = out.map_or_else(|| with_suffix(path, "recovering"), Path::to_path_buf);
    let note = BTreeMap::from([
        (RECOVERY_MESSAGES.to_string(), recovery.messages.to_string()),
        (RECOVERY_OFFSET.to_string(), recovery.offset.to_string()),
        (RECOVERY_REASON.to_string(), recovery.reason.clone()),
        ("recovered_by".to_string(), library_name()),
    ]);
    let copied = copy_readable(&bytes, &target, note);
    drop(bytes);
    let messages = match copied {
        Ok(n) => n,
        Err(e) => {
            // An unfinished copy is no use; the cut file is untouched.
            let _ = std::fs::remove_file(&target);
            return Err(e);
        }
    };
    let (out, original) = match out {
        Some(out) => (out.to_path_buf(), path.to_path_buf()),
        None => {
            let aside = with_suffix(path, DAMAGED_SUFFIX);
            std::fs::rename(path, &aside).map_err(|e| RecordError::io(path, e))?;
            std::fs::rename(&target, path).map_err(|e| RecordError::io(path, e))?;
            (path.to_path_buf(), aside)
        }
    };
    Ok(Recovered::Copied {
        out,
        original,
        messages,
        reason: recovery.reason,
    })
}

/// `<path>.<suffix>`.
fn with_suffix(path: &Path, suffix: &str) -> PathBuf {
    let mut name = path.as_os_str().to_owned();
    name.push(".");
    name.push(suffix);
    PathBuf::from(name)
}

/// One record of the cut file, owned, in file order.
enum Copied {
    Schema {
        id: u16,
        name: String,
        encoding: String,
        data: Vec<u8>,
    },
    Channel(mcap::records::Channel),
    Metadata(Metadata),
    Message {
        header: MessageHeader,
        data: Vec<u8>,
    },
}

/// Write every readable record of `bytes` (a cut MCAP file) to a new file
/// `target`, then `note` as the recovery metadata, finish and sync it;
/// the number of messages written.
fn copy_readable(
    bytes: &[u8],
    target: &Path,
    note: BTreeMap<String, String>,
) -> Result<u64, RecordError> {
    let mut header = None;
    let mut records = Vec::new();
    walk_records(bytes, &mut |record| match record {
        McapRecord::Header(h) => header = Some(h),
        McapRecord::Schema { header, data } => records.push(Copied::Schema {
            id: header.id,
            name: header.name,
            encoding: header.encoding,
            data: data.into_owned(),
        }),
        McapRecord::Channel(c) => records.push(Copied::Channel(c)),
        McapRecord::Metadata(m) => records.push(Copied::Metadata(m)),
        McapRecord::Message { header, data } => records.push(Copied::Message {
            header,
            data: data.into_owned(),
        }),
        _ => {}
    });
    let header = header.ok_or_else(|| RecordError::not_motorbench(target, "no MCAP header"))?;
    let file = OpenOptions::new()
        .write(true)
        .create_new(true)
        .open(target)
        .map_err(|e| RecordError::io(target, e))?;
    let mcap_err = |e| RecordError::mcap(target, e);
    let mut writer = WriteOptions::new()
        .profile(header.profile)
        .library(header.library)
        .compression(Some(Compression::Zstd))
        .use_chunks(true)
        .compression_threads(0)
        .create(BufWriter::new(file))
        .map_err(mcap_err)?;
    let mut messages = 0u64;
    for record in records {
        match record {
            Copied::Schema {
                id,
                name,
                encoding,
                data,
            } => {
                writer
                    .add_schema_with_id(id, &name, &encoding, &data)
                    .map_err(mcap_err)?;
            }
            Copied::Channel(c) => {
                writer
                    .add_channel_with_id(
                        c.id,
                        c.schema_id,
                        &c.topic,
                        &c.message_encoding,
                        &c.metadata,
                    )
                    .map_err(mcap_err)?;
            }
            Copied::Metadata(m) => writer.write_metadata(&m).map_err(mcap_err)?,
            Copied::Message { header, data } => {
                writer
                    .write_to_known_channel(&header, &data)
                    .map_err(mcap_err)?;
                messages += 1;
            }
        }
    }
    writer
        .write_metadata(&Metadata {
            name: METADATA_RECOVERY.to_string(),
            metadata: note,
        })
        .map_err(mcap_err)?;
    writer.finish().map_err(mcap_err)?;
    let file = writer
        .into_inner()
        .into_inner()
        .map_err(|e| RecordError::io(target, e.into_error()))?;
    file.sync_all().map_err(|e| RecordError::io(target, e))?;
    Ok(messages)
}
