//! One simulated Modbus device put on the wire the way the configuration
//! asks: Modbus TCP on a loopback port the OS picks, or Modbus RTU on a
//! new pseudo-terminal pair. Both machines' served rigs
//! (`machine::dc::ServedRig`, `machine::im::ServedImRig`) serve each of
//! their devices through it, with the device's protocol faults
//! (`[[fault]]`, see [`super::fault`]) when it has any: its replies
//! interfered with, its RTU line relayed through the line faults, its
//! server stopped at a `disconnect`.

use std::sync::Arc;

use motorbench_drivers::modbus::server::{serve_rtu, serve_tcp, BankService};
use motorbench_drivers::serial::port::{pty_pair, SerialSettings, SerialStream};
use tokio::task::JoinHandle;

use super::fault::{FaultyLine, ProtocolFaults};
use super::{ServeError, ServedLink};
use crate::config::SimulatedTransport;

/// Aborts its task when dropped.
struct AbortOnDrop(JoinHandle<()>);

impl Drop for AbortOnDrop {
    fn drop(&mut self) {
        self.0.abort();
    }
}

/// Serve `service` over `transport`, with `faults` (the device's protocol
/// faults) when given: where a client finds it and the server's task.
/// Over RTU the line runs at `baud` and the pseudo terminal's device end
/// is pushed to `pty_ends`, to be held open as long as the device is
/// served.
pub fn serve_device(
    transport: SimulatedTransport,
    service: BankService,
    baud: u32,
    pty_ends: &mut Vec<SerialStream>,
    faults: Option<ProtocolFaults>,
) -> Result<(ServedLink, JoinHandle<()>), ServeError> {
    let io = |e: std::io::Error| ServeError::Io(e.to_string());
    let pty = |e: motorbench_drivers::DriverError| ServeError::Io(e.to_string());
    let service = match &faults {
        Some(f) => service.with_interference(Arc::new(f.clone())),
        None => service,
    };
    let (link, task) = match transport {
        SimulatedTransport::Tcp => {
            let std_listener = std::net::TcpListener::bind("127.0.0.1:0").map_err(io)?;
            std_listener.set_nonblocking(true).map_err(io)?;
            let listener = tokio::net::TcpListener::from_std(std_listener).map_err(io)?;
            let (addr, task) = serve_tcp(listener, service).map_err(io)?;
            (ServedLink::Tcp(addr), task)
        }
        SimulatedTransport::Rtu => {
            let device = pty_pair().map_err(pty)?;
            let task = serve_rtu(device.host, service);
            match faults.as_ref().filter(|f| FaultyLine::needed(f)) {
                None => {
                    let settings = SerialSettings::new_8n1(&device.device_path, baud);
                    pty_ends.push(device.device_end);
                    (ServedLink::Rtu(settings), task)
                }
                Some(f) => {
                    // The bench opens a second pair, relayed to the
                    // device's line through the line faults.
                    let bench = pty_pair().map_err(pty)?;
                    let settings = SerialSettings::new_8n1(&bench.device_path, baud);
                    pty_ends.push(bench.device_end);
                    let line = FaultyLine::new(f.clone());
                    let (bench_end, device_end) = (bench.host, device.device_end);
                    let task = tokio::spawn(async move {
                        let _server = AbortOnDrop(task);
                        line.relay(bench_end, device_end).await;
                    });
                    (ServedLink::Rtu(settings), task)
                }
            }
        }
    };
    // A disconnect stops the server for good: its TCP connections close
    // and new ones are refused; an RTU device's pseudo-terminal goes away,
    // as a USB adapter pulled out.
    let task = match faults.as_ref().and_then(ProtocolFaults::disconnect_at) {
        None => task,
        Some(at_s) => tokio::spawn(async move {
            let _server = AbortOnDrop(task);
            tokio::time::sleep(std::time::Duration::from_secs_f64(at_s)).await;
        }),
    };
    Ok((link, task))
}
