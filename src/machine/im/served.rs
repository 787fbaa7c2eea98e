//! The simulated induction-machine rig behind the real protocols: four
//! Modbus devices, each on its own server (Modbus TCP on 127.0.0.1, a port
//! the OS picks, or RTU on a pseudo-terminal pair), with the register maps
//! of shipped profiles:
//!
//! - the supply VFD (e.g. `config/devices/invertek-optidrive-e3.toml`):
//!   control word (bit 0 run, bit 3 coast stop), frequency set point (0,
//!   or up to the machine's rated frequency: the reactances scale with
//!   it), and a voltage register setting the output line voltage;
//!   output frequency, output current and status read back;
//! - the dynamometer VFD (same profile, another unit): run means hold the
//!   speed `2π f / p` of its frequency set point, stop means ramp the shaft
//!   to rest, coast stop lets it go;
//! - the power meter (e.g. `config/devices/eastron-sdm630.toml`): phase and
//!   line-to-line voltages, phase and average currents, phase and total
//!   power, frequency, from the simulated sensors;
//! - the encoder counter (e.g. `config/devices/sim-daq.toml`): the count,
//!   and the winding thermometer's reading where the simulated rig has one
//!   (`winding_temperature`);
//! - for the standard tests, the DC source of the winding-resistance test
//!   (e.g. `config/devices/riden-rd6006.toml`, a DC supply in constant
//!   current): its current-limit register sets the current it drives
//!   between two line terminals, its voltage set point the compliance
//!   voltage, its enable register connects it; `voltage_out` and
//!   `current_out` read back.
//!
//! The plant runs on the wall clock, as in [`crate::machine::dc::ServedRig`]: every
//! request first advances it to "now" in steps of its own period.

use std::f64::consts::TAU;
use std::sync::{Arc, Mutex};

use motorbench_drivers::modbus::server::{
    BankService, ExceptionCode, RegisterBank, SharedBank, SimulatedDevice, WriteSpan,
};
use motorbench_drivers::modbus::{DeviceProfile, Register};
use motorbench_drivers::serial::port::SerialStream;
use motorbench_drivers::{PowerStage, SampleBatch};
use tokio::task::JoinHandle;

use super::sim_rig::{
    channel, sim_im_rig, SimDcSource, SimDyno, SimImRigConfig, SimImSensors, SimVfd,
};
use crate::config::Fault;
use crate::config::{ModbusDeviceLink, SimulatedTransport};
use crate::machine::sim_parts::{lock_plant, missing, plant_now, power_stage_map, ServedPlant};
use crate::model::Connection;
use crate::rig::fault::ProtocolFaults;
use crate::rig::{
    enable_written, ready_now, register, serve_device, touches, ServeError, ServedLink,
    SupplyReadback, WallClock,
};

/// The simulated machine, supply and dynamometer on the wall clock.
struct Plant {
    vfd: SimVfd,
    dyno: SimDyno,
    sensors: SimImSensors,
    clock: WallClock,
    last: Option<SampleBatch>,
    previous: Option<SampleBatch>,
}

impl ServedPlant for Plant {
    fn catch_up(&mut self) {
        let (sensors, last, previous) = (&mut self.sensors, &mut self.last, &mut self.previous);
        self.clock
            .catch_up(|_| *previous = last.replace(sensors.sample()));
    }

    fn last(&self) -> Option<&SampleBatch> {
        self.last.as_ref()
    }
}

impl Plant {
    /// The encoder count now: the latest step's, carried on at the speed
    /// of the last step to the instant of the request, as a hardware
    /// counter would read it (without this, a reading would be up to one
    /// plant period old, and the polled speed jitter by that much).
    fn count_now(&self) -> f64 {
        let count = |b: &Option<SampleBatch>| b.as_ref().and_then(|b| b.value(channel::ENCODER));
        let (Some(c1), Some(c0)) = (count(&self.last), count(&self.previous)) else {
            return self.reading(channel::ENCODER);
        };
        let since = self.clock.since_steps();
        (c1 + (c1 - c0) * (since / self.clock.period_s()).clamp(0.0, 1.0)).floor()
    }
}

type SharedPlant = Arc<Mutex<Plant>>;

/// Control word bits of the drive (Optidrive E3 register 1).
const RUN: u16 = 1;
const COAST: u16 = 8;
/// Status word, high byte: 0 stopped, 1 running.
const STATUS_RUNNING: f64 = 256.0;

/// The registers a served VFD answers on, from its profile.
#[derive(Debug, Clone)]
struct VfdRegisters {
    control: Register,
    frequency: Register,
    output_frequency: Option<Register>,
    output_current: Option<Register>,
    status: Option<Register>,
}

impl VfdRegisters {
    fn of(profile: &DeviceProfile) -> Result<VfdRegisters, ServeError> {
        let map = power_stage_map(profile)?;
        let control = match &map.enable {
            Some((n, _, _)) => register(profile, n)?,
            None => return Err(missing(profile, "[power_stage] enable (the control word)")),
        };
        Ok(VfdRegisters {
            control,
            frequency: register(profile, &map.setpoint)?,
            output_frequency: profile.register("output_frequency").cloned(),
            output_current: profile.register("output_current").cloned(),
            status: profile.register("status").cloned(),
        })
    }

    /// Show the drive's state in its readback registers: the output
    /// frequency (`frequency` while `running`, else 0) and the status
    /// word.
    fn show_state(&self, bank: &mut RegisterBank, running: bool, frequency: f64) {
        if let Some(r) = &self.output_frequency {
            bank.set(r, if running { frequency } else { 0.0 });
        }
        if let Some(r) = &self.status {
            bank.set(r, if running { STATUS_RUNNING } else { 0.0 });
        }
    }

    /// (run, coast) from the control word in `bank`.
    fn command(&self, bank: &RegisterBank) -> (bool, bool) {
        let raw = bank.get(&self.control) as u16;
        (raw & RUN != 0 && raw & COAST == 0, raw & COAST != 0)
    }
}

/// The supply VFD.
struct SupplyDevice {
    plant: SharedPlant,
    regs: VfdRegisters,
    voltage: Register,
}

impl SupplyDevice {
    fn running(&self, bank: &RegisterBank) -> bool {
        self.regs.command(bank).0 && bank.get(&self.regs.frequency) > 0.0
    }
}

impl SimulatedDevice for SupplyDevice {
    fn before_read(&self, bank: &mut RegisterBank) {
        let p = plant_now(&self.plant);
        let running = self.running(bank);
        self.regs.show_state(bank, running, p.vfd.frequency());
        if let Some(r) = &self.regs.output_current {
            bank.set(r, p.reading(channel::LINE_CURRENT).max(0.0));
        }
    }

    fn after_write(
        &self,
        bank: &mut RegisterBank,
        _before: &RegisterBank,
        span: WriteSpan,
    ) -> Result<(), ExceptionCode> {
        let mut p = plant_now(&self.plant);
        if touches(&span, &self.regs.frequency) {
            let f = bank.get(&self.regs.frequency);
            // Zero stops the drive; any other frequency up to the rated
            // one is the output's.
            if f != 0.0 {
                ready_now(p.vfd.set_frequency(f)).map_err(|_| ExceptionCode::IllegalDataValue)?;
            }
        }
        if touches(&span, &self.voltage) {
            ready_now(p.vfd.set_setpoint(bank.get(&self.voltage)))
                .map_err(|_| ExceptionCode::IllegalDataValue)?;
        }
        let on = self.running(bank);
        ready_now(p.vfd.set_output_enabled(on)).map_err(|_| ExceptionCode::ServerDeviceFailure)
    }
}

/// The dynamometer VFD.
struct DynoDevice {
    plant: SharedPlant,
    regs: VfdRegisters,
    rad_s_per_hz: f64,
}

impl SimulatedDevice for DynoDevice {
    fn before_read(&self, bank: &mut RegisterBank) {
        lock_plant(&self.plant).catch_up();
        let (run, _) = self.regs.command(bank);
        let f = bank.get(&self.regs.frequency);
        self.regs.show_state(bank, run, f);
    }

    fn after_write(
        &self,
        bank: &mut RegisterBank,
        _before: &RegisterBank,
        _span: WriteSpan,
    ) -> Result<(), ExceptionCode> {
        let mut p = plant_now(&self.plant);
        let (run, coast) = self.regs.command(bank);
        let speed = bank.get(&self.regs.frequency) * self.rad_s_per_hz;
        let r = if coast {
            ready_now(p.dyno.set_output_enabled(false))
        } else if run {
            ready_now(p.dyno.set_setpoint(speed)).map_err(|_| ExceptionCode::IllegalDataValue)?;
            ready_now(p.dyno.set_output_enabled(true))
        } else {
            // Stop: the drive ramps the shaft to rest.
            ready_now(p.dyno.safe_state())
        };
        r.map_err(|_| ExceptionCode::ServerDeviceFailure)
    }
}

/// The power meter.
struct MeterDevice {
    plant: SharedPlant,
    /// `(register, what it shows)`.
    registers: Vec<(Register, MeterValue)>,
    phase_voltage_per_line: f64,
}

#[derive(Debug, Clone, Copy, PartialEq)]
enum MeterValue {
    LineVoltage,
    PhaseVoltage,
    Current,
    TotalPower,
    PhasePower,
    Frequency,
}

impl MeterValue {
    /// What the SDM630-style register `name` shows, if known.
    fn of_name(name: &str) -> Option<MeterValue> {
        Some(match name {
            "line_voltage" | "line12_voltage" | "line23_voltage" | "line31_voltage" => {
                MeterValue::LineVoltage
            }
            "phase1_voltage" | "phase2_voltage" | "phase3_voltage" => MeterValue::PhaseVoltage,
            "line_current"
            | "phase1_current"
            | "phase2_current"
            | "phase3_current"
            | "average_line_current" => MeterValue::Current,
            "input_power" | "total_power" => MeterValue::TotalPower,
            "phase1_power" | "phase2_power" | "phase3_power" => MeterValue::PhasePower,
            "frequency" => MeterValue::Frequency,
            _ => return None,
        })
    }
}

impl SimulatedDevice for MeterDevice {
    fn before_read(&self, bank: &mut RegisterBank) {
        let p = plant_now(&self.plant);
        let v = p.reading(channel::LINE_VOLTAGE);
        let i = p.reading(channel::LINE_CURRENT);
        let w = p.reading(channel::INPUT_POWER);
        for (r, what) in &self.registers {
            let value = match what {
                MeterValue::LineVoltage => v,
                MeterValue::PhaseVoltage => v * self.phase_voltage_per_line,
                MeterValue::Current => i,
                MeterValue::TotalPower => w,
                MeterValue::PhasePower => w / 3.0,
                MeterValue::Frequency => {
                    if v > 1.0 {
                        p.vfd.frequency()
                    } else {
                        0.0
                    }
                }
            };
            bank.set(r, value);
        }
    }
}

/// The encoder counter (and the winding thermometer's input, where the
/// simulated rig has one).
struct EncoderDevice {
    plant: SharedPlant,
    count: Register,
    /// The winding temperature's register and the sensors' channel.
    temperature: Option<(Register, usize)>,
}

impl SimulatedDevice for EncoderDevice {
    fn before_read(&self, bank: &mut RegisterBank) {
        let p = plant_now(&self.plant);
        bank.set(&self.count, p.count_now());
        if let Some((r, ch)) = &self.temperature {
            bank.set(r, p.reading(*ch));
        }
    }
}

/// The DC source of the winding-resistance test: a DC supply in constant
/// current, behind its profile's power-stage registers.
struct DcSourceDevice {
    plant: SharedPlant,
    source: SimDcSource,
    /// The voltage set point: the compliance voltage.
    compliance: Register,
    /// The current limit: the current driven.
    current: Register,
    enable: (Register, u16, u16),
    readback: SupplyReadback,
    /// The sensors' DC voltage and current channels.
    channels: (usize, usize),
}

impl SimulatedDevice for DcSourceDevice {
    fn before_read(&self, bank: &mut RegisterBank) {
        let p = plant_now(&self.plant);
        let (v, i) = self.channels;
        self.readback.show(bank, p.reading(v), p.reading(i));
    }

    fn after_write(
        &self,
        bank: &mut RegisterBank,
        _before: &RegisterBank,
        span: WriteSpan,
    ) -> Result<(), ExceptionCode> {
        // Held while the source is set: the other devices' requests wait.
        let _plant = plant_now(&self.plant);
        let mut source = self.source.clone();
        if touches(&span, &self.compliance) {
            source
                .set_compliance_voltage(bank.get(&self.compliance))
                .map_err(|_| ExceptionCode::IllegalDataValue)?;
        }
        if touches(&span, &self.current) {
            ready_now(source.set_setpoint(bank.get(&self.current)))
                .map_err(|_| ExceptionCode::IllegalDataValue)?;
        }
        if let Some(enabled) = enable_written(bank, &span, &self.enable)? {
            ready_now(source.set_output_enabled(enabled))
                .map_err(|_| ExceptionCode::ServerDeviceFailure)?;
        }
        Ok(())
    }
}

/// A served VFD: where it answers and its registers.
#[derive(Debug, Clone)]
pub struct ServedVfd {
    /// Where it answers.
    pub link: ServedLink,
    /// Its registers (for tests and diagnostics).
    pub bank: SharedBank,
}

/// The simulated induction-machine rig, served. Dropping it stops the
/// servers.
pub struct ServedImRig {
    /// The supply VFD.
    pub supply: ServedVfd,
    /// The dynamometer VFD.
    pub dynamometer: ServedVfd,
    /// Where the power meter answers.
    pub meter_link: ServedLink,
    /// Where the encoder counter answers.
    pub encoder_link: ServedLink,
    /// Where the DC source answers, when served.
    pub dc_source_link: Option<ServedLink>,
    tasks: Vec<JoinHandle<()>>,
    _pty_ends: Vec<SerialStream>,
    vfd: SimVfd,
    dyno: SimDyno,
}

impl std::fmt::Debug for ServedImRig {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ServedImRig")
            .field("supply", &self.supply.link)
            .field("dynamometer", &self.dynamometer.link)
            .field("meter", &self.meter_link)
            .field("encoder", &self.encoder_link)
            .finish()
    }
}

/// One served device of [`ServedImRig::start`]: profile, unit, and the
/// register names it must answer on.
#[derive(Debug, Clone, Copy)]
pub struct ServedDevice<'a> {
    /// Register map.
    pub profile: &'a DeviceProfile,
    /// Unit id.
    pub unit: u8,
}

impl ServedDevice<'_> {
    /// The device a configured Modbus link names: its profile and unit.
    pub fn of(link: &ModbusDeviceLink) -> ServedDevice<'_> {
        ServedDevice {
            profile: &link.profile,
            unit: link.unit_id,
        }
    }
}

impl ServedImRig {
    /// Serve `sim` (its plant stepped at `plant_rate_hz`) over `transport`:
    /// the supply VFD (its output voltage set through `supply_voltage`),
    /// the dynamometer VFD (a load machine of `dyno_pole_pairs`), the meter
    /// (answering on every register its profile names that it knows, and
    /// on `meter_channels`' registers by quantity), the encoder counter
    /// (its channels' registers by quantity: `encoder_count`, and
    /// `winding_temperature` where the simulated rig has a thermometer) and,
    /// when given, the DC source (a profile whose `[power_stage]` has a
    /// current limit and an enable register; `sim` must fit one).
    #[allow(clippy::too_many_arguments)]
    pub async fn start(
        sim: &SimImRigConfig,
        plant_rate_hz: f64,
        transport: SimulatedTransport,
        supply: (ServedDevice<'_>, &str),
        dynamometer: (ServedDevice<'_>, u32),
        meter: (ServedDevice<'_>, &[(String, String)]),
        encoder: (ServedDevice<'_>, &[(String, String)]),
        dc_source: Option<ServedDevice<'_>>,
        faults: &[Fault],
    ) -> Result<ServedImRig, ServeError> {
        let epoch = std::time::Instant::now();
        let cfg = SimImRigConfig {
            sample_rate_hz: plant_rate_hz,
            ..sim.clone()
        };
        let phase_voltage_per_line = match cfg.supply.connection {
            Connection::Star => 1.0 / 3f64.sqrt(),
            Connection::Delta => 1.0,
        };
        let (vfd, dyno, sensors) = sim_im_rig(cfg).map_err(|e| ServeError::Motor(e.to_string()))?;
        let dc_channels = sensors.dc_channels();
        let temperature_channel = sensors.temperature_channel();
        let plant = Arc::new(Mutex::new(Plant {
            vfd: vfd.clone(),
            dyno: dyno.clone(),
            sensors,
            clock: WallClock::start(plant_rate_hz),
            last: None,
            previous: None,
        }));

        let (sd, voltage_name) = supply;
        let supply_dev = SupplyDevice {
            plant: plant.clone(),
            regs: VfdRegisters::of(sd.profile)?,
            voltage: register(sd.profile, voltage_name)?,
        };
        let (dd, pole_pairs) = dynamometer;
        let dyno_dev = DynoDevice {
            plant: plant.clone(),
            regs: VfdRegisters::of(dd.profile)?,
            rad_s_per_hz: TAU / f64::from(pole_pairs.max(1)),
        };
        let (md, meter_channels) = meter;
        let mut registers: Vec<(Register, MeterValue)> = md
            .profile
            .registers
            .iter()
            .filter_map(|(name, r)| MeterValue::of_name(name).map(|v| (r.clone(), v)))
            .collect();
        for (quantity, name) in meter_channels {
            let what =
                MeterValue::of_name(quantity).ok_or_else(|| ServeError::MissingRegister {
                    profile: format!("{} (served meter)", md.profile.name),
                    register: format!(
                        "{name} for `{quantity}`, which the simulated meter does not measure"
                    ),
                })?;
            registers.push((register(md.profile, name)?, what));
        }
        let meter_dev = MeterDevice {
            plant: plant.clone(),
            registers,
            phase_voltage_per_line,
        };
        let (ed, encoder_channels) = encoder;
        let named = |quantity: &str| {
            encoder_channels
                .iter()
                .find(|(q, _)| q == quantity)
                .map(|(_, name)| register(ed.profile, name))
                .transpose()
        };
        if let Some((quantity, name)) = encoder_channels
            .iter()
            .find(|(q, _)| !matches!(q.as_str(), "encoder_count" | "winding_temperature"))
        {
            return Err(ServeError::MissingRegister {
                profile: format!("{} (served counter)", ed.profile.name),
                register: format!(
                    "{name} for `{quantity}`, which the simulated counter does not read"
                ),
            });
        }
        let count = named("encoder_count")?
            .ok_or_else(|| missing(ed.profile, "encoder_count (a channel of the counter)"))?;
        let temperature = match (named("winding_temperature")?, temperature_channel) {
            (Some(r), Some(ch)) => Some((r, ch)),
            (None, _) => None,
            (Some(_), None) => {
                return Err(ServeError::Motor(
                    "winding_temperature is read, but the simulated rig has no winding \
                     thermometer (rig.simulated.sensors.winding_sensor)"
                        .into(),
                ))
            }
        };
        let encoder_dev = EncoderDevice {
            plant: plant.clone(),
            count,
            temperature,
        };
        let dc_dev = match dc_source {
            None => None,
            Some(d) => {
                let (Some(source), Some(channels)) = (vfd.dc_source(), dc_channels) else {
                    return Err(ServeError::Motor(
                        "a DC source is served, but the simulated rig fits none".into(),
                    ));
                };
                let map =
                    d.profile.power_stage.as_ref().ok_or_else(|| {
                        missing(d.profile, "[power_stage] section (the DC source)")
                    })?;
                let current = map.current_limit.as_deref().ok_or_else(|| {
                    missing(d.profile, "[power_stage] current_limit (the DC current)")
                })?;
                let (enable, on, off) = map.enable.as_ref().ok_or_else(|| {
                    missing(d.profile, "[power_stage] enable (the output switch)")
                })?;
                Some((
                    d,
                    DcSourceDevice {
                        plant: plant.clone(),
                        source,
                        compliance: register(d.profile, &map.setpoint)?,
                        current: register(d.profile, current)?,
                        enable: (register(d.profile, enable)?, *on, *off),
                        readback: SupplyReadback::of(d.profile),
                        channels,
                    },
                ))
            }
        };

        let mut pty_ends = Vec::new();
        let mut tasks = Vec::new();
        let mut serve = |profile: &DeviceProfile,
                         unit: u8,
                         device: Arc<dyn SimulatedDevice>,
                         role: &str|
         -> Result<(ServedLink, SharedBank), ServeError> {
            let bank: SharedBank = Arc::new(Mutex::new(RegisterBank::for_profile(profile)));
            let service = BankService::new(unit, bank.clone(), device);
            let baud = profile.serial.map_or(115_200, |s| s.baud_rate);
            let faults = ProtocolFaults::for_device(faults, role, epoch);
            let (link, task) = serve_device(transport, service, baud, &mut pty_ends, faults)?;
            tasks.push(task);
            Ok((link, bank))
        };
        let (supply_link, supply_bank) =
            serve(sd.profile, sd.unit, Arc::new(supply_dev), "supply")?;
        let (dyno_link, dyno_bank) = serve(dd.profile, dd.unit, Arc::new(dyno_dev), "dynamometer")?;
        let (meter_link, _) = serve(md.profile, md.unit, Arc::new(meter_dev), "meter")?;
        let (encoder_link, _) = serve(ed.profile, ed.unit, Arc::new(encoder_dev), "encoder")?;
        let dc_source_link = match dc_dev {
            Some((d, dev)) => Some(serve(d.profile, d.unit, Arc::new(dev), "dc_source")?.0),
            None => None,
        };
        Ok(ServedImRig {
            supply: ServedVfd {
                link: supply_link,
                bank: supply_bank,
            },
            dynamometer: ServedVfd {
                link: dyno_link,
                bank: dyno_bank,
            },
            meter_link,
            encoder_link,
            dc_source_link,
            tasks,
            _pty_ends: pty_ends,
            vfd,
            dyno,
        })
    }

    /// Whether the simulated supply's output is on, as the plant sees it.
    pub fn supply_output_enabled(&self) -> bool {
        self.vfd.output_enabled()
    }

    /// The simulated dynamometer's speed set point and whether it holds
    /// it, as the plant sees them (a stopped drive holds zero).
    pub fn dyno_command(&self) -> (f64, bool) {
        self.dyno.command()
    }
}

impl Drop for ServedImRig {
    fn drop(&mut self) {
        for t in &self.tasks {
            t.abort();
        }
    }
}
