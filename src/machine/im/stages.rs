//! The two stages of an induction-machine rig behind variable-frequency
//! drives, as the slip sweep commands them:
//!
//! - [`VfdSupply`]: the VFD feeding the machine under test. The sweep's set
//!   point is the output line voltage (V), written to the drive's voltage
//!   register (on an Optidrive E3, the motor rated voltage P-07, which sets
//!   the V/f characteristic's voltage at base frequency); enabling writes
//!   the supply frequency and then the run command; the safe state is the
//!   drive's own (stop, frequency zero): supply output off.
//! - [`VfdDyno`]: the VFD driving the load machine. The sweep's set point is
//!   the shaft speed (rad/s), sent as the frequency `ω·p/2π` for a load
//!   machine of `p` pole pairs; the safe state stops the drive (its ramp
//!   brings the shaft to rest).
//!
//! Both wrap a [`ModbusPowerStage`] over the profile's `[power_stage]`
//! section, so heartbeat, retries and refusals behave as for the DC rig.

use async_trait::async_trait;
use motorbench_drivers::modbus::{BusHandle, ModbusPowerStage, Priority, Register};
use motorbench_drivers::{DriverError, PowerStage, StageCapabilities};

/// The supply VFD; see the module docs.
#[derive(Debug)]
pub struct VfdSupply {
    drive: ModbusPowerStage,
    bus: BusHandle,
    unit: u8,
    voltage: Register,
    frequency_hz: f64,
    max_voltage: f64,
}

impl VfdSupply {
    /// The supply on `drive`, its output voltage set through `voltage`
    /// (unit `unit` on `bus`), run at `frequency_hz`, voltage set points
    /// up to `max_voltage`.
    pub fn new(
        drive: ModbusPowerStage,
        bus: BusHandle,
        unit: u8,
        voltage: Register,
        frequency_hz: f64,
        max_voltage: f64,
    ) -> VfdSupply {
        VfdSupply {
            drive,
            bus,
            unit,
            voltage,
            frequency_hz,
            max_voltage,
        }
    }
}

#[async_trait]
impl PowerStage for VfdSupply {
    fn id(&self) -> &str {
        self.drive.id()
    }

    fn capabilities(&self) -> StageCapabilities {
        StageCapabilities {
            current_limit: false,
            max_setpoint: self.max_voltage,
        }
    }

    async fn set_setpoint(&mut self, volts: f64) -> Result<(), DriverError> {
        if !(volts.is_finite() && (0.0..=self.max_voltage).contains(&volts)) {
            return Err(DriverError::Device {
                device: self.id().to_string(),
                reason: format!(
                    "voltage set point {volts} V outside [0, {}] V",
                    self.max_voltage
                ),
            });
        }
        self.bus
            .write(self.unit, &self.voltage, volts, Priority::Urgent)
            .await
    }

    async fn set_output_enabled(&mut self, enabled: bool) -> Result<(), DriverError> {
        if enabled {
            self.drive.set_setpoint(self.frequency_hz).await?;
        }
        self.drive.set_output_enabled(enabled).await
    }

    async fn safe_state(&mut self) -> Result<(), DriverError> {
        self.drive.safe_state().await
    }
}

/// The dynamometer VFD; see the module docs.
#[derive(Debug)]
pub struct VfdDyno {
    drive: ModbusPowerStage,
    hz_per_rad_s: f64,
}

impl VfdDyno {
    /// The dynamometer on `drive`, a load machine of `pole_pairs`.
    pub fn new(drive: ModbusPowerStage, pole_pairs: u32) -> VfdDyno {
        VfdDyno {
            drive,
            hz_per_rad_s: f64::from(pole_pairs.max(1)) / std::f64::consts::TAU,
        }
    }
}

#[async_trait]
impl PowerStage for VfdDyno {
    fn id(&self) -> &str {
        self.drive.id()
    }

    fn capabilities(&self) -> StageCapabilities {
        let c = self.drive.capabilities();
        StageCapabilities {
            current_limit: false,
            max_setpoint: c.max_setpoint / self.hz_per_rad_s,
        }
    }

    async fn set_setpoint(&mut self, rad_s: f64) -> Result<(), DriverError> {
        self.drive.set_setpoint(rad_s * self.hz_per_rad_s).await
    }

    async fn set_output_enabled(&mut self, enabled: bool) -> Result<(), DriverError> {
        self.drive.set_output_enabled(enabled).await
    }

    async fn safe_state(&mut self) -> Result<(), DriverError> {
        self.drive.safe_state().await
    }
}
