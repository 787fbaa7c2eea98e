//! CAN: frames, one frame-stream trait, its backends, and DBC signal
//! decoding.
//!
//! - [`CanFrame`]: a classic CAN frame, independent of any backend.
//! - [`FrameStream`]: what every backend offers (send a frame, receive the
//!   next one). Backends: [`SlcanStream`] (the Lawicel ASCII protocol of
//!   USB-CAN adapters, over any byte stream: a serial port, a PTY, a
//!   duplex), [`SocketCanStream`] (the Linux kernel's SocketCAN) and
//!   [`InProcessBus`] (a bus inside one process, for simulations and tests).
//! - [`SignalMap`]: signals of a DBC file, decoded from frames;
//!   [`CanSignalSensors`]: such signals as a sensor stream.

mod bus;
mod dbc;
mod frame;
mod sensors;
mod slcan;
mod socketcan;
mod stamp;

pub use bus::{BusEndpoint, InProcessBus};
pub use dbc::{DbcError, DecodedSignal, SignalMap, SignalSpec};
pub use frame::{CanFrame, CanId, FrameError};
pub use sensors::{CanChannel, CanSignalSensors, RESYNC_SILENCE_S};
pub use slcan::{decode_line, encode_frame, SlcanBitrate, SlcanLine, SlcanOptions, SlcanStream};
pub use socketcan::SocketCanStream;
pub use stamp::{LagRun, PeriodicStamp, Stamped};

use async_trait::async_trait;

use crate::DriverError;

/// A CAN interface: send frames, receive the frames others sent.
///
/// `recv` is cancel-safe: dropping its future loses no frame, so it may be
/// raced against a timeout or a shutdown signal.
#[async_trait]
pub trait FrameStream: Send {
    /// Driver id of the interface (used in errors).
    fn id(&self) -> &str;

    /// Queue one frame for transmission.
    async fn send(&mut self, frame: &CanFrame) -> Result<(), DriverError>;

    /// Wait for the next received frame.
    async fn recv(&mut self) -> Result<CanFrame, DriverError>;

    /// Lines received so far that were not a frame the interface could
    /// decode (garbage on a USB-CAN adapter's serial line). Default: 0,
    /// for an interface that hands over whole frames or nothing.
    fn malformed(&self) -> u64 {
        0
    }
}
