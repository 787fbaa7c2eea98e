//! What every rig shares, whatever the machine: the Modbus client of a
//! device's link (or of the simulated device served in its place), which
//! devices share one bus, the one-shot read of polled sensors (`probe`),
//! the serving of a simulated device behind a profile's registers, and
//! the errors of setting a rig up. The machines' rig builders
//! (`machine::dc::rig`, `machine::im::rig`) are built from these.

use std::future::Future;
use std::pin::pin;
use std::task::{Context, Poll, Waker};

use motorbench_drivers::modbus::server::{ExceptionCode, RegisterBank, WriteSpan};
use motorbench_drivers::modbus::{
    spawn_bus_as, BusHandle, CallPolicy, DeviceProfile, ModbusClient, PolledChannel, Register,
};
use motorbench_drivers::serial::port::SerialSettings;
use motorbench_drivers::{ChannelInfo, DriverError, LinkHealth};

use crate::config::{LinkSpec, ModbusDeviceLink};

pub mod fault;
mod modbus_server;
mod pacing;
mod setpoint;
mod wall_clock;

pub use modbus_server::serve_device;
pub(crate) use pacing::Pacing;
pub(crate) use setpoint::{check_frequency, check_setpoint};
pub(crate) use wall_clock::WallClock;

/// What `probe` needs to read every channel once.
pub struct ModbusProbe {
    pub(crate) bus: BusHandle,
    pub(crate) channels: Vec<PolledChannel>,
}

impl ModbusProbe {
    /// Read every sensor channel once: `(channel, value or error)`.
    pub async fn read_each(&self) -> Vec<(ChannelInfo, Result<f64, DriverError>)> {
        let mut out = Vec::new();
        for c in &self.channels {
            let r = self
                .bus
                .read(
                    c.unit,
                    vec![c.register.clone()],
                    motorbench_drivers::modbus::Priority::Routine,
                )
                .await
                .map(|r| r.values[0]);
            out.push((c.info.clone(), r));
        }
        out
    }
}

/// Why a rig could not be built.
#[derive(Debug, thiserror::Error)]
pub enum RigError {
    /// The simulated motor is not valid.
    #[error("simulated rig: {0}")]
    Simulated(String),
    /// Serving the simulated rig failed.
    #[error(transparent)]
    Serve(#[from] ServeError),
    /// A device could not be reached while setting up.
    #[error(transparent)]
    Driver(#[from] DriverError),
    /// A `[[fault]]` entry does not fit the rig.
    #[error("{0}")]
    Fault(String),
}

/// The Modbus client of a device on `link`, or of the simulated device
/// served in its place.
fn client(
    name: &str,
    link: &LinkSpec,
    served: Option<&ServedLink>,
    unit: u8,
    policy: CallPolicy,
) -> ModbusClient {
    match (link, served) {
        (_, Some(ServedLink::Tcp(addr))) | (LinkSpec::Tcp(addr), None) => {
            ModbusClient::tcp(name, *addr, unit, policy)
        }
        (_, Some(ServedLink::Rtu(s) | ServedLink::Stream(s))) | (LinkSpec::Rtu(s), None) => {
            ModbusClient::rtu(name, s.clone(), unit, policy)
        }
        (LinkSpec::Simulated, None) => unreachable!("a simulated link is always served"),
    }
}

/// Whether two devices are on one bus (one TCP gateway, one serial line).
pub(crate) fn same_link(a: &ModbusDeviceLink, b: &ModbusDeviceLink) -> bool {
    match (&a.link, &b.link) {
        (LinkSpec::Tcp(x), LinkSpec::Tcp(y)) => x == y,
        (LinkSpec::Rtu(x), LinkSpec::Rtu(y)) => x.path == y.path,
        _ => false,
    }
}

/// A rig's Modbus buses by link: devices on one line (or one gateway
/// address) share the one task that owns it, unless the rig is served
/// (every simulated device then has a link of its own).
pub(crate) struct Buses<'a> {
    policy: CallPolicy,
    served: bool,
    open: Vec<(&'a ModbusDeviceLink, BusHandle)>,
}

impl<'a> Buses<'a> {
    /// No bus open yet; `served` when the rig's devices are simulated
    /// behind links of their own.
    pub(crate) fn new(policy: CallPolicy, served: bool) -> Buses<'a> {
        Buses {
            policy,
            served,
            open: Vec::new(),
        }
    }

    /// The bus of `device` (named `name` in errors), on `served` in place
    /// of its configured link when the rig is served: one already open on
    /// the same link, else a new one.
    pub(crate) fn bus(
        &mut self,
        name: &str,
        device: &'a ModbusDeviceLink,
        served: Option<&ServedLink>,
    ) -> BusHandle {
        if !self.served {
            if let Some((_, b)) = self.open.iter().find(|(d, _)| same_link(d, device)) {
                return b.clone();
            }
        }
        let bus = spawn_bus_as(
            client(name, &device.link, served, device.unit_id, self.policy),
            &link_name(name, &device.link),
        );
        self.open.push((device, bus.clone()));
        bus
    }

    /// The health of every bus opened, one per link.
    pub(crate) fn health(&self) -> Vec<LinkHealth> {
        self.open.iter().map(|(_, b)| b.health().clone()).collect()
    }
}

/// The name a bus is known by in the metrics, the same from test to
/// test: its configured address (`tcp:HOST:PORT`, `rtu:PATH`), or, for a
/// simulated device served on a port of the day, `simulated:` and the
/// device's role.
pub(crate) fn link_name(role: &str, link: &LinkSpec) -> String {
    match link {
        LinkSpec::Tcp(addr) => format!("tcp:{addr}"),
        LinkSpec::Rtu(s) => format!("rtu:{}", s.path),
        LinkSpec::Simulated => format!("simulated:{role}"),
    }
}

/// Why the simulated rig could not be served.
#[derive(Debug, thiserror::Error)]
pub enum ServeError {
    /// The profile lacks a register the simulation needs.
    #[error("{profile}: the simulated rig needs a register named `{register}`")]
    MissingRegister {
        /// Profile name.
        profile: String,
        /// Register name.
        register: String,
    },
    /// The simulated motor is not valid.
    #[error("simulated motor: {0}")]
    Motor(String),
    /// A socket or pseudo-terminal could not be opened.
    #[error("serving the simulated rig: {0}")]
    Io(String),
}

/// Run a future that never waits (the simulated stage's methods only lock
/// a mutex) to completion, here and now.
pub(crate) fn ready_now<F: Future>(f: F) -> F::Output {
    let mut f = pin!(f);
    match f.as_mut().poll(&mut Context::from_waker(Waker::noop())) {
        Poll::Ready(v) => v,
        Poll::Pending => unreachable!("the simulated rig's calls never wait"),
    }
}

/// The register `name` of a profile, or why the simulation cannot use it.
pub(crate) fn register(profile: &DeviceProfile, name: &str) -> Result<Register, ServeError> {
    profile
        .register(name)
        .cloned()
        .ok_or_else(|| ServeError::MissingRegister {
            profile: profile.name.clone(),
            register: name.to_string(),
        })
}

/// Whether a write touches the register `r`.
pub(crate) fn touches(span: &WriteSpan, r: &Register) -> bool {
    span.kind == r.kind
        && span.address < r.address + r.data_type.width()
        && r.address < span.address + span.count
}

/// The output state a write asks of a served stage whose enable register
/// is `(register, enable value, disable value)`: `None` when the write
/// does not touch it, an illegal-data-value exception for another value.
pub(crate) fn enable_written(
    bank: &RegisterBank,
    span: &WriteSpan,
    (r, on, off): &(Register, u16, u16),
) -> Result<Option<bool>, ExceptionCode> {
    if !touches(span, r) {
        return Ok(None);
    }
    match bank.get(r) as u16 {
        raw if raw == *on => Ok(Some(true)),
        raw if raw == *off => Ok(Some(false)),
        _ => Err(ExceptionCode::IllegalDataValue),
    }
}

/// The optional readback registers of a served DC supply, from its
/// profile: `voltage_out` and `current_out` show the output the plant
/// measures.
#[derive(Debug, Clone)]
pub(crate) struct SupplyReadback {
    voltage_out: Option<Register>,
    current_out: Option<Register>,
}

impl SupplyReadback {
    /// The readback registers `profile` has.
    pub(crate) fn of(profile: &DeviceProfile) -> SupplyReadback {
        SupplyReadback {
            voltage_out: profile.register("voltage_out").cloned(),
            current_out: profile.register("current_out").cloned(),
        }
    }

    /// Show the output voltage `v` and current `i` (a supply reads back
    /// no negative output).
    pub(crate) fn show(&self, bank: &mut RegisterBank, v: f64, i: f64) {
        if let Some(r) = &self.voltage_out {
            bank.set(r, v.max(0.0));
        }
        if let Some(r) = &self.current_out {
            bank.set(r, i.max(0.0));
        }
    }
}

/// Where a served device can be reached.
#[derive(Debug, Clone, PartialEq)]
pub enum ServedLink {
    /// Modbus TCP on this loopback address.
    Tcp(std::net::SocketAddr),
    /// Modbus RTU: open this pseudo-terminal path.
    Rtu(SerialSettings),
    /// A streaming DAQ: open this pseudo-terminal path.
    Stream(SerialSettings),
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_bus_is_named_by_its_configured_address_not_a_port_of_the_day() {
        let tcp = LinkSpec::Tcp("10.0.0.5:502".parse().unwrap());
        assert_eq!(link_name("modbus-supply", &tcp), "tcp:10.0.0.5:502");
        let rtu = LinkSpec::Rtu(SerialSettings::new_8n1("/dev/ttyUSB0", 19200));
        assert_eq!(link_name("modbus-meter", &rtu), "rtu:/dev/ttyUSB0");
        assert_eq!(
            link_name("modbus-stage", &LinkSpec::Simulated),
            "simulated:modbus-stage"
        );
    }
}
