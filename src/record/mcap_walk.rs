//! Walks the records of an MCAP file with every length bounded and every
//! CRC the file carries checked, and says at which byte the damage starts.
//!
//! Why not the `mcap` crate's `ChunkFlattener`: it puts no limit on the
//! length of a record inside a compressed chunk (one flipped bit there sizes
//! an allocation of exabytes) and checks no CRC unless asked. This walk
//! drives the crate's sans-io `LinearReader` in two layers instead:
//!
//! - the file: records one by one, chunks whole, none longer than the file,
//!   the data-section and summary-section CRCs checked;
//! - each chunk by itself, with a fresh reader whose length limit is
//!   [`chunk_limit`]: the chunk's uncompressed size, and so every record in
//!   it, is at most 16 times the file's size (at least 8 MiB), and the
//!   chunk's CRC is checked *before* any of its records is handed on, so a
//!   damaged chunk gives nothing.
//!
//! Header, schema, channel and metadata records are handed on only if their
//! length-prefixed strings lie inside the record (the parser reserves the
//! memory a string's length declares before it reads the string).
//!
//! Damage ends the walk: everything before it has been handed on and
//! [`Damage`] says where it was found. Records after the data section (the
//! summary) are walked, not handed on: damage there is reported too, after
//! the data.

use std::io::{self, Read};

use mcap::records::{op, Record};
use mcap::sans_io::{LinearReadEvent, LinearReader, LinearReaderOptions};
use mcap::{McapError, MAGIC};

use super::error::WalkError;

/// An opcode and a 64-bit length precede every record.
const RECORD_PREFIX: u64 = 1 + 8;

/// Where a walk stopped at damage, and why.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Damage {
    /// The byte offset in the file of the record (or chunk) found damaged.
    pub offset: u64,
    /// What is wrong there.
    pub reason: String,
}

/// The most bytes one chunk may decompress to (and so the longest record
/// in a chunk), for a file of `file_len` bytes: 16 times the file's size,
/// at least 8 MiB. A motorbench chunk holds 768 KiB uncompressed, and
/// compressed sample data is far above a sixteenth of that.
pub(crate) fn chunk_limit(file_len: usize) -> usize {
    file_len.saturating_mul(16).max(8 << 20)
}

/// Walks `bytes` as an MCAP file, calling `visit` with each header,
/// schema, metadata, channel and message record of its data section in file order,
/// chunks opened. Returns where damage ended the walk, if anywhere.
pub(crate) fn walk_records(bytes: &[u8], visit: &mut dyn FnMut(Record<'_>)) -> Option<Damage> {
    let mut source = bytes;
    walk_source(&mut source, bytes.len() as u64, visit)
        .unwrap_or_else(|_| unreachable!("reading a byte slice does not fail"))
}

/// [`walk_records`] over a file of `file_len` bytes read from `source`
/// as the walk goes: at most one record (a chunk, compressed) is held at
/// a time, so a walk's memory does not grow with the file. An error
/// reading `source` ends the walk as that error.
pub(crate) fn walk_source(
    source: &mut dyn Read,
    file_len: u64,
    visit: &mut dyn FnMut(Record<'_>),
) -> io::Result<Option<Damage>> {
    let file_len = usize::try_from(file_len).unwrap_or(usize::MAX);
    let options = LinearReaderOptions::default()
        .with_emit_chunks(true)
        .with_record_length_limit(file_len)
        .with_validate_data_section_crc(true)
        .with_validate_summary_section_crc(true);
    let mut reader = LinearReader::new_with_options(options);
    let limit = chunk_limit(file_len);
    // The file's first bytes, to tell a file that is not MCAP at all.
    let mut first = Vec::with_capacity(MAGIC.len());
    // Where the record being read starts (0: still at the start magic).
    let mut start = 0u64;
    let mut in_data_section = true;
    while let Some(event) = reader.next_event() {
        match event {
            Ok(LinearReadEvent::ReadRequest(need)) => {
                let buf = reader.insert(need);
                let n = read_some(source, buf)?;
                let wanted = n.min(MAGIC.len() - first.len());
                first.extend_from_slice(&buf[..wanted]);
                reader.notify_read(n);
            }
            Ok(LinearReadEvent::Record { opcode, data }) => {
                let at = start.max(MAGIC.len() as u64);
                start = at + RECORD_PREFIX + data.len() as u64;
                if !in_data_section {
                    continue;
                }
                let handed = match opcode {
                    op::CHUNK => walk_chunk(data, limit, visit),
                    op::DATA_END => {
                        in_data_section = false;
                        Ok(())
                    }
                    _ => hand_on(opcode, data, visit),
                };
                if let Err(reason) = handed {
                    return Ok(Some(Damage {
                        offset: at,
                        reason: reason.to_string(),
                    }));
                }
            }
            Err(e) => {
                let at_magic = start == 0 && !first.starts_with(MAGIC);
                let offset = if at_magic {
                    0
                } else {
                    start.max(MAGIC.len() as u64)
                };
                return Ok(Some(Damage {
                    offset,
                    reason: describe(&e),
                }));
            }
        }
    }
    Ok(None)
}

/// Reads one chunk record (`body`: the chunk's body) with its own
/// reader, handing its records on once its CRC has been checked.
fn walk_chunk(
    body: &[u8],
    limit: usize,
    visit: &mut dyn FnMut(Record<'_>),
) -> Result<(), WalkError> {
    let options = LinearReaderOptions::default()
        .with_skip_start_magic(true)
        .with_skip_end_magic(true)
        .with_prevalidate_chunk_crcs(true)
        .with_record_length_limit(limit);
    let mut reader = LinearReader::new_with_options(options);
    // The reader reads the chunk as a record: opcode, length, body.
    let mut prefix = [op::CHUNK; RECORD_PREFIX as usize];
    prefix[1..].copy_from_slice(&(body.len() as u64).to_le_bytes());
    let mut record = (&prefix[..]).chain(body);
    while let Some(event) = reader.next_event() {
        match event {
            Ok(LinearReadEvent::ReadRequest(need)) => {
                let n = read_some(&mut record, reader.insert(need))
                    .unwrap_or_else(|_| unreachable!("reading bytes in memory does not fail"));
                reader.notify_read(n);
            }
            Ok(LinearReadEvent::Record { opcode, data }) => {
                hand_on(opcode, data, visit).map_err(|e| WalkError::InChunk(Box::new(e)))?
            }
            Err(e) => return Err(WalkError::InChunk(Box::new(WalkError::Mcap(describe(&e))))),
        }
    }
    Ok(())
}

/// Reads what `source` gives into `buf` (0: the end), retrying an
/// interrupted read.
fn read_some(source: &mut dyn Read, buf: &mut [u8]) -> io::Result<usize> {
    loop {
        match source.read(buf) {
            Err(e) if e.kind() == io::ErrorKind::Interrupted => continue,
            read => return read,
        }
    }
}

/// Parses and visits a record the reader uses; skips the others.
fn hand_on(opcode: u8, body: &[u8], visit: &mut dyn FnMut(Record<'_>)) -> Result<(), WalkError> {
    if !matches!(
        opcode,
        op::HEADER | op::SCHEMA | op::METADATA | op::CHANNEL | op::MESSAGE
    ) {
        return Ok(());
    }
    if !strings_fit(opcode, body) {
        return Err(WalkError::StringOverrun {
            opcode,
            len: body.len(),
        });
    }
    let record = mcap::parse_record(opcode, body).map_err(|e| WalkError::Mcap(describe(&e)))?;
    visit(record);
    Ok(())
}

/// Whether the length-prefixed strings (and the string map) of a header,
/// channel or metadata record lie inside the record.
fn strings_fit(opcode: u8, body: &[u8]) -> bool {
    // Bytes before the first string, strings before the map, whether a map.
    let (fixed, strings, map) = match opcode {
        op::HEADER => (0, 2, false),
        op::SCHEMA => (2, 3, false),
        op::CHANNEL => (4, 2, true),
        op::METADATA => (0, 1, true),
        _ => return true,
    };
    let Some(mut rest) = body.get(fixed..) else {
        return false;
    };
    for _ in 0..strings {
        let Some((_, after)) = split_prefixed(rest) else {
            return false;
        };
        rest = after;
    }
    if !map {
        return true;
    }
    let Some((mut entries, _)) = split_prefixed(rest) else {
        return false;
    };
    while !entries.is_empty() {
        let Some((_, after)) = split_prefixed(entries) else {
            return false;
        };
        entries = after;
    }
    true
}

/// Splits a field with a 32-bit length prefix off the front of `bytes`:
/// (the field, the rest); None if the field does not fit.
fn split_prefixed(bytes: &[u8]) -> Option<(&[u8], &[u8])> {
    let (len, rest) = bytes.split_first_chunk::<4>()?;
    let len = usize::try_from(u32::from_le_bytes(*len)).ok()?;
    (len <= rest.len()).then(|| rest.split_at(len))
}

/// The error and its causes, on one line.
fn describe(e: &McapError) -> String {
    let mut text = e.to_string();
    let mut source = std::error::Error::source(e);
    while let Some(cause) = source {
        text.push_str(": ");
        text.push_str(&cause.to_string().replace('\n', " "));
        source = cause.source();
    }
    if matches!(e, McapError::BadDataCrc { .. }) {
        text.push_str(
            " (every chunk matches its own CRC: the damage is outside the chunks' \
             contents, e.g. in the metadata or a chunk header)",
        );
    }
    text
}

#[cfg(test)]
mod tests {
    use super::*;

    fn prefixed(s: &[u8]) -> Vec<u8> {
        let mut v = (s.len() as u32).to_le_bytes().to_vec();
        v.extend_from_slice(s);
        v
    }

    #[test]
    fn strings_that_overrun_their_record_are_caught() {
        let mut map = prefixed(b"key");
        map.extend(prefixed(b"value"));
        let mut metadata = prefixed(b"name");
        metadata.extend(prefixed(&map));
        assert!(strings_fit(op::METADATA, &metadata));
        // The name claims 4 GiB.
        let mut bad = metadata.clone();
        bad[..4].copy_from_slice(&u32::MAX.to_le_bytes());
        assert!(!strings_fit(op::METADATA, &bad));
        // A map entry runs past the map.
        let mut bad = metadata.clone();
        bad[8 + 4] = 200;
        assert!(!strings_fit(op::METADATA, &bad));
        assert!(!strings_fit(op::METADATA, &metadata[..metadata.len() - 1]));
        assert!(!strings_fit(op::CHANNEL, &[0, 0, 0]));
    }

    #[test]
    fn chunk_limit_has_a_floor_and_scales() {
        assert_eq!(chunk_limit(0), 8 << 20);
        assert_eq!(chunk_limit(1 << 20), 16 << 20);
        assert_eq!(chunk_limit(usize::MAX), usize::MAX);
    }
}
