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
//! Backends (the simulated rig in the `motorbench` crate today; Modbus, CAN
//! and serial transports later) implement these traits. The traits speak of
//! set points, channels and samples only: what a channel *means* for a motor
//! is the caller's business.

mod error;
mod power_stage;
mod sensor;

pub use error::DriverError;
pub use power_stage::{PowerStage, StageCapabilities};
pub use sensor::{ChannelInfo, Sample, SampleBatch, SensorStream};
