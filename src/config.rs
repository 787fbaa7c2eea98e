//! Rig and test configuration: what every machine's configuration shares
//! ([`CommonConfig`]: the motor, `[limits]`, `[supervisor]`, `[records]`,
//! the faults; errors naming file, line and key; Modbus and CAN links;
//! sensor channels) and
//! [`TestConfig`], the test plan as a tagged enum mapped to its machine.
//! Each machine's own file format lives with it: the DC machine's
//! [`Config`] in `machine/dc/config.rs`, the induction machine's in
//! `machine/im/config.rs`.

mod can;
mod common;
mod error;
mod fault;
mod key_line;
mod limits;
pub(crate) mod modbus;
mod retention;
mod sensor_channels;
mod supervision;
mod test_config;
mod test_override;

pub use can::{CanLink, CanTransport};
pub use common::CommonConfig;
pub(crate) use common::{RawCommon, RawFile};
pub use error::ConfigError;
pub(crate) use error::{bounded, invalid, syntax_error};
pub(crate) use fault::{validate_faults, FaultRig, RawFault};
pub use fault::{Fault, FaultKind, FaultPlan, MAX_FAULTS};
pub use key_line::key_line;
pub use limits::Limits;
pub use modbus::{LinkSpec, ModbusDeviceLink, ModbusRig, SensorLink, SimulatedTransport};
pub use sensor_channels::SensorChannel;
pub use test_config::{recorded_im_model, PlanKind, TestConfig};

pub(crate) use modbus::{call_policy, merge_window, simulated_transport, RawLink};
pub(crate) use retention::RawRetention;
pub(crate) use supervision::RawSupervisor;
pub(crate) use test_override::merged_test;

pub use crate::machine::dc::config::{
    Backend, Config, Plan, Settle, SimPowerStageConfig, SimSensorConfig, SimulatedRig,
};
pub use retention::{Retention, DEFAULT_MAX_TOTAL_GIB};
pub use supervision::{
    LastResort, Supervision, ThermalModel, DEFAULT_AMBIENT_C, DEFAULT_BUS_LOSS_TIMEOUT_S,
    DEFAULT_MAX_WINDING_C, DEFAULT_RATED_RISE_K, DEFAULT_STALE_TIMEOUT_S,
    DEFAULT_THERMAL_TIME_CONSTANT_S,
};

/// The embedded default configuration: the simulated rig with the seed
/// paper's Table 4 motor.
pub const DEFAULT_CONFIG: &str = include_str!("../config/sim-dc.toml");

/// Name shown for the embedded default in messages.
pub const DEFAULT_CONFIG_NAME: &str = "<embedded default: config/sim-dc.toml>";
