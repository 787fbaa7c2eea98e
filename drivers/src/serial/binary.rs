//! The binary framed protocol: COBS-framed records with a CRC-16.
//!
//! A record before framing (all little-endian):
//!
//! | offset | size | field |
//! |---|---|---|
//! | 0 | 1 | `0xB1` (format and version) |
//! | 1 | 4 | `seq`, u32, +1 per record, wraps |
//! | 5 | 8 | `t_us`, u64, the device's time of the readings in µs |
//! | 13 | 1 | `n`, the number of values, 1–[`MAX_VALUES`] |
//! | 14 | 8·n | the values, f64 (IEEE 754), channel 0 first |
//! | 14+8n | 2 | CRC-16/IBM-3740 (poly 0x1021, init 0xFFFF, not reflected; also known as CCITT-FALSE; Python `binascii.crc_hqx(data, 0xFFFF)`) of bytes 0..14+8n |
//!
//! The record is COBS-encoded (Consistent Overhead Byte Stuffing: no `0x00`
//! inside) and followed by one `0x00`. A receiver that joins mid-stream or
//! sees a corrupted byte drops everything up to the next `0x00` and goes
//! on with the next frame; the CRC refuses a frame damaged in between.
//! Values travel as f64 so that counters (an encoder count) stay exact.

use crc::{Crc, CRC_16_IBM_3740};

use super::{DecodeCounts, StreamRecord};

/// Format byte of a record.
pub const FORMAT: u8 = 0xB1;
/// Most values in one record.
pub const MAX_VALUES: usize = 32;
/// Largest framed record accepted (COBS adds at most 1 byte per 254).
pub const MAX_FRAME: usize = 14 + 8 * MAX_VALUES + 2 + 4;

const CRC16: Crc<u16> = Crc::<u16>::new(&CRC_16_IBM_3740);

/// The CRC of `bytes`.
pub fn crc16(bytes: &[u8]) -> u16 {
    CRC16.checksum(bytes)
}

/// Encode a record as one frame, the trailing `0x00` included. Only the
/// values are used (positionally); their names are ignored.
pub fn encode(record: &StreamRecord) -> Vec<u8> {
    assert!(
        (1..=MAX_VALUES).contains(&record.values.len()),
        "a record carries 1 to {MAX_VALUES} values"
    );
    let mut raw = Vec::with_capacity(16 + 8 * record.values.len());
    raw.push(FORMAT);
    raw.extend(record.seq.to_le_bytes());
    raw.extend(record.t_us.to_le_bytes());
    raw.push(record.values.len() as u8);
    for (_, v) in &record.values {
        raw.extend(v.to_le_bytes());
    }
    raw.extend(crc16(&raw).to_le_bytes());
    let mut framed = cobs::encode_vec(&raw);
    framed.push(0);
    framed
}

fn parse(raw: &[u8]) -> Option<StreamRecord> {
    if raw.len() < 16 || raw[0] != FORMAT {
        return None;
    }
    let (body, crc) = raw.split_at(raw.len() - 2);
    if crc16(body) != u16::from_le_bytes([crc[0], crc[1]]) {
        return None;
    }
    let n = usize::from(body[13]);
    if n == 0 || n > MAX_VALUES || body.len() != 14 + 8 * n {
        return None;
    }
    let seq = u32::from_le_bytes(body[1..5].try_into().ok()?);
    let t_us = u64::from_le_bytes(body[5..13].try_into().ok()?);
    let values = body[14..]
        .chunks_exact(8)
        .enumerate()
        .map(|(k, b)| {
            let v = f64::from_le_bytes(b.try_into().expect("chunks of 8"));
            (k.to_string(), v)
        })
        .collect();
    Some(StreamRecord { seq, t_us, values })
}

/// Incremental decoder: feed bytes, take records.
#[derive(Debug, Default)]
pub struct BinaryDecoder {
    frame: Vec<u8>,
    overlong: bool,
    synced: bool,
    counts: DecodeCounts,
}

impl BinaryDecoder {
    /// A decoder that drops bytes up to the first `0x00` (it cannot know
    /// whether it joined the stream at a frame start).
    pub fn new() -> BinaryDecoder {
        BinaryDecoder::default()
    }

    /// What it decoded and refused so far.
    pub fn counts(&self) -> DecodeCounts {
        self.counts
    }

    /// Feed bytes; decoded records are appended to `out`.
    pub fn feed(&mut self, bytes: &[u8], out: &mut Vec<StreamRecord>) {
        for &b in bytes {
            if !self.synced {
                if b == 0 {
                    self.synced = true;
                } else {
                    self.counts.skipped_bytes += 1;
                }
                continue;
            }
            if b != 0 {
                if self.frame.len() < MAX_FRAME {
                    self.frame.push(b);
                } else {
                    self.overlong = true;
                    self.counts.skipped_bytes += 1;
                }
                continue;
            }
            if self.frame.is_empty() {
                continue; // back-to-back delimiters: an idle line
            }
            let decoded = (!self.overlong)
                .then(|| cobs::decode_vec(&self.frame).ok())
                .flatten()
                .and_then(|raw| parse(&raw));
            match decoded {
                Some(r) => {
                    self.counts.records += 1;
                    out.push(r);
                }
                None => self.counts.rejected += 1,
            }
            self.frame.clear();
            self.overlong = false;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn rec(seq: u32, values: &[f64]) -> StreamRecord {
        StreamRecord {
            seq,
            t_us: 1_000_000 + u64::from(seq) * 500,
            values: values
                .iter()
                .enumerate()
                .map(|(k, v)| (k.to_string(), *v))
                .collect(),
        }
    }

    #[test]
    fn crc_matches_the_catalogue_check_value() {
        // CRC-16/IBM-3740 of "123456789" is 0x29B1 (the catalogue's check).
        assert_eq!(crc16(b"123456789"), 0x29B1);
    }

    #[test]
    fn a_frame_has_no_zero_inside_and_ends_in_one() {
        let f = encode(&rec(0, &[0.0, 0.0, 1.0]));
        assert_eq!(f.last(), Some(&0));
        assert!(!f[..f.len() - 1].contains(&0));
    }

    #[test]
    fn resynchronises_after_garbage_and_refuses_corruption() {
        let mut bytes = vec![0x13, 0x37, 0x00]; // joined mid-frame
        bytes.extend(encode(&rec(1, &[60.0, 0.1, 42.0])));
        let mut bad = encode(&rec(2, &[60.0, 0.1, 43.0]));
        bad[20] = bad[20] % 254 + 1; // a changed byte (never 0x00): refused
        bytes.extend(bad);
        bytes.extend([0x55; 5]); // noise, then the delimiter of the next frame
        bytes.extend(encode(&rec(3, &[61.0, 0.2, 44.0])));
        bytes.extend(vec![0x01; MAX_FRAME + 5]);
        bytes.push(0);
        bytes.extend(encode(&rec(4, &[1.0])));
        let mut d = BinaryDecoder::new();
        let mut out = Vec::new();
        for chunk in bytes.chunks(7) {
            d.feed(chunk, &mut out);
        }
        let seqs: Vec<u32> = out.iter().map(|r| r.seq).collect();
        assert_eq!(seqs, vec![1, 4]);
        assert_eq!(out[0], rec(1, &[60.0, 0.1, 42.0]));
        let c = d.counts();
        // Refused: the corrupted frame; the noise glued to frame 3 (one
        // frame as far as the delimiters tell); the overlong run.
        assert_eq!(c.rejected, 3);
        assert_eq!(c.skipped_bytes, 2 + 5, "before sync, and past MAX_FRAME");
    }

    proptest! {
        #![proptest_config(ProptestConfig { cases: 256, rng_seed: proptest::test_runner::RngSeed::Fixed(7), ..ProptestConfig::default() })]
        #[test]
        fn any_record_survives_framing(seq in any::<u32>(), t in any::<u64>(),
                                       values in proptest::collection::vec(-1e9f64..1e9, 1..=MAX_VALUES)) {
            let r = StreamRecord { seq, t_us: t, values: values.iter().enumerate().map(|(k, v)| (k.to_string(), *v)).collect() };
            let mut d = BinaryDecoder::new();
            let mut out = Vec::new();
            d.feed(&[0], &mut out);
            d.feed(&encode(&r), &mut out);
            prop_assert_eq!(out, vec![r]);
        }
    }
}
