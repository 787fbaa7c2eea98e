//! SLCAN: the Lawicel ASCII protocol spoken by USB-CAN adapters
//! (CANable, CANUSB, many clones) over a serial line.
//!
//! Host to adapter: `C` close, `Sn` bitrate (`S0` 10 kbit/s … `S8`
//! 1 Mbit/s), `O` open (or `L` listen only), then frames. Each command
//! ends in `\r`; the adapter answers `\r` (OK) or `\a` (BEL, error), and
//! after a transmitted frame some adapters answer `z\r` / `Z\r`.
//!
//! Frames, both directions: `tIIILDD…` (11-bit id, 3 hex digits),
//! `TIIIIIIIILDD…` (29-bit id, 8 hex digits), `rIIIL` / `RIIIIIIIIL`
//! (remote frames), `L` the data length 0–8, `DD` one byte in hex each;
//! an adapter with timestamps on (`Z1`) appends 4 hex digits of
//! milliseconds.
//!
//! The reader splits the byte stream at `\r` and `\a`, so it resynchronises
//! on the next line after any garbage; a line that is not valid is counted
//! and skipped, and a runaway line without terminator is dropped.

use std::collections::VecDeque;
use std::time::Duration;

use async_trait::async_trait;
use tokio::io::{AsyncRead, AsyncReadExt, AsyncWrite, AsyncWriteExt};

use super::{CanFrame, CanId, FrameStream};
use crate::DriverError;

/// Longest line the reader accepts (an extended frame with 8 bytes and a
/// timestamp is 30 characters).
const MAX_LINE: usize = 64;

/// CAN bitrates selectable with the `Sn` command.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SlcanBitrate {
    /// 10 kbit/s (`S0`).
    K10,
    /// 20 kbit/s (`S1`).
    K20,
    /// 50 kbit/s (`S2`).
    K50,
    /// 100 kbit/s (`S3`).
    K100,
    /// 125 kbit/s (`S4`).
    K125,
    /// 250 kbit/s (`S5`).
    K250,
    /// 500 kbit/s (`S6`).
    K500,
    /// 800 kbit/s (`S7`).
    K800,
    /// 1 Mbit/s (`S8`).
    M1,
}

impl SlcanBitrate {
    /// The bitrate for `bits_per_s`, if the protocol has a code for it.
    pub fn from_bits_per_s(bits_per_s: u32) -> Option<SlcanBitrate> {
        use SlcanBitrate::*;
        Some(match bits_per_s {
            10_000 => K10,
            20_000 => K20,
            50_000 => K50,
            100_000 => K100,
            125_000 => K125,
            250_000 => K250,
            500_000 => K500,
            800_000 => K800,
            1_000_000 => M1,
            _ => return None,
        })
    }

    fn code(self) -> u8 {
        self as u8
    }
}

/// How to open an adapter.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SlcanOptions {
    /// Bitrate to set before opening; `None` keeps the adapter's own.
    pub bitrate: Option<SlcanBitrate>,
    /// Open listen-only (`L`): receive, never acknowledge or send.
    pub listen_only: bool,
    /// Wait this long for the adapter's answer to each setup command and
    /// fail on an error answer or none. `None`: send the commands without
    /// waiting (for peers that do not answer, such as another host).
    pub ack_timeout: Option<Duration>,
}

impl Default for SlcanOptions {
    fn default() -> Self {
        SlcanOptions {
            bitrate: Some(SlcanBitrate::K500),
            listen_only: false,
            ack_timeout: Some(Duration::from_millis(200)),
        }
    }
}

/// One line read from an SLCAN stream.
#[derive(Debug, Clone, PartialEq)]
pub enum SlcanLine {
    /// A received frame, with the adapter's millisecond timestamp if on.
    Frame(CanFrame, Option<u16>),
    /// `\r` alone: the adapter accepted a command.
    Ok,
    /// `\a`: the adapter refused a command.
    Error,
    /// `z` / `Z`: the adapter queued a transmitted frame.
    Transmitted,
    /// Anything else that is well formed text: a version (`V…`), serial
    /// number (`N…`), status flags (`F…`) or a command echoed by a peer.
    Other(String),
    /// A line that cannot be valid.
    Malformed(String),
}

fn hex(s: &[u8]) -> Option<u32> {
    if s.is_empty() || s.len() > 8 {
        return None;
    }
    let mut v = 0u32;
    for &c in s {
        v = (v << 4) | (c as char).to_digit(16)?;
    }
    Some(v)
}

/// Decode one line (without its `\r`; a lone `\a` is passed as `b"\x07"`).
pub fn decode_line(line: &[u8]) -> SlcanLine {
    let bad =
        |why: &str| SlcanLine::Malformed(format!("{why}: {:?}", String::from_utf8_lossy(line)));
    let Some(&kind) = line.first() else {
        return SlcanLine::Ok;
    };
    let (id_len, extended, remote) = match kind {
        b't' => (3, false, false),
        b'T' => (8, true, false),
        b'r' => (3, false, true),
        b'R' => (8, true, true),
        0x07 if line.len() == 1 => return SlcanLine::Error,
        b'z' | b'Z' if line.len() == 1 => return SlcanLine::Transmitted,
        _ if line.iter().all(|c| c.is_ascii_graphic()) => {
            return SlcanLine::Other(String::from_utf8_lossy(line).into_owned())
        }
        _ => return bad("not a frame or known answer"),
    };
    if line.len() < 2 + id_len {
        return bad("too short");
    }
    let Some(raw_id) = hex(&line[1..1 + id_len]) else {
        return bad("id is not hex");
    };
    let id = if extended {
        CanId::Extended(raw_id)
    } else {
        CanId::Standard(raw_id as u16)
    };
    let dlc_char = line[1 + id_len];
    if !(b'0'..=b'8').contains(&dlc_char) {
        return bad("length is not 0-8");
    }
    let dlc = dlc_char - b'0';
    let rest = &line[2 + id_len..];
    let data_len = if remote { 0 } else { 2 * usize::from(dlc) };
    let timestamp = match rest.len().checked_sub(data_len) {
        Some(0) => None,
        Some(4) => match hex(&rest[data_len..]) {
            Some(t) => Some(t as u16),
            None => return bad("timestamp is not hex"),
        },
        _ => return bad("data length does not match its length code"),
    };
    let frame = if remote {
        CanFrame::remote(id, dlc)
    } else {
        let mut data = [0u8; 8];
        for (k, byte) in data.iter_mut().take(usize::from(dlc)).enumerate() {
            match hex(&rest[2 * k..2 * k + 2]) {
                Some(b) => *byte = b as u8,
                None => return bad("data is not hex"),
            }
        }
        CanFrame::new(id, &data[..usize::from(dlc)])
    };
    match frame {
        Ok(f) => SlcanLine::Frame(f, timestamp),
        Err(e) => bad(&e.to_string()),
    }
}

/// Encode a frame as an SLCAN line, `\r` included.
pub fn encode_frame(frame: &CanFrame) -> Vec<u8> {
    let kind = match (frame.id().is_extended(), frame.is_remote()) {
        (false, false) => 't',
        (true, false) => 'T',
        (false, true) => 'r',
        (true, true) => 'R',
    };
    let mut s = format!("{kind}{}{}", frame.id(), frame.dlc());
    for b in frame.data() {
        s.push_str(&format!("{b:02X}"));
    }
    s.push('\r');
    s.into_bytes()
}

/// Splits a byte stream into SLCAN lines; resynchronises after garbage.
#[derive(Debug, Default)]
struct LineSplitter {
    buf: Vec<u8>,
    overlong: bool,
}

impl LineSplitter {
    /// Feed bytes; complete lines go to `out` (the terminator removed, a BEL
    /// kept as its own line).
    fn feed(&mut self, bytes: &[u8], out: &mut VecDeque<SlcanLine>, dropped: &mut u64) {
        for &b in bytes {
            match b {
                b'\r' | 0x07 => {
                    if self.overlong {
                        *dropped += 1;
                    } else if b == b'\r' || !self.buf.is_empty() {
                        out.push_back(decode_line(&self.buf));
                    }
                    if b == 0x07 {
                        out.push_back(SlcanLine::Error);
                    }
                    self.buf.clear();
                    self.overlong = false;
                }
                b'\n' => {}
                _ if self.buf.len() >= MAX_LINE => self.overlong = true,
                _ => self.buf.push(b),
            }
        }
    }
}

/// A CAN interface behind an SLCAN adapter, over any byte stream.
#[derive(Debug)]
pub struct SlcanStream<T> {
    name: String,
    io: T,
    splitter: LineSplitter,
    lines: VecDeque<SlcanLine>,
    malformed: u64,
    adapter_errors: u64,
}

impl<T: AsyncRead + AsyncWrite + Unpin + Send> SlcanStream<T> {
    /// Set up and open the adapter on `io` (`C`, then `Sn`, then `O`/`L`).
    pub async fn open(io: T, name: &str, opts: SlcanOptions) -> Result<Self, DriverError> {
        let mut s = SlcanStream {
            name: name.to_string(),
            io,
            splitter: LineSplitter::default(),
            lines: VecDeque::new(),
            malformed: 0,
            adapter_errors: 0,
        };
        // Close first: the adapter may have been left open; an error
        // answer to this one only means "was not open".
        s.command(b"C", opts.ack_timeout).await?;
        if let Some(rate) = opts.bitrate {
            s.command(&[b'S', b'0' + rate.code()], opts.ack_timeout)
                .await?;
        }
        let open: &[u8] = if opts.listen_only { b"L" } else { b"O" };
        s.command(open, opts.ack_timeout).await?;
        Ok(s)
    }

    /// Error answers (BEL) the adapter gave after opening.
    pub fn adapter_errors(&self) -> u64 {
        self.adapter_errors
    }

    /// Send a command; wait for its answer when `ack` is given.
    async fn command(&mut self, cmd: &[u8], ack: Option<Duration>) -> Result<(), DriverError> {
        let mut line = cmd.to_vec();
        line.push(b'\r');
        self.write(&line).await?;
        let Some(wait) = ack else { return Ok(()) };
        let deadline = tokio::time::Instant::now() + wait;
        loop {
            while let Some(l) = self.lines.pop_front() {
                match l {
                    SlcanLine::Ok => return Ok(()),
                    SlcanLine::Error if cmd == b"C" => return Ok(()),
                    SlcanLine::Error => {
                        return Err(DriverError::Device {
                            device: self.name.clone(),
                            reason: format!("adapter refused `{}`", String::from_utf8_lossy(cmd)),
                        })
                    }
                    // A frame from a bus already open: keep it for recv.
                    SlcanLine::Frame(..) => {
                        self.lines.push_front(l);
                        return Ok(());
                    }
                    _ => {}
                }
            }
            match tokio::time::timeout_at(deadline, self.fill()).await {
                Ok(r) => r?,
                Err(_) if cmd == b"C" => return Ok(()),
                Err(_) => {
                    return Err(DriverError::Timeout {
                        device: self.name.clone(),
                        timeout_ms: wait.as_millis() as u64,
                    })
                }
            }
        }
    }

    async fn write(&mut self, bytes: &[u8]) -> Result<(), DriverError> {
        let r = async {
            self.io.write_all(bytes).await?;
            self.io.flush().await
        }
        .await;
        r.map_err(|e| DriverError::Link {
            device: self.name.clone(),
            reason: e.to_string(),
        })
    }

    /// Read once from the stream into the line queue (cancel-safe).
    async fn fill(&mut self) -> Result<(), DriverError> {
        let mut buf = [0u8; 512];
        let n = self
            .io
            .read(&mut buf)
            .await
            .map_err(|e| DriverError::Link {
                device: self.name.clone(),
                reason: e.to_string(),
            })?;
        if n == 0 {
            return Err(DriverError::Ended {
                device: self.name.clone(),
            });
        }
        let mut dropped = 0;
        self.splitter.feed(&buf[..n], &mut self.lines, &mut dropped);
        self.malformed += dropped;
        Ok(())
    }
}

#[async_trait]
impl<T: AsyncRead + AsyncWrite + Unpin + Send> FrameStream for SlcanStream<T> {
    fn id(&self) -> &str {
        &self.name
    }

    async fn send(&mut self, frame: &CanFrame) -> Result<(), DriverError> {
        self.write(&encode_frame(frame)).await
    }

    fn malformed(&self) -> u64 {
        self.malformed
    }

    async fn recv(&mut self) -> Result<CanFrame, DriverError> {
        loop {
            while let Some(line) = self.lines.pop_front() {
                match line {
                    SlcanLine::Frame(f, _) => return Ok(f),
                    SlcanLine::Malformed(_) => self.malformed += 1,
                    SlcanLine::Error => self.adapter_errors += 1,
                    SlcanLine::Ok | SlcanLine::Transmitted | SlcanLine::Other(_) => {}
                }
            }
            self.fill().await?;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn frame(id: CanId, data: &[u8]) -> CanFrame {
        CanFrame::new(id, data).unwrap()
    }

    #[test]
    fn encodes_the_lawicel_forms() {
        let f = frame(CanId::Standard(0x123), &[0xDE, 0xAD]);
        assert_eq!(encode_frame(&f), b"t1232DEAD\r");
        let f = frame(CanId::Extended(0x18FF_0001), &[]);
        assert_eq!(encode_frame(&f), b"T18FF00010\r");
        let r = CanFrame::remote(CanId::Standard(0x7FF), 8).unwrap();
        assert_eq!(encode_frame(&r), b"r7FF8\r");
    }

    #[test]
    fn decodes_what_it_encodes_and_timestamps() {
        for f in [
            frame(CanId::Standard(0), &[]),
            frame(CanId::Standard(0x7FF), &[1, 2, 3, 4, 5, 6, 7, 8]),
            frame(CanId::Extended(0x1FFF_FFFF), &[0xFF]),
            CanFrame::remote(CanId::Extended(5), 3).unwrap(),
        ] {
            let line = encode_frame(&f);
            assert_eq!(
                decode_line(&line[..line.len() - 1]),
                SlcanLine::Frame(f.clone(), None)
            );
        }
        assert_eq!(
            decode_line(b"t1231AA1F40"),
            SlcanLine::Frame(frame(CanId::Standard(0x123), &[0xAA]), Some(0x1F40))
        );
        assert_eq!(decode_line(b"t12"), decode_line(b"t12"));
        assert!(matches!(decode_line(b"t12"), SlcanLine::Malformed(_)));
        assert!(matches!(decode_line(b"t1232AA"), SlcanLine::Malformed(_)));
        assert!(matches!(decode_line(b"t1239AA"), SlcanLine::Malformed(_)));
        assert!(matches!(decode_line(b"tG231AA"), SlcanLine::Malformed(_)));
        assert!(matches!(decode_line(b"t8001AA"), SlcanLine::Malformed(_)));
        assert_eq!(decode_line(b"V1013"), SlcanLine::Other("V1013".into()));
        assert_eq!(decode_line(b"z"), SlcanLine::Transmitted);
        assert_eq!(decode_line(b""), SlcanLine::Ok);
    }

    #[test]
    fn splitter_resynchronises_after_garbage() {
        let mut s = LineSplitter::default();
        let mut out = VecDeque::new();
        let mut dropped = 0;
        let mut bytes = b"t1231AA\r\x00\xFFjunk\rt4560\r".to_vec();
        bytes.extend(std::iter::repeat_n(b'x', 200));
        bytes.extend(b"\r\x07t0011BB\r");
        s.feed(&bytes, &mut out, &mut dropped);
        let frames: Vec<_> = out
            .iter()
            .filter_map(|l| match l {
                SlcanLine::Frame(f, _) => Some(f.id().raw()),
                _ => None,
            })
            .collect();
        assert_eq!(frames, vec![0x123, 0x456, 0x001]);
        assert_eq!(dropped, 1, "the runaway line");
        assert!(out.iter().any(|l| matches!(l, SlcanLine::Malformed(_))));
        assert!(out.contains(&SlcanLine::Error));
    }

    /// A minimal adapter on the other end of a duplex: answers OK to
    /// commands, BEL to an unknown bitrate, and echoes frames back.
    async fn adapter(mut io: tokio::io::DuplexStream, refuse_bitrate: bool) {
        let mut buf = Vec::new();
        let mut byte = [0u8; 1];
        while io.read(&mut byte).await.unwrap_or(0) == 1 {
            if byte[0] != b'\r' {
                buf.push(byte[0]);
                continue;
            }
            let answer: Vec<u8> = match buf.first() {
                Some(b'S') if refuse_bitrate => vec![0x07],
                Some(b't') | Some(b'T') => {
                    let mut a = b"z\r".to_vec();
                    a.extend(&buf);
                    a.push(b'\r');
                    a
                }
                _ => b"\r".to_vec(),
            };
            buf.clear();
            if io.write_all(&answer).await.is_err() {
                return;
            }
        }
    }

    #[tokio::test]
    async fn opens_an_adapter_and_exchanges_frames() {
        let (host, dev) = tokio::io::duplex(256);
        tokio::spawn(adapter(dev, false));
        let mut s = SlcanStream::open(host, "can0", SlcanOptions::default())
            .await
            .unwrap();
        let f = frame(CanId::Standard(0x181), &[1, 2, 3, 4]);
        s.send(&f).await.unwrap();
        assert_eq!(s.recv().await.unwrap(), f);
        assert_eq!(s.malformed(), 0);
    }

    #[tokio::test(start_paused = true)]
    async fn a_refused_bitrate_is_a_device_error_and_silence_a_timeout() {
        let (host, dev) = tokio::io::duplex(256);
        tokio::spawn(adapter(dev, true));
        let err = SlcanStream::open(host, "can0", SlcanOptions::default())
            .await
            .unwrap_err();
        assert!(matches!(err, DriverError::Device { .. }), "{err}");

        let (host, _silent) = tokio::io::duplex(256);
        let err = SlcanStream::open(host, "can0", SlcanOptions::default())
            .await
            .unwrap_err();
        assert!(matches!(err, DriverError::Timeout { .. }), "{err}");
    }
}
