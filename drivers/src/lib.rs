//! Device traits for motorbench, with no motor knowledge.
//!
//! A test rig is seen through two narrow traits:
//!
//! - [`PowerStage`]: something that drives the machine under test (an
//!   armature supply, a VFD, a dynamometer): a set point, an output enable
//!   and a safe state. Optional capabilities default to
//!   [`DriverError::Unsupported`].
//! - [`SensorStream`]: something that delivers timestamped samples of named
//!   channels (a DAQ, a power meter, an encoder interface).
//!
//! Backends implement these traits: the simulated rig in the `motorbench`
//! crate, and the transports here. The traits speak of set points,
//! channels and samples only: what a channel *means* for a motor is the
//! caller's business.
//!
//! Transports and codecs, each written over byte streams or frame streams
//! so that a TCP socket, a pseudo-terminal, an in-process duplex or real
//! hardware are interchangeable:
//!
//! - [`modbus`]: Modbus TCP and RTU clients (tokio-modbus) with timeouts,
//!   retries of idempotent calls and typed errors; register maps loaded
//!   from TOML device profiles; a Modbus power stage and polled sensors.
//! - [`can`]: one frame-stream trait with SocketCAN, SLCAN and in-process
//!   backends; DBC signal decoding.
//! - [`serial`]: ASCII and binary line protocols for streaming sensors,
//!   serial ports and pseudo-terminals.
//! - [`ChannelStats`]: jitter and loss per channel, kept by the streams.
//! - [`LinkHealth`]: requests and errors by kind per link (timeouts,
//!   exceptions, decode errors, reconnects), kept by the link's owner.
//! - [`MergedSensors`]: several streams (each in its own task) as one, on
//!   one time base and in time order.

pub mod can;
mod error;
mod link_health;
mod merged;
pub mod modbus;
mod power_stage;
mod sensor;
pub mod serial;
mod stats;

pub use error::DriverError;
pub use link_health::{LinkCounts, LinkHealth};
pub use merged::{MergedSensors, DEFAULT_REORDER};
pub use power_stage::{PowerStage, StageCapabilities};
pub use sensor::{ChannelInfo, Sample, SampleBatch, SensorStream};
pub use stats::{ChannelStats, IntervalStats};
