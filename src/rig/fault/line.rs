//! [`FaultyLine`]: a served RTU device's serial line with its line faults:
//! while a `crc_error` lasts each reply reaches the bench with its last
//! byte (its CRC) flipped; while `garbage` lasts, each reply comes after
//! a few bytes of noise. A relay between two byte streams (the end the
//! bench opens and the served device's line), the requests passed on as
//! they are, so that a pseudo-terminal, an in-process duplex or a real
//! line stand in alike.
//!
//! On a request-and-reply line ([`FaultyLine::new`], Modbus RTU) the
//! noise goes before a reply's first byte only, as on a line where the
//! bench's request turned round a transceiver: a reply read in several
//! pieces gets no noise inside it. On a line the device talks on unasked
//! ([`FaultyLine::unasked`], an SLCAN adapter's stream), before each
//! piece it writes. (Noise inside a frame is not
//! what this fault models, and it gave the RTU decoder's resynchronising
//! a rare frame whose CRC matched by chance, one in 65 536 per try: a
//! wrong reading, not a skipped one.)

use std::sync::atomic::{AtomicBool, Ordering};

use tokio::io::{AsyncRead, AsyncReadExt, AsyncWrite, AsyncWriteExt};

use super::ProtocolFaults;
use crate::config::FaultKind;

/// The noise put before each reply while `garbage` lasts.
pub const GARBAGE: [u8; 3] = [0xFF, 0x00, 0xFF];

/// A served device's line with its faults. See the module docs.
#[derive(Debug, Clone)]
pub struct FaultyLine {
    faults: ProtocolFaults,
    unasked: bool,
}

impl FaultyLine {
    /// The line faults of `faults` on a line where the device only
    /// replies to requests.
    pub fn new(faults: ProtocolFaults) -> FaultyLine {
        FaultyLine {
            faults,
            unasked: false,
        }
    }

    /// The line faults of `faults` on a line the device talks on unasked.
    pub fn unasked(faults: ProtocolFaults) -> FaultyLine {
        FaultyLine {
            faults,
            unasked: true,
        }
    }

    /// Whether `faults` has any line fault (else no relay is needed).
    pub fn needed(faults: &ProtocolFaults) -> bool {
        faults.has(FaultKind::CrcError) || faults.has(FaultKind::Garbage)
    }

    /// `chunk` of a reply as the bench receives it now; `first` when it
    /// is the reply's first piece (only that one gets the noise).
    pub fn pass(&self, chunk: &[u8], first: bool) -> Vec<u8> {
        let mut out = Vec::with_capacity(chunk.len() + GARBAGE.len());
        if first && self.faults.acting(FaultKind::Garbage).is_some() {
            out.extend_from_slice(&GARBAGE);
        }
        out.extend_from_slice(chunk);
        if self.faults.acting(FaultKind::CrcError).is_some() {
            if let Some(last) = out.last_mut() {
                *last ^= 0xFF;
            }
        }
        out
    }

    /// Relay between `bench` (the end the bench's client opens) and
    /// `device` (the served device's line) until either closes. A reply
    /// starts with the first byte the device sends after a request.
    pub async fn relay<B, D>(self, bench: B, device: D)
    where
        B: AsyncRead + AsyncWrite + Unpin,
        D: AsyncRead + AsyncWrite + Unpin,
    {
        let (mut bench_rx, mut bench_tx) = tokio::io::split(bench);
        let (mut device_rx, mut device_tx) = tokio::io::split(device);
        let reply_due = AtomicBool::new(true);
        let requests = async {
            let mut buf = [0u8; 512];
            loop {
                let n = match bench_rx.read(&mut buf).await {
                    Ok(0) | Err(_) => return,
                    Ok(n) => n,
                };
                reply_due.store(true, Ordering::Relaxed);
                if device_tx.write_all(&buf[..n]).await.is_err() {
                    return;
                }
            }
        };
        let replies = async {
            let mut buf = [0u8; 512];
            loop {
                let n = match device_rx.read(&mut buf).await {
                    Ok(0) | Err(_) => return,
                    Ok(n) => n,
                };
                let first = reply_due.swap(false, Ordering::Relaxed) || self.unasked;
                let out = self.pass(&buf[..n], first);
                if bench_tx.write_all(&out).await.is_err() {
                    return;
                }
            }
        };
        tokio::select! {
            () = requests => {}
            () = replies => {}
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn line(kind: FaultKind) -> FaultyLine {
        FaultyLine::new(ProtocolFaults::one(kind))
    }

    #[tokio::test]
    async fn replies_are_corrupted_and_requests_pass_as_they_are() {
        assert_eq!(
            line(FaultKind::CrcError).pass(&[1, 2, 3], true),
            [1, 2, 0xFC]
        );
        assert_eq!(
            line(FaultKind::Garbage).pass(&[1, 2, 3], true),
            [0xFF, 0x00, 0xFF, 1, 2, 3]
        );
        let (bench, mut bench_far) = tokio::io::duplex(64);
        let (device, mut device_far) = tokio::io::duplex(64);
        let relay = tokio::spawn(line(FaultKind::CrcError).relay(bench, device));
        bench_far.write_all(&[7, 8]).await.unwrap();
        let mut got = [0u8; 2];
        device_far.read_exact(&mut got).await.unwrap();
        assert_eq!(got, [7, 8]);
        device_far.write_all(&[9, 10]).await.unwrap();
        bench_far.read_exact(&mut got).await.unwrap();
        assert_eq!(got, [9, 0xF5]);
        relay.abort();
    }

    #[tokio::test]
    async fn the_noise_comes_before_a_reply_not_inside_it() {
        let (bench, mut bench_far) = tokio::io::duplex(64);
        let (device, mut device_far) = tokio::io::duplex(64);
        let relay = tokio::spawn(line(FaultKind::Garbage).relay(bench, device));
        for request in [[1u8, 3], [1, 4]] {
            bench_far.write_all(&request).await.unwrap();
            let mut got = [0u8; 2];
            device_far.read_exact(&mut got).await.unwrap();
            // The reply in two pieces, the second once the first is through.
            device_far.write_all(&[9, 10]).await.unwrap();
            let mut first = [0u8; 5];
            bench_far.read_exact(&mut first).await.unwrap();
            assert_eq!(first, [0xFF, 0x00, 0xFF, 9, 10]);
            device_far.write_all(&[11]).await.unwrap();
            let mut rest = [0u8; 1];
            bench_far.read_exact(&mut rest).await.unwrap();
            assert_eq!(rest, [11], "no noise inside the reply");
        }
        relay.abort();
    }
}
