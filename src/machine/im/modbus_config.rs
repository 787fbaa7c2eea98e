//! The `[rig.modbus]` section of an induction-machine sweep configuration:
//! the supply VFD, the dynamometer's VFD, the power meter and the encoder
//! counter, each a Modbus device with its profile (`config/devices/`),
//! optionally with the simulated rig served behind them.
//!
//! ```toml
//! [rig.modbus]
//! simulate = "tcp"            # serve [rig.simulated] on loopback TCP ("rtu": PTY pairs); omit on a real rig
//! timeout_ms = 200            # deadline of every Modbus call
//! retries = 2                 # extra attempts of idempotent calls
//! max_lost_polls = 5          # failed polls in a row that end the test
//! merge_window_ms = 10        # meter and counter on separate links: how long a batch waits to be put in time order
//!
//! [rig.modbus.supply]         # the VFD feeding the machine under test
//! profile = "devices/invertek-optidrive-e3.toml"
//! unit_id = 1
//! voltage_register = "motor_rated_voltage"   # where the output line voltage is set
//!
//! [rig.modbus.dynamometer]    # the VFD driving the load machine
//! profile = "devices/invertek-optidrive-e3.toml"
//! unit_id = 2
//! pole_pairs = 2              # of the load machine: speed = 2π f / pole_pairs
//! coast_value = 8             # optional: the control word's coast stop (lets the shaft go; the no-load test needs it)
//!
//! [rig.modbus.meter]          # line voltage, line current, input power
//! profile = "devices/eastron-sdm630.toml"
//! unit_id = 3
//! channels = { line_voltage = "line12_voltage", line_current = "average_line_current", input_power = "total_power" }
//!
//! [rig.modbus.encoder]        # the shaft encoder's counter
//! profile = "devices/sim-daq.toml"
//! unit_id = 4
//! encoder_lines = 4096
//! channels = { encoder_count = "encoder_count" }   # optional: winding_temperature = "winding_temperature"
//!
//! [rig.modbus.dc_source]      # optional: the standard tests' DC source (winding resistance)
//! profile = "devices/riden-rd6006.toml"   # a DC supply whose [power_stage] has a current limit
//! unit_id = 5
//! compliance_V = 30           # its voltage set point in constant current; default: the profile's max_setpoint
//! channels = { dc_voltage = "voltage_out", dc_current = "current_out" }
//! ```
//!
//! On a real rig each device section also says where the device is
//! (`transport = "tcp"` with `address`, or `"rtu"` with `path`), as in the
//! DC rig's `[rig.modbus.power_stage]`. A meter and a counter on separate
//! links are read by separate pollers whose batches are merged in time
//! order (`motorbench_drivers::MergedSensors`, as the DC rig's CAN
//! signals are), each batch held `merge_window_ms` (default 10 ms, at
//! most 1000) for the slower link.

use std::collections::BTreeMap;
use std::path::Path;
use std::time::Duration;

use motorbench_drivers::modbus::{Access, CallPolicy};

use crate::bounds;
use crate::config::{
    call_policy, merge_window, simulated_transport, ModbusDeviceLink, RawLink, SimulatedTransport,
};

/// The `modbus` backend of a sweep, validated.
#[derive(Debug, Clone, PartialEq)]
pub struct ImModbusRig {
    /// Serve the simulated rig behind the links.
    pub simulate: Option<SimulatedTransport>,
    /// Deadline and retries of every call.
    pub policy: CallPolicy,
    /// Failed polls in a row that end the test.
    pub max_lost_polls: u32,
    /// How long the merged sensor stream holds each batch to put the meter
    /// and the counter in time order (when they are on separate links).
    pub merge_window: Duration,
    /// The supply VFD.
    pub supply: ModbusDeviceLink,
    /// The supply's register that sets its output line voltage, V.
    pub supply_voltage_register: String,
    /// The dynamometer's VFD.
    pub dynamometer: ModbusDeviceLink,
    /// Pole pairs of the load machine (speed set point to frequency).
    pub dyno_pole_pairs: u32,
    /// The value of the dynamometer's enable (control) register that
    /// coasts it (lets the shaft turn freely), where given.
    pub dyno_coast_value: Option<u16>,
    /// The power meter.
    pub meter: ModbusDeviceLink,
    /// `(quantity, register)` read from the meter.
    pub meter_channels: Vec<(String, String)>,
    /// The encoder counter.
    pub encoder: ModbusDeviceLink,
    /// `(quantity, register)` read from the encoder counter.
    pub encoder_channels: Vec<(String, String)>,
    /// Encoder lines per revolution (4 counts per line).
    pub encoder_lines: u32,
    /// The DC source of the standard tests' winding-resistance reading,
    /// when the rig has one.
    pub dc_source: Option<ImDcSourceLink>,
}

/// `[rig.modbus.dc_source]`: a DC supply driven in constant current.
#[derive(Debug, Clone, PartialEq)]
pub struct ImDcSourceLink {
    /// The supply (its profile's `[power_stage]` has a current limit).
    pub device: ModbusDeviceLink,
    /// Its voltage set point while it drives a current, V.
    pub compliance_voltage: f64,
    /// `(quantity, register)` read back: `dc_voltage`, `dc_current`.
    pub channels: Vec<(String, String)>,
}

/// Quantities the sweep needs, and the device that must provide each.
const REQUIRED: [(&str, &str); 4] = [
    ("line_voltage", "meter"),
    ("line_current", "meter"),
    ("input_power", "meter"),
    ("encoder_count", "encoder"),
];

type Bad = (String, String);

fn take<T: serde::de::DeserializeOwned>(
    table: &mut toml::Table,
    section: &str,
    key: &str,
) -> Result<Option<T>, Bad> {
    table
        .remove(key)
        .map(|v| {
            v.try_into()
                .map_err(|e: toml::de::Error| (format!("{section}.{key}"), e.message().to_string()))
        })
        .transpose()
}

/// The count `key` of `section`, taken out of `table`: required, and zero
/// refused with the reason `if_zero`.
fn take_count(
    table: &mut toml::Table,
    section: &str,
    key: &str,
    if_zero: &str,
) -> Result<u32, Bad> {
    let n: u32 =
        take(table, section, key)?.ok_or_else(|| (format!("{section}.{key}"), "missing".into()))?;
    if n == 0 {
        return Err((format!("{section}.{key}"), if_zero.into()));
    }
    Ok(n)
}

fn section(rig: &mut toml::Table, name: &str) -> Result<toml::Table, Bad> {
    let key = format!("rig.modbus.{name}");
    match rig.remove(name) {
        Some(toml::Value::Table(t)) => Ok(t),
        Some(_) => Err((key, "must be a table".into())),
        None => Err((key, "missing".into())),
    }
}

fn link(t: toml::Table, key: &str, dir: &Path, simulated: bool) -> Result<ModbusDeviceLink, Bad> {
    let raw: RawLink = toml::Value::Table(t)
        .try_into()
        .map_err(|e: toml::de::Error| (key.to_string(), e.message().to_string()))?;
    raw.validate(key, dir, simulated)
}

fn channel_map(t: &mut toml::Table, key: &str) -> Result<BTreeMap<String, String>, Bad> {
    take(t, key, "channels")?.ok_or_else(|| (format!("{key}.channels"), "missing".into()))
}

fn channels(
    map: BTreeMap<String, String>,
    key: &str,
    device: &ModbusDeviceLink,
) -> Result<Vec<(String, String)>, Bad> {
    let mut out = Vec::new();
    for (quantity, register) in map {
        let k = format!("{key}.channels.{quantity}");
        match device.profile.register(&register) {
            None => {
                return Err((
                    k,
                    format!("{} has no register `{register}`", device.profile_path),
                ))
            }
            Some(r) if r.access == Access::Write => {
                return Err((k, format!("register `{register}` is write-only")))
            }
            Some(_) => out.push((quantity, register)),
        }
    }
    Ok(out)
}

/// `Ok` when `channels`, the validated channels of the device at `key`,
/// read the quantity `q`; else the error on `{key}.channels` naming it,
/// with `why` (what needs it).
fn require_channel(
    channels: &[(String, String)],
    key: &str,
    q: &str,
    why: &str,
) -> Result<(), Bad> {
    if channels.iter().any(|(c, _)| c == q) {
        Ok(())
    } else {
        Err((format!("{key}.channels"), format!("missing `{q}`: {why}")))
    }
}

/// `[rig.modbus.dc_source]`, validated.
fn dc_source(mut t: toml::Table, dir: &Path, simulated: bool) -> Result<ImDcSourceLink, Bad> {
    let key = "rig.modbus.dc_source";
    let compliance: Option<f64> = take(&mut t, key, "compliance_V")?;
    let map = channel_map(&mut t, key)?;
    let device = link(t, key, dir, simulated)?;
    let Some(stage) = device.profile.power_stage.as_ref() else {
        return Err((
            format!("{key}.profile"),
            format!(
                "{} has no [power_stage] section: it cannot drive a current",
                device.profile_path
            ),
        ));
    };
    if stage.current_limit.is_none() || stage.enable.is_none() {
        return Err((
            format!("{key}.profile"),
            format!(
                "{}'s [power_stage] needs a current_limit and an enable register: the DC \
                 source drives a current and disconnects",
                device.profile_path
            ),
        ));
    }
    let compliance_voltage = compliance.unwrap_or(stage.max_setpoint);
    if !(compliance_voltage.is_finite()
        && compliance_voltage > 0.0
        && compliance_voltage <= stage.max_setpoint)
    {
        return Err((
            format!("{key}.compliance_V"),
            format!(
                "{compliance_voltage} must be in (0, {}] V (the profile's max_setpoint)",
                stage.max_setpoint
            ),
        ));
    }
    let channels = channels(map, key, &device)?;
    for q in ["dc_voltage", "dc_current"] {
        require_channel(
            &channels,
            key,
            q,
            "the winding-resistance test reads DC voltage and current",
        )?;
    }
    Ok(ImDcSourceLink {
        device,
        compliance_voltage,
        channels,
    })
}

impl ImModbusRig {
    /// Validate the `[rig.modbus]` table; `dir` resolves relative profile
    /// paths; `simulated_present`: the file has `[rig.simulated]`. Errors
    /// are `(key, reason)`.
    pub fn parse(
        mut rig: toml::Table,
        dir: &Path,
        simulated_present: bool,
    ) -> Result<ImModbusRig, Bad> {
        let top = "rig.modbus";
        let simulate = simulated_transport(
            take::<String>(&mut rig, top, "simulate")?.as_deref(),
            simulated_present,
        )?;
        let policy = call_policy(
            take(&mut rig, top, "timeout_ms")?.unwrap_or(200),
            take(&mut rig, top, "retries")?.unwrap_or(2),
        )?;
        let max_lost_polls: u32 = take(&mut rig, top, "max_lost_polls")?.unwrap_or(5);
        let max_lost_polls = bounds::at_most(max_lost_polls, bounds::MAX_LOST_POLLS)
            .map_err(|why| (format!("{top}.max_lost_polls"), why.to_string()))?;
        let merge_window = merge_window(
            take(&mut rig, top, "merge_window_ms")?
                .unwrap_or(motorbench_drivers::DEFAULT_REORDER.as_millis() as u64),
        )?;
        let sim = simulate.is_some();

        let key = "rig.modbus.supply";
        let mut t = section(&mut rig, "supply")?;
        let voltage_register: String = take(&mut t, key, "voltage_register")?
            .ok_or_else(|| (format!("{key}.voltage_register"), "missing".into()))?;
        let supply = link(t, key, dir, sim)?;
        match supply.profile.register(&voltage_register) {
            Some(r) if r.access != Access::Read => {}
            Some(_) => {
                return Err((
                    format!("{key}.voltage_register"),
                    format!("register `{voltage_register}` is read-only"),
                ))
            }
            None => {
                return Err((
                    format!("{key}.voltage_register"),
                    format!(
                        "{} has no register `{voltage_register}`",
                        supply.profile_path
                    ),
                ))
            }
        }

        let key = "rig.modbus.dynamometer";
        let mut t = section(&mut rig, "dynamometer")?;
        let dyno_pole_pairs = take_count(&mut t, key, "pole_pairs", "must be ≥ 1")?;
        let dyno_coast_value: Option<u16> = take(&mut t, key, "coast_value")?;
        let dynamometer = link(t, key, dir, sim)?;
        for (k, d) in [
            ("rig.modbus.supply.profile", &supply),
            ("rig.modbus.dynamometer.profile", &dynamometer),
        ] {
            if d.profile.power_stage.is_none() {
                return Err((
                    k.into(),
                    format!(
                        "{} has no [power_stage] section: it cannot drive the rig",
                        d.profile_path
                    ),
                ));
            }
        }

        let key = "rig.modbus.meter";
        let mut t = section(&mut rig, "meter")?;
        let map = channel_map(&mut t, key)?;
        let meter = link(t, key, dir, sim)?;
        let meter_channels = channels(map, key, &meter)?;

        let key = "rig.modbus.encoder";
        let mut t = section(&mut rig, "encoder")?;
        let encoder_lines = take_count(&mut t, key, "encoder_lines", "must be > 0")?;
        let map = channel_map(&mut t, key)?;
        let encoder = link(t, key, dir, sim)?;
        let encoder_channels = channels(map, key, &encoder)?;

        let dc_source = match rig.contains_key("dc_source") {
            true => Some(dc_source(section(&mut rig, "dc_source")?, dir, sim)?),
            false => None,
        };

        if let Some(extra) = rig.keys().next() {
            return Err((
                format!("rig.modbus.{extra}"),
                "unknown key: want simulate, timeout_ms, retries, max_lost_polls, \
                 merge_window_ms, supply, dynamometer, meter, encoder, dc_source"
                    .into(),
            ));
        }
        for (q, device) in REQUIRED {
            let list = if device == "meter" {
                &meter_channels
            } else {
                &encoder_channels
            };
            require_channel(
                list,
                &format!("rig.modbus.{device}"),
                q,
                "a slip sweep needs line voltage, current, input power and the encoder count",
            )?;
        }
        Ok(ImModbusRig {
            simulate,
            policy,
            max_lost_polls: max_lost_polls.max(1),
            merge_window,
            supply,
            supply_voltage_register: voltage_register,
            dynamometer,
            dyno_pole_pairs,
            dyno_coast_value,
            meter,
            meter_channels,
            encoder,
            encoder_channels,
            encoder_lines,
            dc_source,
        })
    }

    /// For a person: the devices and where they are.
    pub fn describe(&self) -> String {
        let how = match self.simulate {
            Some(SimulatedTransport::Tcp) => "the simulated rig served over Modbus TCP: ",
            Some(SimulatedTransport::Rtu) => "the simulated rig served over Modbus RTU: ",
            None => "Modbus: ",
        };
        let dc = match &self.dc_source {
            Some(d) => format!(", DC source {}", d.device.profile.name),
            None => String::new(),
        };
        format!(
            "{how}supply {}, dynamometer {}, meter {}, encoder {}{dc}",
            self.supply.profile.name,
            self.dynamometer.profile.name,
            self.meter.profile.name,
            self.encoder.profile.name
        )
    }
}
