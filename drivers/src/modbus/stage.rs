//! [`ModbusPowerStage`]: a power stage (a programmable supply, a VFD)
//! driven through the registers its profile names.

use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;

use async_trait::async_trait;

use super::bus::{BusHandle, Priority};
use super::profile::{DeviceProfile, StageMap};
use super::register_map::Register;
use crate::{DriverError, PowerStage, StageCapabilities};

/// A power stage behind Modbus registers.
///
/// - Set point: written to the profile's set-point register (range-checked
///   against `max_setpoint` and the register's raw range first).
/// - Enable: the enable register written with its enable or disable value.
/// - Safe state: disable first (the output stops at once), then set point
///   zero; both are attempted even if the first fails, and the first
///   failure is returned.
/// - Heartbeat (optional): a counter written to the heartbeat register at
///   its period by a background task, for devices that stop themselves
///   when the master goes quiet. Failures are counted
///   ([`ModbusPowerStage::heartbeat_failures`]).
#[derive(Debug)]
pub struct ModbusPowerStage {
    id: String,
    bus: BusHandle,
    unit: u8,
    map: StageMap,
    setpoint: Register,
    enable: Option<(Register, u16, u16)>,
    current_limit: Option<Register>,
    heartbeat: Option<tokio::task::JoinHandle<()>>,
    heartbeat_failures: Arc<AtomicU64>,
}

impl ModbusPowerStage {
    /// A power stage on `bus`, unit `unit`, per `profile`'s
    /// `[power_stage]` section. Starts the heartbeat task if the profile
    /// has one.
    pub fn new(
        id: &str,
        bus: BusHandle,
        unit: u8,
        profile: &DeviceProfile,
    ) -> Result<ModbusPowerStage, DriverError> {
        let unsupported = || DriverError::Unsupported {
            device: id.to_string(),
            what: "a power stage (its profile has no [power_stage] section)",
        };
        let map = profile.power_stage.clone().ok_or_else(unsupported)?;
        let reg = |name: &str| {
            profile
                .register(name)
                .cloned()
                .expect("the profile checked its power-stage register names")
        };
        let heartbeat_failures = Arc::new(AtomicU64::new(0));
        let heartbeat = map.heartbeat.as_ref().map(|(name, period)| {
            let (bus, register, period) = (bus.clone(), reg(name), *period);
            let failures = heartbeat_failures.clone();
            tokio::spawn(async move {
                let mut counter: u16 = 0;
                let mut tick = tokio::time::interval(period);
                loop {
                    tick.tick().await;
                    counter = counter.wrapping_add(1);
                    let r = bus
                        .write_words(unit, &register, vec![counter], Priority::Routine)
                        .await;
                    if r.is_err() {
                        failures.fetch_add(1, Ordering::Relaxed);
                    }
                }
            })
        });
        Ok(ModbusPowerStage {
            id: id.to_string(),
            bus,
            unit,
            setpoint: reg(&map.setpoint),
            enable: map.enable.as_ref().map(|(n, on, off)| (reg(n), *on, *off)),
            current_limit: map.current_limit.as_ref().map(|n| reg(n)),
            map,
            heartbeat,
            heartbeat_failures,
        })
    }

    /// Heartbeat writes that failed so far.
    pub fn heartbeat_failures(&self) -> u64 {
        self.heartbeat_failures.load(Ordering::Relaxed)
    }

    async fn enable(&self, on: bool) -> Result<(), DriverError> {
        match &self.enable {
            Some((reg, on_value, off_value)) => {
                let raw = if on { *on_value } else { *off_value };
                self.bus
                    .write_words(self.unit, reg, vec![raw], Priority::Urgent)
                    .await
            }
            // A stage without an enable register is "enabled" by its set
            // point alone; disabling it means a zero set point.
            None if on => Ok(()),
            None => {
                self.bus
                    .write(self.unit, &self.setpoint, 0.0, Priority::Urgent)
                    .await
            }
        }
    }
}

impl Drop for ModbusPowerStage {
    fn drop(&mut self) {
        if let Some(h) = self.heartbeat.take() {
            h.abort();
        }
    }
}

#[async_trait]
impl PowerStage for ModbusPowerStage {
    fn id(&self) -> &str {
        &self.id
    }

    fn capabilities(&self) -> StageCapabilities {
        StageCapabilities {
            current_limit: self.current_limit.is_some(),
            max_setpoint: self.map.max_setpoint,
        }
    }

    async fn set_setpoint(&mut self, value: f64) -> Result<(), DriverError> {
        if !value.is_finite() || value.abs() > self.map.max_setpoint {
            return Err(DriverError::Device {
                device: self.id.clone(),
                reason: format!(
                    "set point {value} {} is outside ±{} {}",
                    self.setpoint.unit, self.map.max_setpoint, self.setpoint.unit
                ),
            });
        }
        self.bus
            .write(self.unit, &self.setpoint, value, Priority::Urgent)
            .await
    }

    async fn set_output_enabled(&mut self, enabled: bool) -> Result<(), DriverError> {
        self.enable(enabled).await
    }

    /// The enable register read back (`None` without one).
    async fn read_output_enabled(&mut self) -> Result<Option<bool>, DriverError> {
        let Some((reg, on, _)) = &self.enable else {
            return Ok(None);
        };
        let r = self
            .bus
            .read(self.unit, vec![reg.clone()], Priority::Urgent)
            .await?;
        Ok(r.values.first().map(|v| v.round() == f64::from(*on)))
    }

    async fn safe_state(&mut self) -> Result<(), DriverError> {
        let off = self.enable(false).await;
        let zero = self
            .bus
            .write(self.unit, &self.setpoint, 0.0, Priority::Urgent)
            .await;
        off.and(zero)
    }

    async fn set_current_limit(&mut self, amperes: f64) -> Result<(), DriverError> {
        match &self.current_limit {
            Some(reg) => {
                self.bus
                    .write(self.unit, reg, amperes, Priority::Urgent)
                    .await
            }
            None => Err(DriverError::Unsupported {
                device: self.id.clone(),
                what: "a current limit",
            }),
        }
    }
}
