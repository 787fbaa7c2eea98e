//! Serial line protocols for sensors that stream readings, and the serial
//! ports they run on.
//!
//! Two framings of one record (a sequence number, the device's own
//! timestamp in microseconds, and channel values):
//!
//! - [`ascii`]: one NMEA-style line per record,
//!   `$MB,<seq>,<t_us>,<name>=<value>,…*HH\r\n`, `HH` the XOR of the bytes
//!   between `$` and `*` in two hex digits.
//! - [`binary`]: COBS-framed records (`0x00` ends a frame) with a CRC-16.
//!
//! Both decoders resynchronise after garbage: they drop bytes up to the
//! next frame start and count what they dropped. [`SerialSensors`] turns
//! either into a [`crate::SensorStream`], counting lost records from gaps
//! in the sequence number. [`port`] opens serial ports (tokio-serial, no
//! libudev) and pseudo-terminal pairs.

pub mod ascii;
pub mod binary;
pub mod port;
mod stream;

pub use stream::{SerialChannel, SerialFraming, SerialSensors};

/// One record of a streaming sensor, before it is mapped to channels.
#[derive(Debug, Clone, PartialEq)]
pub struct StreamRecord {
    /// Sequence number, incremented by one per record (wraps at 2³²).
    pub seq: u32,
    /// The device's timestamp of the readings, µs (any epoch).
    pub t_us: u64,
    /// Readings: by name (ASCII framing) or by position as `"0"`, `"1"`, …
    /// (binary framing).
    pub values: Vec<(String, f64)>,
}

/// Counts kept by a decoder.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct DecodeCounts {
    /// Records decoded.
    pub records: u64,
    /// Frames refused (bad checksum or CRC, bad syntax).
    pub rejected: u64,
    /// Bytes dropped while looking for a frame start.
    pub skipped_bytes: u64,
}
