//! Serial ports and pseudo-terminals as async byte streams.
//!
//! Ports open through tokio-serial with serialport's default features off
//! (no libudev). A pseudo-terminal pair stands in for a cable in tests and
//! for the simulated rig's serial devices: one end is kept here as a
//! stream, the other is opened by path by whoever plays the device.
//!
//! An opened port is a [`SerialLink`]: tokio-serial's `flush` is the
//! POSIX `tcdrain`, a blocking call that holds the runtime's worker thread
//! until the UART has sent every queued byte (8 ms for an 8-byte request
//! at 9 600 baud), and every task on that worker (the supervisor's among
//! them) waits with it. Written bytes are already the kernel's to send, as
//! a TCP stream's are, and every protocol here waits for its answer, not
//! for the line to empty; so a link's flush returns at once.

use std::io;
use std::pin::Pin;
use std::task::{Context, Poll};
use std::time::Duration;

use tokio::io::{AsyncRead, AsyncWrite, ReadBuf};
pub use tokio_serial::SerialStream;
use tokio_serial::{SerialPort, SerialPortBuilderExt};

use crate::DriverError;

/// Parity of a serial line.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Parity {
    /// No parity bit (8N1, 8N2).
    #[default]
    None,
    /// Even parity (8E1: the Modbus RTU default).
    Even,
    /// Odd parity.
    Odd,
}

/// How to open a serial port.
#[derive(Debug, Clone, PartialEq)]
pub struct SerialSettings {
    /// Device path, e.g. `/dev/ttyUSB0`.
    pub path: String,
    /// Bits per second.
    pub baud_rate: u32,
    /// Parity.
    pub parity: Parity,
    /// Stop bits, 1 or 2.
    pub stop_bits: u8,
}

impl SerialSettings {
    /// 8 data bits, no parity, 1 stop bit.
    pub fn new_8n1(path: &str, baud_rate: u32) -> SerialSettings {
        SerialSettings {
            path: path.to_string(),
            baud_rate,
            parity: Parity::None,
            stop_bits: 1,
        }
    }

    /// Bits on the wire per byte (start, 8 data, parity, stop).
    pub fn bits_per_byte(&self) -> u32 {
        1 + 8 + u32::from(self.parity != Parity::None) + u32::from(self.stop_bits)
    }
}

/// A serial port as an async byte stream whose `flush` does not wait for
/// the line to empty (see the module docs); reads and writes are the
/// port's.
#[derive(Debug)]
pub struct SerialLink<S = SerialStream>(S);

impl<S> SerialLink<S> {
    /// `port` behind a flush that returns at once.
    pub fn new(port: S) -> SerialLink<S> {
        SerialLink(port)
    }
}

impl<S: AsyncRead + Unpin> AsyncRead for SerialLink<S> {
    fn poll_read(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        buf: &mut ReadBuf<'_>,
    ) -> Poll<io::Result<()>> {
        Pin::new(&mut self.0).poll_read(cx, buf)
    }
}

impl<S: AsyncWrite + Unpin> AsyncWrite for SerialLink<S> {
    fn poll_write(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        buf: &[u8],
    ) -> Poll<io::Result<usize>> {
        Pin::new(&mut self.0).poll_write(cx, buf)
    }

    fn poll_flush(self: Pin<&mut Self>, _cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        // Not the port's flush: that blocks the worker in `tcdrain`.
        Poll::Ready(Ok(()))
    }

    fn poll_shutdown(self: Pin<&mut Self>, _cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        // tokio-serial's shutdown is its flush; closing is the drop's.
        Poll::Ready(Ok(()))
    }
}

/// Open a serial port as an async byte stream.
pub fn open_serial(s: &SerialSettings) -> Result<SerialLink, DriverError> {
    let parity = match s.parity {
        Parity::None => tokio_serial::Parity::None,
        Parity::Even => tokio_serial::Parity::Even,
        Parity::Odd => tokio_serial::Parity::Odd,
    };
    let stop = if s.stop_bits == 2 {
        tokio_serial::StopBits::Two
    } else {
        tokio_serial::StopBits::One
    };
    tokio_serial::new(&s.path, s.baud_rate)
        .parity(parity)
        .stop_bits(stop)
        .data_bits(tokio_serial::DataBits::Eight)
        .timeout(Duration::from_millis(100))
        .open_native_async()
        .map(SerialLink::new)
        .map_err(|e| DriverError::Link {
            device: s.path.clone(),
            reason: format!("cannot open serial port: {e}"),
        })
}

/// A pseudo-terminal pair: `host` is an async stream; `device_path` is
/// the path the other party opens (in raw mode) to play the device.
#[derive(Debug)]
pub struct PtyPair {
    /// Our end.
    pub host: SerialStream,
    /// The path of the other end, e.g. `/dev/pts/7`.
    pub device_path: String,
    /// The other end, held open so that our end does not see a hang-up
    /// before (or between) the other party's opens. Drop it to let the
    /// other party's close be seen.
    pub device_end: SerialStream,
}

/// Create a pseudo-terminal pair (both ends in raw mode).
pub fn pty_pair() -> Result<PtyPair, DriverError> {
    let link = |e: tokio_serial::Error| DriverError::Link {
        device: "pty".into(),
        reason: e.to_string(),
    };
    let (host, device_end) = SerialStream::pair().map_err(link)?;
    let device_path = device_end.name().ok_or_else(|| DriverError::Link {
        device: "pty".into(),
        reason: "the pseudo-terminal has no path".into(),
    })?;
    Ok(PtyPair {
        host,
        device_path,
        device_end,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use tokio::io::{AsyncReadExt, AsyncWriteExt};

    #[tokio::test]
    async fn a_pty_pair_carries_bytes_unchanged_both_ways() {
        let PtyPair {
            mut host,
            device_path,
            device_end: _keep,
        } = pty_pair().unwrap();
        let mut dev = open_serial(&SerialSettings::new_8n1(&device_path, 115_200)).unwrap();
        // Raw mode: \r, \n, 0x00 and 0xFF pass untouched, nothing echoes.
        let bytes = b"\r\n\x00\xff$MB\x03";
        host.write_all(bytes).await.unwrap();
        let mut got = vec![0u8; bytes.len()];
        dev.read_exact(&mut got).await.unwrap();
        assert_eq!(&got, bytes);
        dev.write_all(b"ok\r").await.unwrap();
        let mut back = [0u8; 3];
        host.read_exact(&mut back).await.unwrap();
        assert_eq!(&back, b"ok\r");
    }

    /// A port whose flush would block the worker (a stand-in for
    /// `tcdrain`): it panics if asked.
    struct DrainingPort(Vec<u8>);

    impl AsyncWrite for DrainingPort {
        fn poll_write(
            mut self: Pin<&mut Self>,
            _cx: &mut Context<'_>,
            buf: &[u8],
        ) -> Poll<io::Result<usize>> {
            self.0.extend_from_slice(buf);
            Poll::Ready(Ok(buf.len()))
        }

        fn poll_flush(self: Pin<&mut Self>, _cx: &mut Context<'_>) -> Poll<io::Result<()>> {
            panic!("the port's flush was called: it would block the worker until the line empties")
        }

        fn poll_shutdown(self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
            self.poll_flush(cx)
        }
    }

    /// Writing a request and flushing it, as the Modbus RTU client and
    /// the SLCAN driver do, hands the bytes to the port and never waits
    /// in its flush.
    #[tokio::test]
    async fn a_links_flush_never_waits_for_the_line_to_empty() {
        let mut link = SerialLink::new(DrainingPort(Vec::new()));
        link.write_all(b"\x01\x03\x00\x00\x00\x06\xc5\xc8")
            .await
            .unwrap();
        link.flush().await.unwrap();
        link.shutdown().await.unwrap();
        assert_eq!(link.0 .0, b"\x01\x03\x00\x00\x00\x06\xc5\xc8");
    }

    #[test]
    fn a_missing_port_is_a_link_error_naming_it() {
        let err = open_serial(&SerialSettings::new_8n1("/dev/no-such-tty", 9600)).unwrap_err();
        assert!(
            err.is_link_failure() && err.to_string().contains("/dev/no-such-tty"),
            "{err}"
        );
    }

    #[test]
    fn bits_per_byte_counts_parity_and_stop_bits() {
        let mut s = SerialSettings::new_8n1("x", 115_200);
        assert_eq!(s.bits_per_byte(), 10);
        s.parity = Parity::Even;
        assert_eq!(s.bits_per_byte(), 11);
    }
}
