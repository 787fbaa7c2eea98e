//! The two stages of an induction-machine rig behind variable-frequency
//! drives, as the slip sweep commands them:
//!
//! - [`VfdSupply`]: the VFD feeding the machine under test. The sweep's set
//!   point is the output line voltage (V), written to the drive's voltage
//!   register (on an Optidrive E3, the motor rated voltage P-07, which sets
//!   the V/f characteristic's voltage at base frequency); enabling writes
//!   the supply frequency and then the run command; the frequency may be
//!   commanded below the rated one ([`PowerStage::set_frequency`], for a
//!   locked-rotor test at reduced frequency); the safe state is the
//!   drive's own (stop, frequency zero): supply output off.
//! - [`VfdDyno`]: the VFD driving the load machine. The sweep's set point is
//!   the shaft speed (rad/s), sent as the frequency `ω·p/2π` for a load
//!   machine of `p` pole pairs; the safe state stops the drive (its ramp
//!   brings the shaft to rest). Output off is that stop too, or, where
//!   the drive's coast-stop command is given ([`VfdDyno::with_coast`]), a
//!   coast stop: the shaft turns freely (the no-load test).
//!
//! - [`DcCurrentSource`]: the DC supply of the winding-resistance test, in
//!   constant current: the set point (A) is written to its current limit,
//!   its voltage set point is the compliance voltage; the safe state is
//!   the supply's own (output off, set point zero).
//!
//! Each wraps a [`ModbusPowerStage`] over the profile's `[power_stage]`
//! section, so heartbeat, retries, refusals and the read-back of the
//! enable register (what the supervisor checks after a safe command)
//! behave as for the DC rig.

use async_trait::async_trait;
use motorbench_drivers::modbus::{BusHandle, ModbusPowerStage, Priority, Register};
use motorbench_drivers::{DriverError, PowerStage, StageCapabilities};

use crate::rig::{check_frequency, check_setpoint};

/// The supply VFD; see the module docs.
#[derive(Debug)]
pub struct VfdSupply {
    drive: ModbusPowerStage,
    bus: BusHandle,
    unit: u8,
    voltage: Register,
    frequency_hz: f64,
    rated_hz: f64,
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
            rated_hz: frequency_hz,
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
        check_setpoint(self.id(), "voltage", "V", volts, self.max_voltage, 1.0)?;
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

    /// The drive's run command read back from its control word.
    async fn read_output_enabled(&mut self) -> Result<Option<bool>, DriverError> {
        self.drive.read_output_enabled().await
    }

    async fn set_frequency(&mut self, hz: f64) -> Result<(), DriverError> {
        check_frequency(self.id(), hz, self.rated_hz, 1.0)?;
        self.drive.set_setpoint(hz).await?;
        self.frequency_hz = hz;
        Ok(())
    }
}

/// The DC source of the winding-resistance test; see the module docs.
#[derive(Debug)]
pub struct DcCurrentSource {
    drive: ModbusPowerStage,
    compliance_voltage: f64,
    max_current: f64,
}

impl DcCurrentSource {
    /// The DC supply `drive` (its profile with a current limit) driving
    /// currents up to `max_current` A with `compliance_voltage` V as its
    /// voltage set point.
    pub fn new(
        drive: ModbusPowerStage,
        compliance_voltage: f64,
        max_current: f64,
    ) -> DcCurrentSource {
        DcCurrentSource {
            drive,
            compliance_voltage,
            max_current,
        }
    }
}

#[async_trait]
impl PowerStage for DcCurrentSource {
    fn id(&self) -> &str {
        self.drive.id()
    }

    fn capabilities(&self) -> StageCapabilities {
        StageCapabilities {
            current_limit: true,
            max_setpoint: self.max_current,
        }
    }

    async fn set_setpoint(&mut self, amperes: f64) -> Result<(), DriverError> {
        check_setpoint(self.id(), "DC current", "A", amperes, self.max_current, 1.0)?;
        self.drive.set_current_limit(amperes).await?;
        self.drive.set_setpoint(self.compliance_voltage).await
    }

    async fn set_output_enabled(&mut self, enabled: bool) -> Result<(), DriverError> {
        self.drive.set_output_enabled(enabled).await
    }

    async fn safe_state(&mut self) -> Result<(), DriverError> {
        self.drive.safe_state().await
    }

    /// The supply's output switch read back.
    async fn read_output_enabled(&mut self) -> Result<Option<bool>, DriverError> {
        self.drive.read_output_enabled().await
    }

    async fn set_current_limit(&mut self, amperes: f64) -> Result<(), DriverError> {
        self.set_setpoint(amperes).await
    }
}

/// The dynamometer VFD; see the module docs.
#[derive(Debug)]
pub struct VfdDyno {
    drive: ModbusPowerStage,
    hz_per_rad_s: f64,
    /// Where and what to write to coast the drive.
    coast: Option<(BusHandle, u8, Register, u16)>,
}

impl VfdDyno {
    /// The dynamometer on `drive`, a load machine of `pole_pairs`.
    pub fn new(drive: ModbusPowerStage, pole_pairs: u32) -> VfdDyno {
        VfdDyno {
            drive,
            hz_per_rad_s: f64::from(pole_pairs.max(1)) / std::f64::consts::TAU,
            coast: None,
        }
    }

    /// Output off coasts the drive: `value` written to `control` (unit
    /// `unit` on `bus`) lets the shaft turn freely.
    pub fn with_coast(
        mut self,
        bus: BusHandle,
        unit: u8,
        control: Register,
        value: u16,
    ) -> VfdDyno {
        self.coast = Some((bus, unit, control, value));
        self
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
        match &self.coast {
            Some((bus, unit, control, value)) if !enabled => {
                bus.write_words(*unit, control, vec![*value], Priority::Urgent)
                    .await
            }
            _ => self.drive.set_output_enabled(enabled).await,
        }
    }

    async fn safe_state(&mut self) -> Result<(), DriverError> {
        self.drive.safe_state().await
    }

    /// The drive's run command read back from its control word (a coast
    /// stop reads as not running).
    async fn read_output_enabled(&mut self) -> Result<Option<bool>, DriverError> {
        self.drive.read_output_enabled().await
    }
}
