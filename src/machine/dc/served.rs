//! The simulated rig behind the real protocols: the simulated supply
//! served as a Modbus device with a shipped profile's register map (e.g.
//! the Riden RD6006's), each on its own Modbus TCP server on 127.0.0.1 (a
//! port the OS picks) or its own RTU server on a pseudo-terminal pair; the
//! simulated sensors either as a Modbus DAQ (`config/devices/sim-daq.toml`)
//! or as a DAQ that streams records (ASCII or binary framing) over a
//! pseudo-terminal at its sample rate, stamped with the plant's own time.
//! The bench then reaches them through the real driver code, exactly as it
//! would reach hardware.
//!
//! The plant runs on the wall clock: every request first advances it to
//! "now" in steps of its own sample period, so a set point written at
//! time t acts from t on, and a read returns the sensors' latest sample.

use std::sync::{Arc, Mutex};
use std::time::Instant;

use motorbench_drivers::can::{FrameStream, SignalMap, SlcanOptions, SlcanStream};
use motorbench_drivers::modbus::server::{
    lock_bank, BankService, ExceptionCode, RegisterBank, SharedBank, SimulatedDevice, WriteSpan,
};
use motorbench_drivers::modbus::{DeviceProfile, Register};
use motorbench_drivers::serial::port::{pty_pair, SerialSettings, SerialStream};
use motorbench_drivers::serial::{ascii, binary, SerialFraming, StreamRecord};
use motorbench_drivers::{PowerStage, SampleBatch};
use tokio::io::AsyncWriteExt;
use tokio::task::JoinHandle;

use super::sim_rig::{channel, sim_rig, SimPowerStage, SimSensors};
use crate::config::{Fault, SimulatedRig, SimulatedTransport};
use crate::machine::sim_parts::{lock_plant, plant_now, power_stage_map, ServedPlant};
use crate::rig::fault::{FaultyLine, ProtocolFaults, StreamRecordFate};
use crate::rig::{
    enable_written, ready_now, register, serve_device, touches, ServeError, ServedLink,
    SupplyReadback, WallClock,
};

/// The simulated plant on the wall clock.
struct RealtimePlant {
    stage: SimPowerStage,
    sensors: SimSensors,
    clock: WallClock,
    last: Option<SampleBatch>,
    /// The sensor readings of the latest steps, `(step, batch)`, oldest
    /// first: for devices that sample on their own clock while the host is
    /// late to run them (a streaming DAQ, the CAN encoder's event timer).
    history: std::collections::VecDeque<(u64, SampleBatch)>,
}

/// Plant steps kept for late senders (half a second at 2 kHz).
const HISTORY: usize = 1024;

impl ServedPlant for RealtimePlant {
    fn catch_up(&mut self) {
        let (sensors, history, last) = (&mut self.sensors, &mut self.history, &mut self.last);
        self.clock.catch_up(|step| {
            let b = sensors.sample();
            if history.len() == HISTORY {
                history.pop_front();
            }
            history.push_back((step, b.clone()));
            *last = Some(b);
        });
    }

    fn last(&self) -> Option<&SampleBatch> {
        self.last.as_ref()
    }
}

impl RealtimePlant {
    /// The readings at the plant instant `at`: the step taken there and
    /// its values of `channels` (the latest step not after `at`, as far
    /// back as the history goes).
    fn readings_at(&mut self, at: Instant, channels: &[usize]) -> (u64, Vec<f64>) {
        self.catch_up();
        let step = self.clock.step_at(at);
        let i = self.history.partition_point(|(s, _)| *s <= step);
        let found = match i {
            0 => self.history.front(),
            i => self.history.get(i - 1),
        };
        match found {
            Some((s, b)) => (
                *s,
                channels
                    .iter()
                    .map(|&c| b.value(c).unwrap_or(0.0))
                    .collect(),
            ),
            None => (0, vec![0.0; channels.len()]),
        }
    }
}

type SharedPlant = Arc<Mutex<RealtimePlant>>;

/// The simulated supply behind its profile's power-stage registers, with
/// optional readback registers `voltage_out` / `current_out`.
struct SupplyDevice {
    plant: SharedPlant,
    setpoint: Register,
    enable: Option<(Register, u16, u16)>,
    current_limit: Option<Register>,
    readback: SupplyReadback,
}

impl SimulatedDevice for SupplyDevice {
    fn before_read(&self, bank: &mut RegisterBank) {
        let p = plant_now(&self.plant);
        self.readback.show(
            bank,
            p.reading(channel::VOLTAGE),
            p.reading(channel::CURRENT),
        );
    }

    fn after_write(
        &self,
        bank: &mut RegisterBank,
        _before: &RegisterBank,
        span: WriteSpan,
    ) -> Result<(), ExceptionCode> {
        let mut p = plant_now(&self.plant);
        if touches(&span, &self.setpoint) {
            ready_now(p.stage.set_setpoint(bank.get(&self.setpoint)))
                .map_err(|_| ExceptionCode::IllegalDataValue)?;
        }
        if let Some(r) = &self.current_limit {
            if touches(&span, r) {
                ready_now(p.stage.set_current_limit(bank.get(r)))
                    .map_err(|_| ExceptionCode::IllegalDataValue)?;
            }
        }
        if let Some(enable) = &self.enable {
            if let Some(enabled) = enable_written(bank, &span, enable)? {
                ready_now(p.stage.set_output_enabled(enabled))
                    .map_err(|_| ExceptionCode::ServerDeviceFailure)?;
            }
        }
        Ok(())
    }
}

/// The simulated sensors as a DAQ: voltage, current, encoder count.
struct DaqDevice {
    plant: SharedPlant,
    voltage: Register,
    current: Register,
    count: Register,
}

impl SimulatedDevice for DaqDevice {
    fn before_read(&self, bank: &mut RegisterBank) {
        let p = plant_now(&self.plant);
        bank.set(&self.voltage, p.reading(channel::VOLTAGE));
        bank.set(&self.current, p.reading(channel::CURRENT));
        bank.set(&self.count, p.reading(channel::ENCODER));
    }
}

/// How the simulated sensors are served.
#[derive(Debug, Clone, Copy)]
pub enum ServedDaq<'a> {
    /// As Modbus registers of this profile, on this unit.
    Modbus(&'a DeviceProfile, u8),
    /// As a stream of records at `rate_hz`, keys `armature_voltage`,
    /// `armature_current`, `encoder_count` (ASCII) or `0`, `1`, `2`
    /// (binary).
    Stream {
        /// The line protocol.
        framing: SerialFraming,
        /// Records per second.
        rate_hz: f64,
    },
}

/// Stream the plant's sensor readings as records, one per `period` on the
/// DAQ's own clock: a slot the host runs late still sends the readings of
/// its own instant (the frames of missed slots then go out together, as
/// from a DAQ's buffer). Each record passes the DAQ's `faults` first.
async fn stream_daq(
    plant: SharedPlant,
    mut io: SerialStream,
    framing: SerialFraming,
    period: std::time::Duration,
    faults: Option<ProtocolFaults>,
) {
    let mut tick = tokio::time::interval(period);
    tick.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Burst);
    if framing == SerialFraming::Binary && io.write_all(&[0]).await.is_err() {
        return;
    }
    let mut seq = 0u32;
    let mut last_step = None;
    let channels = [channel::VOLTAGE, channel::CURRENT, channel::ENCODER];
    loop {
        let slot = tick.tick().await.into_std();
        let (step, t_us, values) = {
            let mut p = lock_plant(&plant);
            let (step, readings) = p.readings_at(slot, &channels);
            let t_us = (step as f64 * p.clock.period_s() * 1e6).round() as u64;
            let values = readings
                .into_iter()
                .zip(["armature_voltage", "armature_current", "encoder_count"])
                .enumerate()
                .map(|(k, (value, name))| {
                    let key = match framing {
                        SerialFraming::Ascii => name.to_string(),
                        SerialFraming::Binary => k.to_string(),
                    };
                    (key, value)
                })
                .collect();
            (step, t_us, values)
        };
        // One record per plant step at most: a late tick sends the
        // newest sample, never a repeat.
        if last_step == Some(step) {
            continue;
        }
        last_step = Some(step);
        seq = seq.wrapping_add(1);
        let record = StreamRecord { seq, t_us, values };
        let bytes = match framing {
            SerialFraming::Ascii => ascii::encode(&record),
            SerialFraming::Binary => binary::encode(&record),
        };
        let fate = match &faults {
            Some(f) => f.stream_record(framing, bytes),
            None => StreamRecordFate::Send(bytes),
        };
        let bytes = match fate {
            StreamRecordFate::Send(b) => b,
            StreamRecordFate::Drop => continue,
            StreamRecordFate::HangUp => return,
        };
        if io.write_all(&bytes).await.is_err() {
            return;
        }
    }
}

/// The simulated rig, served. Dropping it stops the servers.
pub struct ServedRig {
    /// Where the supply answers.
    pub stage_link: ServedLink,
    /// Where the DAQ answers.
    pub daq_link: ServedLink,
    /// The supply's registers (for tests and diagnostics).
    pub stage_bank: SharedBank,
    /// The DAQ's registers (empty for a streaming DAQ).
    pub daq_bank: SharedBank,
    stage_task: Option<JoinHandle<()>>,
    daq_task: Option<JoinHandle<()>>,
    _pty_ends: Vec<SerialStream>,
    stage: SimPowerStage,
    plant: SharedPlant,
    encoder_task: Option<JoinHandle<()>>,
    /// The protocol faults that target the CAN encoder (`encoder`).
    encoder_faults: Option<ProtocolFaults>,
}

impl std::fmt::Debug for ServedRig {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ServedRig")
            .field("stage_link", &self.stage_link)
            .field("daq_link", &self.daq_link)
            .finish()
    }
}

impl ServedRig {
    /// Serve `sim` (its plant stepped at `plant_rate_hz`): the supply with
    /// `supply`'s register map on its unit, over `transport`; the sensors
    /// as `daq` says; each device (`power_stage`, `sensors`) with the
    /// protocol faults of `faults` that target it (on the time since now).
    pub async fn start(
        sim: &SimulatedRig,
        plant_rate_hz: f64,
        transport: SimulatedTransport,
        supply: (&DeviceProfile, u8),
        daq: ServedDaq<'_>,
        faults: &[Fault],
    ) -> Result<ServedRig, ServeError> {
        let epoch = Instant::now();
        let faults_of = |device: &str| ProtocolFaults::for_device(faults, device, epoch);
        let (stage, sensors) =
            sim_rig(sim, plant_rate_hz, false).map_err(|e| ServeError::Motor(e.to_string()))?;
        let plant = Arc::new(Mutex::new(RealtimePlant {
            stage: stage.clone(),
            sensors,
            clock: WallClock::start(plant_rate_hz),
            last: None,
            history: std::collections::VecDeque::with_capacity(HISTORY),
        }));
        let (sp, su) = supply;
        let map = power_stage_map(sp)?;
        let supply_dev = SupplyDevice {
            plant: plant.clone(),
            setpoint: register(sp, &map.setpoint)?,
            enable: match &map.enable {
                Some((n, on, off)) => Some((register(sp, n)?, *on, *off)),
                None => None,
            },
            current_limit: match &map.current_limit {
                Some(n) => Some(register(sp, n)?),
                None => None,
            },
            readback: SupplyReadback::of(sp),
        };
        let stage_bank: SharedBank = Arc::new(Mutex::new(RegisterBank::for_profile(sp)));
        let stage_service = BankService::new(su, stage_bank.clone(), Arc::new(supply_dev));
        let mut pty_ends = Vec::new();
        let mut serve = |service: BankService, baud: u32, device: &str| {
            serve_device(transport, service, baud, &mut pty_ends, faults_of(device))
        };
        let baud = |p: &DeviceProfile| p.serial.map_or(115_200, |s| s.baud_rate);
        let (stage_link, stage_task) = serve(stage_service, baud(sp), "power_stage")?;
        let (daq_link, daq_task, daq_bank) = match daq {
            ServedDaq::Modbus(dp, du) => {
                let daq_dev = DaqDevice {
                    plant: plant.clone(),
                    voltage: register(dp, "armature_voltage")?,
                    current: register(dp, "armature_current")?,
                    count: register(dp, "encoder_count")?,
                };
                let bank: SharedBank = Arc::new(Mutex::new(RegisterBank::for_profile(dp)));
                let service = BankService::new(du, bank.clone(), Arc::new(daq_dev));
                let (link, task) = serve(service, baud(dp), "sensors")?;
                (link, task, bank)
            }
            ServedDaq::Stream { framing, rate_hz } => {
                let pty = pty_pair().map_err(|e| ServeError::Io(e.to_string()))?;
                let settings = SerialSettings::new_8n1(&pty.device_path, 921_600);
                let period = std::time::Duration::from_secs_f64(1.0 / rate_hz);
                let task = tokio::spawn(stream_daq(
                    plant.clone(),
                    pty.host,
                    framing,
                    period,
                    faults_of("sensors"),
                ));
                pty_ends.push(pty.device_end);
                (
                    ServedLink::Stream(settings),
                    task,
                    Arc::new(Mutex::new(RegisterBank::default())),
                )
            }
        };
        Ok(ServedRig {
            stage_link,
            daq_link,
            stage_bank,
            daq_bank,
            stage_task: Some(stage_task),
            daq_task: Some(daq_task),
            _pty_ends: pty_ends,
            stage,
            plant,
            encoder_task: None,
            encoder_faults: faults_of("encoder"),
        })
    }

    /// Also simulate a CANopen encoder on `frames`: the message of `map`
    /// that carries the signal `position` is sent at `rate_hz` with the
    /// plant's encoder count (as an unsigned 32-bit position, wrapping),
    /// other signals zero. Like a real encoder's event timer, every slot is
    /// sent with the position at the slot's own time, also when the host
    /// runs the sender late (then the frames of the missed slots go out
    /// together). The protocol faults on `encoder` act on it: while a
    /// `bus_timeout` lasts it sends nothing; a `disconnect` ends the sender
    /// and with it `frames`. Replaces an encoder started before.
    pub fn start_can_encoder(
        &mut self,
        frames: Box<dyn FrameStream>,
        map: SignalMap,
        rate_hz: f64,
    ) -> Result<(), ServeError> {
        let (id, _) = map
            .find("position")
            .ok_or_else(|| ServeError::MissingRegister {
                profile: "the encoder's DBC file".into(),
                register: "position".into(),
            })?;
        let plant = self.plant.clone();
        let faults = self.encoder_faults.clone();
        let period = std::time::Duration::from_secs_f64(1.0 / rate_hz);
        let mut frames = frames;
        let task = tokio::spawn(async move {
            let mut tick = tokio::time::interval(period);
            tick.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Burst);
            loop {
                let slot = tick.tick().await.into_std();
                match faults.as_ref().and_then(ProtocolFaults::withheld) {
                    Some(StreamRecordFate::HangUp) => return,
                    Some(_) => continue,
                    None => {}
                }
                let count = lock_plant(&plant).readings_at(slot, &[channel::ENCODER]).1[0];
                let position = count.rem_euclid(4_294_967_296.0);
                let Some(frame) = map.encode(id, &[("position", position)]) else {
                    return;
                };
                if frames.send(&frame).await.is_err() {
                    return;
                }
            }
        });
        if let Some(old) = self.encoder_task.replace(task) {
            old.abort();
        }
        Ok(())
    }

    /// Serve the simulated CANopen encoder (see [`Self::start_can_encoder`])
    /// over SLCAN on a new pseudo-terminal pair, as a USB-CAN adapter would
    /// present it: the settings of the end the bench opens. The encoder's
    /// end sends no answers to setup commands: open the bench's end with
    /// `ack_timeout: None`. While `garbage` on `encoder` lasts, noise
    /// comes before each of its frames on that line ([`FaultyLine`]).
    pub async fn serve_can_encoder_on_pty(
        &mut self,
        map: SignalMap,
        rate_hz: f64,
    ) -> Result<SerialSettings, ServeError> {
        let pty = pty_pair().map_err(|e| ServeError::Io(e.to_string()))?;
        let opts = SlcanOptions {
            bitrate: None,
            listen_only: false,
            ack_timeout: None,
        };
        let io = |e: motorbench_drivers::DriverError| ServeError::Io(e.to_string());
        let name = "sim-cia406-encoder";
        let encoder_side: Box<dyn FrameStream> = match self
            .encoder_faults
            .as_ref()
            .filter(|f| FaultyLine::needed(f))
        {
            None => Box::new(SlcanStream::open(pty.host, name, opts).await.map_err(io)?),
            Some(f) => {
                // The adapter's line through its faults: the encoder's
                // end on an in-process pipe, relayed to the terminal.
                let (adapter, line_end) = tokio::io::duplex(4096);
                tokio::spawn(FaultyLine::unasked(f.clone()).relay(pty.host, line_end));
                Box::new(SlcanStream::open(adapter, name, opts).await.map_err(io)?)
            }
        };
        self.start_can_encoder(encoder_side, map, rate_hz)?;
        let settings = SerialSettings::new_8n1(&pty.device_path, 115_200);
        self._pty_ends.push(pty.device_end);
        Ok(settings)
    }

    /// Stop the simulated CAN encoder, as if its cable were pulled.
    pub fn pull_can_cable(&mut self) {
        if let Some(t) = self.encoder_task.take() {
            t.abort();
        }
    }

    /// Stop serving the sensors, as if their cable were pulled: the
    /// connection closes (TCP) or the line goes silent (RTU).
    pub fn pull_sensor_cable(&mut self) {
        if let Some(t) = self.daq_task.take() {
            t.abort();
        }
    }

    /// Stop serving the power stage (its cable pulled).
    pub fn pull_stage_cable(&mut self) {
        if let Some(t) = self.stage_task.take() {
            t.abort();
        }
    }

    /// The simulated supply's output enable, as the plant sees it.
    pub fn stage_output_enabled(&self) -> bool {
        self.stage.output_enabled()
    }

    /// The simulated supply's set point, as the plant sees it.
    pub fn stage_setpoint(&self) -> f64 {
        self.stage.setpoint()
    }

    /// The value (SI) a supply register holds.
    pub fn stage_register(&self, r: &Register) -> f64 {
        lock_bank(&self.stage_bank).get(r)
    }
}

impl Drop for ServedRig {
    fn drop(&mut self) {
        self.pull_sensor_cable();
        self.pull_stage_cable();
        if let Some(t) = self.encoder_task.take() {
            t.abort();
        }
    }
}
