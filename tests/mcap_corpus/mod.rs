//! A fuzz-style corpus of corrupted MCAP records, generated from one small
//! good record (`seed.mcap`, made by `make_seed.sh` from `seed.toml`) with
//! a fixed-seed generator, so the corpus is the same on every run and only
//! the seed is checked in.
//!
//! The cases: bit flips and cuts at random places, record and chunk
//! lengths forged to huge values (also inside a compressed chunk with its
//! CRC made to match, so only the reader's length limits stand between the
//! file and an allocation of exabytes), strings longer than their record,
//! and chunks whose CRC no longer matches their content.
//!
//! Set `MOTORBENCH_CORPUS_OUT=DIR` when running the tests that use it to
//! keep the corpus files in DIR (e.g. to measure the reader's memory on
//! them with `/usr/bin/time -v`).

use std::path::{Path, PathBuf};

/// The good record every case is made from.
pub fn seed() -> Vec<u8> {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/mcap_corpus/seed.mcap");
    std::fs::read(&path).expect("tests/mcap_corpus/seed.mcap")
}

/// One corrupted copy of the seed.
pub struct Case {
    /// File name: what was done, where.
    pub name: String,
    pub bytes: Vec<u8>,
    /// The byte offset of the record the reader must name as damaged,
    /// where the damage is forged into one record.
    pub damaged_record: Option<u64>,
}

/// A record of the file's top level: opcode, offset, length with prefix.
#[derive(Clone, Copy, Debug)]
pub struct TopRecord {
    pub opcode: u8,
    pub offset: usize,
    pub len: usize,
}

const CHUNK: u8 = 0x06;
const CHANNEL: u8 = 0x04;
const MESSAGE: u8 = 0x05;
const METADATA: u8 = 0x0C;
const PREFIX: usize = 9;

fn u64_at(b: &[u8], at: usize) -> u64 {
    u64::from_le_bytes(b[at..at + 8].try_into().unwrap())
}

fn u32_at(b: &[u8], at: usize) -> u32 {
    u32::from_le_bytes(b[at..at + 4].try_into().unwrap())
}

/// The top-level records of a good file, in order.
pub fn top_records(b: &[u8]) -> Vec<TopRecord> {
    let mut out = Vec::new();
    let mut at = 8;
    while at + PREFIX <= b.len() - 8 {
        let len = PREFIX + u64_at(b, at + 1) as usize;
        out.push(TopRecord {
            opcode: b[at],
            offset: at,
            len,
        });
        at += len;
    }
    out
}

/// The chunk records of a good file.
pub fn chunks(b: &[u8]) -> Vec<TopRecord> {
    top_records(b)
        .into_iter()
        .filter(|r| r.opcode == CHUNK)
        .collect()
}

/// Offsets inside a chunk record's body (from the record's start).
struct ChunkLayout {
    uncompressed_size: usize,
    crc: usize,
    compression_len: usize,
    compressed_size: usize,
    data: usize,
}

fn layout(b: &[u8], chunk: TopRecord) -> ChunkLayout {
    let body = chunk.offset + PREFIX;
    let compression_len = body + 28;
    let compressed_size = compression_len + 4 + u32_at(b, compression_len) as usize;
    ChunkLayout {
        uncompressed_size: body + 16,
        crc: body + 24,
        compression_len,
        compressed_size,
        data: compressed_size + 8,
    }
}

/// The seed with the chunk's decompressed records changed by `edit`,
/// recompressed, the chunk's sizes fixed and its CRC fixed too
/// (`fix_crc`) or left as it was.
fn rewrite_chunk(
    b: &[u8],
    chunk: TopRecord,
    fix_crc: bool,
    edit: impl FnOnce(&mut Vec<u8>),
) -> Vec<u8> {
    let l = layout(b, chunk);
    let compressed = &b[l.data..l.data + u64_at(b, l.compressed_size) as usize];
    let mut records = zstd::decode_all(compressed).unwrap();
    edit(&mut records);
    let packed = zstd::encode_all(&records[..], 3).unwrap();
    let mut body = b[chunk.offset + PREFIX..l.data].to_vec();
    let at = |abs: usize| abs - chunk.offset - PREFIX;
    body[at(l.uncompressed_size)..at(l.uncompressed_size) + 8]
        .copy_from_slice(&(records.len() as u64).to_le_bytes());
    if fix_crc {
        body[at(l.crc)..at(l.crc) + 4].copy_from_slice(&crc32fast::hash(&records).to_le_bytes());
    }
    body[at(l.compressed_size)..at(l.compressed_size) + 8]
        .copy_from_slice(&(packed.len() as u64).to_le_bytes());
    body.extend_from_slice(&packed);
    let mut out = b[..chunk.offset].to_vec();
    out.push(CHUNK);
    out.extend_from_slice(&(body.len() as u64).to_le_bytes());
    out.extend_from_slice(&body);
    out.extend_from_slice(&b[chunk.offset + chunk.len..]);
    out
}

/// Offset of the first record with `opcode` in a chunk's records.
fn first_in_chunk(records: &[u8], opcode: u8) -> usize {
    let mut at = 0;
    while records[at] != opcode {
        at += PREFIX + u64_at(records, at + 1) as usize;
    }
    at
}

/// A small deterministic generator (SplitMix64).
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    fn below(&mut self, n: usize) -> usize {
        (self.next() % n as u64) as usize
    }
}

fn with(b: &[u8], at: usize, bytes: &[u8]) -> Vec<u8> {
    let mut out = b.to_vec();
    out[at..at + bytes.len()].copy_from_slice(bytes);
    out
}

/// The whole corpus: `flips` bit flips and `cuts` cuts at random places,
/// then the forged cases.
pub fn corpus(b: &[u8], flips: usize, cuts: usize) -> Vec<Case> {
    let mut rng = Rng(0x6d63_6170);
    let mut out = Vec::new();
    for _ in 0..flips {
        let bit = rng.below(b.len() * 8);
        let mut bytes = b.to_vec();
        bytes[bit / 8] ^= 1 << (bit % 8);
        out.push(Case {
            name: format!("flip-byte{}-bit{}", bit / 8, bit % 8),
            bytes,
            damaged_record: None,
        });
    }
    for _ in 0..cuts {
        let n = rng.below(b.len());
        out.push(Case {
            name: format!("cut-at{n}"),
            bytes: b[..n].to_vec(),
            damaged_record: None,
        });
    }
    out.extend(forged(b));
    out
}

/// Lengths forged to huge values, strings longer than their record, CRCs
/// that do not match: each names the record the reader must stop at.
pub fn forged(b: &[u8]) -> Vec<Case> {
    let records = top_records(b);
    let chunks = chunks(b);
    let middle = chunks[chunks.len() / 2];
    let mut out = Vec::new();
    let mut case = |name: String, bytes: Vec<u8>, at: usize| {
        out.push(Case {
            name,
            bytes,
            damaged_record: Some(at as u64),
        })
    };
    // The first record of every kind claims more than the file holds.
    let mut seen = Vec::new();
    for r in &records {
        if seen.contains(&r.opcode) {
            continue;
        }
        seen.push(r.opcode);
        for (tag, len) in [("max", u64::MAX), ("past-end", b.len() as u64)] {
            case(
                format!("len-{tag}-op{:02x}-at{}", r.opcode, r.offset),
                with(b, r.offset + 1, &len.to_le_bytes()),
                r.offset,
            );
        }
    }
    let l = layout(b, middle);
    let at = middle.offset;
    for (tag, size) in [("max", u64::MAX), ("1TiB", 1 << 40)] {
        case(
            format!("chunk-uncompressed-{tag}-at{at}"),
            with(b, l.uncompressed_size, &size.to_le_bytes()),
            at,
        );
    }
    case(
        format!("chunk-compressed-max-at{at}"),
        with(b, l.compressed_size, &u64::MAX.to_le_bytes()),
        at,
    );
    case(
        format!("chunk-compression-name-max-at{at}"),
        with(b, l.compression_len, &u32::MAX.to_le_bytes()),
        at,
    );
    // Only the CRC is wrong: the data is intact.
    let crc = u32_at(b, l.crc) ^ 1;
    case(
        format!("chunk-crc-wrong-at{at}"),
        with(b, l.crc, &crc.to_le_bytes()),
        at,
    );
    // The data changed (a digit of a sample value), the CRC did not.
    let changed = rewrite_chunk(b, middle, false, |r| {
        let m = first_in_chunk(r, MESSAGE);
        let digit = (m + PREFIX + 22..r.len())
            .find(|&i| r[i].is_ascii_digit())
            .unwrap();
        r[digit] = if r[digit] == b'9' { b'8' } else { r[digit] + 1 };
    });
    case(format!("chunk-content-changed-at{at}"), changed, at);
    // Inside a compressed chunk whose CRC matches: a message claiming
    // 2^62 bytes, the first channel's topic claiming 4 GiB.
    let huge_message = rewrite_chunk(b, middle, true, |r| {
        let m = first_in_chunk(r, MESSAGE);
        r[m + 1..m + PREFIX].copy_from_slice(&(1u64 << 62).to_le_bytes());
    });
    case(
        format!("message-len-2e62-in-chunk-at{at}"),
        huge_message,
        at,
    );
    let first = chunks[0];
    let long_topic = rewrite_chunk(b, first, true, |r| {
        let c = first_in_chunk(r, CHANNEL);
        r[c + PREFIX + 4..c + PREFIX + 8].copy_from_slice(&u32::MAX.to_le_bytes());
    });
    case(
        format!("channel-topic-4GiB-in-chunk-at{}", first.offset),
        long_topic,
        first.offset,
    );
    let metadata = records.iter().find(|r| r.opcode == METADATA).unwrap();
    case(
        format!("metadata-name-4GiB-at{}", metadata.offset),
        with(b, metadata.offset + PREFIX, &u32::MAX.to_le_bytes()),
        metadata.offset,
    );
    out
}

/// Writes the cases to files (in `MOTORBENCH_CORPUS_OUT` if set, else in
/// `dir`), returning each case with its path.
pub fn write(cases: Vec<Case>, dir: &Path) -> Vec<(Case, PathBuf)> {
    let dir = std::env::var_os("MOTORBENCH_CORPUS_OUT")
        .map(PathBuf::from)
        .unwrap_or_else(|| dir.to_path_buf());
    std::fs::create_dir_all(&dir).unwrap();
    cases
        .into_iter()
        .map(|c| {
            let path = dir.join(format!("{}.mcap", c.name));
            std::fs::write(&path, &c.bytes).unwrap();
            (c, path)
        })
        .collect()
}
