//! The ASCII line protocol: `$MB,<seq>,<t_us>,<name>=<value>,…*HH\r\n`.
//!
//! - `seq`: decimal u32, +1 per record, wraps.
//! - `t_us`: decimal u64, the device's time of the readings in µs.
//! - `name=value`: one or more; names are `[A-Za-z0-9_]+`, values decimal
//!   floats (`1.5`, `-2e-3`).
//! - `HH`: XOR of every byte between `$` and `*`, two hex digits (either
//!   case accepted, upper case sent), as in NMEA 0183.
//! - A line is at most [`MAX_LINE`] bytes; `\r` is optional before `\n`.
//!
//! Example: `$MB,17,1250000,u=60.02,i=0.113*HH\r\n` ([`encode`] computes
//! `HH`).

use super::{DecodeCounts, StreamRecord};

/// Longest line accepted, `$` to `\n`.
pub const MAX_LINE: usize = 512;

/// The XOR checksum of `body` (the bytes between `$` and `*`).
pub fn checksum(body: &[u8]) -> u8 {
    body.iter().fold(0, |a, b| a ^ b)
}

/// Encode a record as one line, `\r\n` included.
pub fn encode(record: &StreamRecord) -> Vec<u8> {
    let mut body = format!("MB,{},{}", record.seq, record.t_us);
    for (name, v) in &record.values {
        body.push_str(&format!(",{name}={v}"));
    }
    format!("${body}*{:02X}\r\n", checksum(body.as_bytes())).into_bytes()
}

/// Parse one line's body (between `$` and `*`) into a record.
fn parse_body(body: &str) -> Option<StreamRecord> {
    let mut fields = body.split(',');
    if fields.next()? != "MB" {
        return None;
    }
    let seq = fields.next()?.parse().ok()?;
    let t_us = fields.next()?.parse().ok()?;
    let mut values = Vec::new();
    for f in fields {
        let (name, v) = f.split_once('=')?;
        if name.is_empty() || !name.bytes().all(|c| c.is_ascii_alphanumeric() || c == b'_') {
            return None;
        }
        let v: f64 = v.parse().ok()?;
        values.push((name.to_string(), v));
    }
    (!values.is_empty()).then_some(StreamRecord { seq, t_us, values })
}

/// Incremental decoder: feed bytes, take records.
#[derive(Debug, Default)]
pub struct AsciiDecoder {
    line: Vec<u8>,
    in_line: bool,
    counts: DecodeCounts,
}

impl AsciiDecoder {
    /// A decoder waiting for the first `$`.
    pub fn new() -> AsciiDecoder {
        AsciiDecoder::default()
    }

    /// What it decoded and refused so far.
    pub fn counts(&self) -> DecodeCounts {
        self.counts
    }

    /// Feed bytes; decoded records are appended to `out`.
    pub fn feed(&mut self, bytes: &[u8], out: &mut Vec<StreamRecord>) {
        for &b in bytes {
            if b == b'$' {
                // A `$` always starts a new line: a line cut short by a
                // glitch is refused, and the next one is read whole.
                if self.in_line {
                    self.counts.rejected += 1;
                }
                self.line.clear();
                self.in_line = true;
                continue;
            }
            if !self.in_line {
                self.counts.skipped_bytes += 1;
                continue;
            }
            if b == b'\n' {
                self.in_line = false;
                match self.finish_line() {
                    Some(r) => {
                        self.counts.records += 1;
                        out.push(r);
                    }
                    None => self.counts.rejected += 1,
                }
                continue;
            }
            if self.line.len() >= MAX_LINE {
                self.in_line = false;
                self.counts.rejected += 1;
                continue;
            }
            self.line.push(b);
        }
    }

    fn finish_line(&mut self) -> Option<StreamRecord> {
        let mut line = self.line.as_slice();
        if line.last() == Some(&b'\r') {
            line = &line[..line.len() - 1];
        }
        let star = line.iter().rposition(|&c| c == b'*')?;
        let (body, sum) = (&line[..star], &line[star + 1..]);
        let sum = std::str::from_utf8(sum).ok()?;
        if sum.len() != 2 || u8::from_str_radix(sum, 16).ok()? != checksum(body) {
            return None;
        }
        parse_body(std::str::from_utf8(body).ok()?)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rec(seq: u32) -> StreamRecord {
        StreamRecord {
            seq,
            t_us: 1_250_000 + u64::from(seq) * 500,
            values: vec![("u".into(), 60.02), ("i".into(), -0.113)],
        }
    }

    #[test]
    fn checksum_matches_a_published_nmea_sentence() {
        // The widely quoted GPGGA example sentence and its checksum 47.
        let body = b"GPGGA,123519,4807.038,N,01131.000,E,1,08,0.9,545.4,M,46.9,M,,";
        assert_eq!(checksum(body), 0x47);
    }

    #[test]
    fn encoded_lines_decode_to_the_same_record() {
        let mut d = AsciiDecoder::new();
        let mut out = Vec::new();
        d.feed(&encode(&rec(1)), &mut out);
        assert_eq!(out, vec![rec(1)]);
        let line = String::from_utf8(encode(&rec(1))).unwrap();
        assert!(
            line.starts_with("$MB,1,1250500,u=60.02,i=-0.113*"),
            "{line}"
        );
    }

    #[test]
    fn resynchronises_after_garbage_and_refuses_bad_lines() {
        let mut bytes = b"\x00\xFFnoise".to_vec();
        bytes.extend(encode(&rec(1)));
        let mut corrupt = encode(&rec(2));
        corrupt[8] ^= 0x01; // one bit flipped: checksum fails
        bytes.extend(corrupt);
        let cut = encode(&rec(3));
        bytes.extend(&cut[..10]); // cut short, then a new line starts
        bytes.extend(encode(&rec(4)));
        bytes.extend(b"$MB,5,1,x=1*00\r\n"); // wrong checksum
        bytes.push(b'$'); // an overlong line: refused at MAX_LINE bytes
        bytes.extend(vec![b'a'; MAX_LINE + 10]);
        bytes.push(b'\n');
        bytes.extend(encode(&rec(6)));
        let mut d = AsciiDecoder::new();
        let mut out = Vec::new();
        // Byte by byte: the decoder must not depend on read boundaries.
        for b in &bytes {
            d.feed(std::slice::from_ref(b), &mut out);
        }
        let seqs: Vec<u32> = out.iter().map(|r| r.seq).collect();
        assert_eq!(seqs, vec![1, 4, 6]);
        let c = d.counts();
        assert_eq!(c.records, 3);
        assert_eq!(
            c.rejected, 4,
            "corrupt, cut short, wrong checksum, overlong"
        );
        // 7 bytes of noise; of the overlong line, the bytes after the one
        // that overflowed it (9 × `a` and its `\n`).
        assert_eq!(c.skipped_bytes, 7 + 10);
    }

    #[test]
    fn syntax_errors_are_refused() {
        for body in [
            "XX,1,2,a=1",
            "MB,1,2",
            "MB,x,2,a=1",
            "MB,1,2,a",
            "MB,1,2,=1",
            "MB,1,2,a-b=1",
            "MB,1,2,a=z",
        ] {
            let line = format!("${body}*{:02X}\n", checksum(body.as_bytes()));
            let mut d = AsciiDecoder::new();
            let mut out = Vec::new();
            d.feed(line.as_bytes(), &mut out);
            assert!(out.is_empty(), "{body}");
            assert_eq!(d.counts().rejected, 1, "{body}");
        }
    }
}
