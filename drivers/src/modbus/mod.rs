//! Modbus TCP and RTU: a client with deadlines, retries and typed errors
//! ([`ModbusClient`]), register maps and device profiles
//! ([`DeviceProfile`]), one task per link ([`spawn_bus`]), a power stage
//! ([`ModbusPowerStage`]) and polled sensors ([`ModbusSensors`]) on top,
//! and (feature `server`) a register-bank server for simulated devices.

mod bus;
mod client;
mod profile;
mod register_map;
mod sensors;
#[cfg(feature = "server")]
pub mod server;
mod stage;

pub use bus::{
    read_registers, spawn_bus, spawn_bus_as, worst_case_latency, BusHandle, Priority, Reading,
};
pub use client::{
    is_idempotent, rtu_frame_gap, CallPolicy, LinkStats, ModbusClient, RTU_FRAME_GAP_FAST,
};
pub use profile::{DeviceProfile, ProfileError, SerialDefaults, StageMap};
pub use register_map::{
    Access, ByteOrder, DataType, RangeError, Register, RegisterKind, WordOrder,
};
pub use sensors::{ModbusSensors, PolledChannel};
pub use stage::ModbusPowerStage;
