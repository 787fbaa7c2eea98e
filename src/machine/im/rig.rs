//! Build the rig an induction-machine sweep configuration names: the
//! simulated rig in process, or the supply VFD, the dynamometer VFD, the
//! power meter, the encoder counter and (for the standard tests) the DC
//! source over Modbus (with the simulated rig served behind those links
//! when the configuration asks for it).

use motorbench_drivers::modbus::{BusHandle, ModbusPowerStage, ModbusSensors, PolledChannel};
use motorbench_drivers::{
    ChannelInfo, DriverError, LinkHealth, MergedSensors, PowerStage, SensorStream,
};

use super::served::{ServedDevice, ServedImRig};
use super::{sim_im_rig, DcCurrentSource, ImModbusRig, ImRunConfig, VfdDyno, VfdSupply};
use crate::config::ModbusDeviceLink;
use crate::model::ImCircuit;
use crate::rig::{same_link, Buses, RigError};

/// Plant rate of the simulated induction-machine rig when it is served
/// behind Modbus, Hz (independent of the bench's poll rate).
pub const SERVED_IM_PLANT_RATE_HZ: f64 = 1000.0;

/// An induction-machine rig ready for a sweep.
pub struct ImRig {
    /// The supply VFD (set point: line voltage, V).
    pub supply: Box<dyn PowerStage>,
    /// The dynamometer (set point: shaft speed, rad/s).
    pub dynamometer: Box<dyn PowerStage>,
    /// The DC source of the winding-resistance test (set point: DC
    /// current between two line terminals, A), where the rig has one.
    pub dc_source: Option<Box<dyn PowerStage>>,
    /// Line voltage, line current, input power, encoder count (and torque
    /// where fitted).
    pub sensors: Box<dyn SensorStream>,
    /// Encoder counts per revolution.
    pub counts_per_rev: f64,
    /// The simulated machine's circuit (simulated rigs only).
    pub truth: Option<ImCircuit>,
    /// The simulated rig's servers, when it is served behind Modbus.
    pub served: Option<ServedImRig>,
    /// The health of the rig's Modbus buses, one per link.
    pub links: Vec<LinkHealth>,
}

impl std::fmt::Debug for ImRig {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ImRig")
            .field("supply", &self.supply.id())
            .field("dynamometer", &self.dynamometer.id())
            .field("sensors", &self.sensors.id())
            .field("served", &self.served)
            .finish()
    }
}

/// The power stage of the Modbus device `link` on `bus`, named
/// `modbus:<profile> (<role>)`.
fn drive(
    link: &ModbusDeviceLink,
    role: &str,
    bus: &BusHandle,
) -> Result<ModbusPowerStage, DriverError> {
    ModbusPowerStage::new(
        &format!("modbus:{} ({role})", link.profile.name),
        bus.clone(),
        link.unit_id,
        &link.profile,
    )
}

fn polled(
    device: &ModbusDeviceLink,
    channels: &[(String, String)],
    rate_hz: f64,
) -> Vec<PolledChannel> {
    let source = format!("modbus:{}", device.profile.name);
    channels
        .iter()
        .map(|(quantity, name)| {
            let register = device
                .profile
                .register(name)
                .expect("checked when the configuration was loaded")
                .clone();
            PolledChannel {
                unit: device.unit_id,
                info: ChannelInfo {
                    quantity: quantity.clone(),
                    unit: register.unit.clone(),
                    source: source.clone(),
                    rate_hz,
                },
                register,
            }
        })
        .collect()
}

async fn modbus_im_rig(cfg: &ImRunConfig, m: &ImModbusRig) -> Result<ImRig, RigError> {
    let served = match (m.simulate, &cfg.simulated) {
        (Some(transport), Some(sim)) => Some(
            ServedImRig::start(
                sim,
                SERVED_IM_PLANT_RATE_HZ,
                transport,
                (ServedDevice::of(&m.supply), &m.supply_voltage_register),
                (ServedDevice::of(&m.dynamometer), m.dyno_pole_pairs),
                (ServedDevice::of(&m.meter), &m.meter_channels),
                (ServedDevice::of(&m.encoder), &m.encoder_channels),
                m.dc_source.as_ref().map(|d| ServedDevice::of(&d.device)),
                &cfg.common.faults.protocol_faults(),
            )
            .await?,
        ),
        _ => None,
    };
    let s = served.as_ref();
    let mut buses = Buses::new(m.policy, s.is_some());
    let supply_bus = buses.bus("modbus-supply", &m.supply, s.map(|s| &s.supply.link));
    let dyno_bus = buses.bus(
        "modbus-dyno",
        &m.dynamometer,
        s.map(|s| &s.dynamometer.link),
    );
    let meter_bus = buses.bus("modbus-meter", &m.meter, s.map(|s| &s.meter_link));
    let encoder_bus = buses.bus("modbus-encoder", &m.encoder, s.map(|s| &s.encoder_link));

    let supply_drive = drive(&m.supply, "supply", &supply_bus)?;
    let voltage = m
        .supply
        .profile
        .register(&m.supply_voltage_register)
        .expect("checked when the configuration was loaded")
        .clone();
    let supply = VfdSupply::new(
        supply_drive,
        supply_bus,
        m.supply.unit_id,
        voltage,
        cfg.plan.frequency,
        cfg.common.limits.max_voltage,
    );
    let dyno_drive = drive(&m.dynamometer, "dynamometer", &dyno_bus)?;
    let mut dynamometer = VfdDyno::new(dyno_drive, m.dyno_pole_pairs);
    let control = m.dynamometer.profile.power_stage.as_ref().and_then(|s| {
        let (name, ..) = s.enable.as_ref()?;
        m.dynamometer.profile.register(name).cloned()
    });
    if let (Some(value), Some(control)) = (m.dyno_coast_value, control) {
        dynamometer = dynamometer.with_coast(dyno_bus, m.dynamometer.unit_id, control, value);
    }

    // The DC source: its stage, and its read-back channels polled.
    let dc = match &m.dc_source {
        Some(d) => {
            let bus = buses.bus(
                "modbus-dc-source",
                &d.device,
                s.and_then(|s| s.dc_source_link.as_ref()),
            );
            let source = drive(&d.device, "DC source", &bus)?;
            let stage = DcCurrentSource::new(source, d.compliance_voltage, cfg.plan.rated_current);
            Some((stage, &d.device, bus, &d.channels))
        }
        None => None,
    };

    let rate = cfg.common.sample_rate_hz;
    // The devices polled, with their buses: those on one line (a real rig)
    // share one poller, the units read in turn.
    let mut groups: Vec<(&ModbusDeviceLink, _, Vec<PolledChannel>)> = Vec::new();
    let devices = [
        Some((&m.meter, meter_bus, &m.meter_channels)),
        Some((&m.encoder, encoder_bus, &m.encoder_channels)),
        dc.as_ref().map(|(_, d, bus, ch)| (*d, bus.clone(), *ch)),
    ];
    for (device, bus, channels) in devices.into_iter().flatten() {
        let channels = polled(device, channels, rate);
        match groups
            .iter_mut()
            .find(|(d, _, _)| s.is_none() && same_link(d, device))
        {
            Some((_, _, all)) => all.extend(channels),
            None => groups.push((device, bus, channels)),
        }
    }
    let mut pollers: Vec<Box<dyn SensorStream>> = groups
        .into_iter()
        .map(|(link, bus, channels)| {
            Box::new(
                ModbusSensors::new(
                    &format!("modbus:{}", link.profile.name),
                    bus,
                    channels,
                    m.max_lost_polls,
                )
                .with_max_read_gap(link.profile.max_read_gap),
            ) as Box<dyn SensorStream>
        })
        .collect();
    let sensors: Box<dyn SensorStream> = if pollers.len() == 1 {
        pollers.remove(0)
    } else {
        // Separate links: a poller each, their batches (each with one
        // device's channels) put on one time base and in time order; the
        // plan holds the latest value of every channel.
        let ids: Vec<&str> = pollers.iter().map(|p| p.id()).collect();
        let name = format!("modbus-merged({})", ids.join("+"));
        Box::new(MergedSensors::new(&name, pollers, m.merge_window))
    };
    Ok(ImRig {
        supply: Box::new(supply),
        dynamometer: Box::new(dynamometer),
        dc_source: dc.map(|(stage, ..)| Box::new(stage) as Box<dyn PowerStage>),
        sensors,
        counts_per_rev: cfg.plan.encoder_counts_per_rev,
        truth: cfg
            .simulated
            .as_ref()
            .filter(|_| m.simulate.is_some())
            .map(|s| s.circuit),
        served,
        links: buses.health(),
    })
}

/// Build `cfg`'s rig. `realtime` paces the in-process simulated rig at
/// wall-clock time (a served or real rig always runs on it).
pub async fn build_im_rig(cfg: &ImRunConfig, realtime: bool) -> Result<ImRig, RigError> {
    match (&cfg.modbus, &cfg.simulated) {
        (Some(m), _) => modbus_im_rig(cfg, m).await,
        (None, Some(sim)) => {
            let (vfd, dyno, sensors) =
                sim_im_rig(sim.clone()).map_err(|e| RigError::Simulated(e.to_string()))?;
            let sensors = if realtime { sensors.paced() } else { sensors };
            Ok(ImRig {
                dc_source: vfd
                    .dc_source()
                    .map(|dc| Box::new(dc) as Box<dyn PowerStage>),
                supply: Box::new(vfd),
                dynamometer: Box::new(dyno),
                sensors: Box::new(sensors),
                counts_per_rev: cfg.plan.encoder_counts_per_rev,
                truth: Some(sim.circuit),
                served: None,
                links: Vec::new(),
            })
        }
        (None, None) => Err(RigError::Simulated(
            "the configuration names no rig (checked when it was loaded)".into(),
        )),
    }
}
