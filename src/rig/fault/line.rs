//! [`FaultyLine`]: a served RTU device's serial line with its line faults:
//! while a `crc_error` lasts each reply reaches the bench with its last
//! byte (its CRC) flipped; while `garbage` lasts, each reply comes after
//! a few bytes of noise. A relay between two byte streams (the end the
//! bench opens and the served device's line), the requests passed on as
//! they are, so that a pseudo-terminal, an in-process duplex or a real
//! line stand in alike.

use tokio::io::{AsyncRead, AsyncReadExt, AsyncWrite, AsyncWriteExt};

use super::ProtocolFaults;
use crate::config::FaultKind;

/// The noise put before each reply while `garbage` lasts.
pub const GARBAGE: [u8; 3] = [0xFF, 0x00, 0xFF];

/// A served device's line with its faults. See the module docs.
#[derive(Debug, Clone)]
pub struct FaultyLine {
    faults: ProtocolFaults,
}

impl FaultyLine {
    /// The line faults of `faults`.
    pub fn new(faults: ProtocolFaults) -> FaultyLine {
        FaultyLine { faults }
    }

    /// Whether `faults` has any line fault (else no relay is needed).
    pub fn needed(faults: &ProtocolFaults) -> bool {
        faults.has(FaultKind::CrcError) || faults.has(FaultKind::Garbage)
    }

    /// `chunk` of a reply as the bench receives it now.
    pub fn pass(&self, chunk: &[u8]) -> Vec<u8> {
        let mut out = Vec::with_capacity(chunk.len() + GARBAGE.len());
        if self.faults.acting(FaultKind::Garbage).is_some() {
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
    /// `device` (the served device's line) until either closes.
    pub async fn relay<B, D>(self, bench: B, device: D)
    where
        B: AsyncRead + AsyncWrite + Unpin,
        D: AsyncRead + AsyncWrite + Unpin,
    {
        let (mut bench_rx, mut bench_tx) = tokio::io::split(bench);
        let (mut device_rx, mut device_tx) = tokio::io::split(device);
        let requests = tokio::io::copy(&mut bench_rx, &mut device_tx);
        let replies = async {
            let mut buf = [0u8; 512];
            loop {
                let n = match device_rx.read(&mut buf).await {
                    Ok(0) | Err(_) => return,
                    Ok(n) => n,
                };
                if bench_tx.write_all(&self.pass(&buf[..n])).await.is_err() {
                    return;
                }
            }
        };
        tokio::select! {
            _ = requests => {}
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
        assert_eq!(line(FaultKind::CrcError).pass(&[1, 2, 3]), [1, 2, 0xFC]);
        assert_eq!(
            line(FaultKind::Garbage).pass(&[1, 2, 3]),
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
}
