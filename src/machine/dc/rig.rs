//! Build the rig a configuration names: the simulated rig in process, or a
//! power stage and sensors over Modbus (with the simulated rig served
//! behind the links when the configuration asks for it). Sensors on more
//! than one link (a Modbus DAQ or a serial stream, plus CAN signals) are
//! merged into one stream ([`MergedSensors`]), each link read by its own
//! task.

use motorbench_drivers::can::{
    CanChannel, CanSignalSensors, SlcanOptions, SlcanStream, SocketCanStream,
};
use motorbench_drivers::modbus::{ModbusPowerStage, ModbusSensors, PolledChannel};
use motorbench_drivers::serial::port::open_serial;
use motorbench_drivers::serial::{SerialChannel, SerialSensors};
use motorbench_drivers::{ChannelInfo, LinkHealth, MergedSensors, PowerStage, SensorStream};

use super::served::{ServedDaq, ServedRig};
use super::sim_rig;
use crate::config::{Backend, CanLink, CanTransport, Config, ModbusRig, SensorLink};
use crate::model::DcParams;
use crate::rig::{Buses, ModbusProbe, RigError, ServedLink};

/// Plant rate of the simulated rig when it is served behind a protocol,
/// Hz (independent of the bench's poll rate).
pub const SERVED_PLANT_RATE_HZ: f64 = 2000.0;

/// A rig ready for a test.
pub struct Rig {
    /// What drives the motor.
    pub stage: Box<dyn PowerStage>,
    /// What measures it.
    pub sensors: Box<dyn SensorStream>,
    /// Encoder counts per revolution.
    pub counts_per_rev: f64,
    /// The simulated motor's true parameters (simulated rigs only).
    pub truth: Option<DcParams>,
    /// The simulated rig's servers, when it is served behind a protocol.
    pub served: Option<ServedRig>,
    /// The Modbus sensors again, for a one-shot read (`probe`).
    pub modbus_sensors: Option<ModbusProbe>,
    /// The health of the rig's Modbus buses, one per link.
    pub links: Vec<LinkHealth>,
}

async fn modbus_rig(
    faults: &[crate::config::Fault],
    m: &ModbusRig,
    simulated: Option<&crate::config::SimulatedRig>,
    sample_rate_hz: f64,
) -> Result<Rig, RigError> {
    let served = match (m.simulate, simulated) {
        (Some(t), Some(sim)) => {
            let daq = match &m.sensors {
                SensorLink::Modbus(l) => ServedDaq::Modbus(&l.profile, l.unit_id),
                SensorLink::Serial { framing, .. } => ServedDaq::Stream {
                    framing: *framing,
                    rate_hz: sample_rate_hz,
                },
            };
            Some(
                ServedRig::start(
                    sim,
                    SERVED_PLANT_RATE_HZ,
                    t,
                    (&m.power_stage.profile, m.power_stage.unit_id),
                    daq,
                    faults,
                )
                .await?,
            )
        }
        _ => None,
    };
    let mut buses = Buses::new(m.policy, served.is_some());
    let stage_bus = buses.bus(
        "modbus-stage",
        &m.power_stage,
        served.as_ref().map(|s| &s.stage_link),
    );
    let stage_id = format!("modbus:{}", m.power_stage.profile.name);
    let stage = ModbusPowerStage::new(
        &stage_id,
        stage_bus.clone(),
        m.power_stage.unit_id,
        &m.power_stage.profile,
    )?;
    let (sensors, modbus_sensors): (Box<dyn SensorStream>, _) = match &m.sensors {
        SensorLink::Modbus(link) => {
            // One task per link: a stage and sensors on one line share it.
            let sensor_bus = buses.bus(
                "modbus-sensors",
                link.as_ref(),
                served.as_ref().map(|s| &s.daq_link),
            );
            let source = format!("modbus:{}", link.profile.name);
            let channels: Vec<PolledChannel> = m
                .channels
                .iter()
                .map(|c| {
                    let r = link
                        .profile
                        .register(&c.name)
                        .expect("checked when the configuration was loaded")
                        .clone();
                    PolledChannel {
                        unit: link.unit_id,
                        info: ChannelInfo {
                            quantity: c.quantity.clone(),
                            unit: r.unit.clone(),
                            source: source.clone(),
                            rate_hz: c.rate_hz,
                        },
                        register: r,
                    }
                })
                .collect();
            let sensors = ModbusSensors::new(
                &source,
                sensor_bus.clone(),
                channels.clone(),
                m.max_lost_polls,
            )
            .with_max_read_gap(link.profile.max_read_gap);
            (
                Box::new(sensors) as Box<dyn SensorStream>,
                Some(ModbusProbe {
                    bus: sensor_bus,
                    channels,
                }),
            )
        }
        SensorLink::Serial { port, framing } => {
            let settings = match (port, served.as_ref().map(|s| &s.daq_link)) {
                (_, Some(ServedLink::Stream(s))) | (Some(s), None) => s.clone(),
                _ => unreachable!("a simulated stream is always served"),
            };
            let io = open_serial(&settings)?;
            let source = format!("serial:{}", settings.path);
            let channels = m
                .channels
                .iter()
                .map(|c| SerialChannel {
                    key: c.name.clone(),
                    info: ChannelInfo {
                        quantity: c.quantity.clone(),
                        unit: match c.quantity.as_str() {
                            "armature_voltage" => "V",
                            "armature_current" => "A",
                            "encoder_count" => "count",
                            _ => "",
                        }
                        .into(),
                        source: source.clone(),
                        rate_hz: c.rate_hz,
                    },
                })
                .collect();
            (
                Box::new(SerialSensors::new(&source, io, *framing, channels))
                    as Box<dyn SensorStream>,
                None,
            )
        }
    };
    let mut served = served;
    let sensors = match &m.can {
        None => sensors,
        Some(can) => {
            let can_sensors = can_sensors(can, served.as_mut()).await?;
            Box::new(MergedSensors::new(
                "merged",
                vec![sensors, can_sensors],
                m.merge_window,
            )) as Box<dyn SensorStream>
        }
    };
    Ok(Rig {
        stage: Box::new(stage),
        sensors,
        counts_per_rev: 4.0 * f64::from(m.encoder_lines),
        truth: simulated.filter(|_| m.simulate.is_some()).map(|s| s.motor),
        served,
        modbus_sensors,
        links: buses.health(),
    })
}

/// The CAN signals of `can` as a sensor stream: over the simulated encoder
/// when `served`, else over the configured adapter or interface.
async fn can_sensors(
    can: &CanLink,
    served: Option<&mut ServedRig>,
) -> Result<Box<dyn SensorStream>, RigError> {
    let name = std::path::Path::new(&can.dbc_path)
        .file_stem()
        .map_or_else(|| "dbc".into(), |s| s.to_string_lossy().into_owned());
    let channels = |source: &str| -> Vec<CanChannel> {
        can.channels
            .iter()
            .map(|c| CanChannel {
                signal: c.name.clone(),
                info: ChannelInfo {
                    quantity: c.quantity.clone(),
                    unit: can
                        .map
                        .find(&c.name)
                        .map_or_else(String::new, |(_, s)| s.unit.clone()),
                    source: source.to_string(),
                    rate_hz: c.rate_hz,
                },
            })
            .collect()
    };
    let (port, bitrate, ack_timeout) = match (&can.transport, served) {
        (CanTransport::Slcan { bitrate, .. }, Some(served)) => {
            // The simulated encoder sends at the rate of its first channel
            // (one message carries them all).
            let rate = can.channels.first().map_or(100.0, |c| c.rate_hz);
            let settings = served
                .serve_can_encoder_on_pty(can.map.clone(), rate)
                .await?;
            (settings, *bitrate, None)
        }
        (
            CanTransport::Slcan {
                port: Some(p),
                bitrate,
            },
            None,
        ) => (p.clone(), *bitrate, SlcanOptions::default().ack_timeout),
        (CanTransport::Slcan { port: None, .. }, None) => {
            unreachable!("an SLCAN port is given unless the encoder is served")
        }
        (CanTransport::SocketCan { interface }, _) => {
            let source = format!("socketcan:{interface}:{name}");
            let frames = SocketCanStream::open(interface)?;
            let s = CanSignalSensors::new(&source, frames, can.map.clone(), channels(&source))?;
            return Ok(Box::new(s));
        }
    };
    let source = format!("slcan:{}:{name}", port.path);
    let io = open_serial(&port)?;
    let opts = SlcanOptions {
        bitrate,
        listen_only: false,
        ack_timeout,
    };
    let frames = SlcanStream::open(io, &source, opts).await?;
    let s = CanSignalSensors::new(&source, frames, can.map.clone(), channels(&source))?;
    Ok(Box::new(s))
}

/// Build `cfg`'s rig. `realtime` paces the in-process simulated rig at
/// wall-clock time (a served or real rig always runs on it).
pub async fn build_rig(cfg: &Config, realtime: bool) -> Result<Rig, RigError> {
    match &cfg.backend {
        Backend::Simulated(sim) => {
            let (stage, sensors) = sim_rig::sim_rig(sim, cfg.common.sample_rate_hz, realtime)
                .map_err(|e| RigError::Simulated(e.to_string()))?;
            Ok(Rig {
                stage: Box::new(stage),
                sensors: Box::new(sensors),
                counts_per_rev: 4.0 * f64::from(sim.sensors.encoder_lines),
                truth: Some(sim.motor),
                served: None,
                modbus_sensors: None,
                links: Vec::new(),
            })
        }
        Backend::Modbus { rig, simulated } => {
            modbus_rig(
                &cfg.common.faults.protocol_faults(),
                rig,
                simulated.as_ref(),
                cfg.common.sample_rate_hz,
            )
            .await
        }
    }
}
