//! One simulated Modbus device put on the wire the way the configuration
//! asks: Modbus TCP on a loopback port the OS picks, or Modbus RTU on a
//! new pseudo-terminal pair. Both machines' served rigs
//! (`machine::dc::ServedRig`, `machine::im::ServedImRig`) serve each of
//! their devices through it.

use motorbench_drivers::modbus::server::{serve_rtu, serve_tcp, BankService};
use motorbench_drivers::serial::port::{pty_pair, SerialSettings, SerialStream};
use tokio::task::JoinHandle;

use super::{ServeError, ServedLink};
use crate::config::SimulatedTransport;

/// Serve `service` over `transport`: where a client finds it and the
/// server's task. Over RTU the line runs at `baud` and the pseudo
/// terminal's device end is pushed to `pty_ends`, to be held open as long
/// as the device is served.
pub fn serve_device(
    transport: SimulatedTransport,
    service: BankService,
    baud: u32,
    pty_ends: &mut Vec<SerialStream>,
) -> Result<(ServedLink, JoinHandle<()>), ServeError> {
    let io = |e: std::io::Error| ServeError::Io(e.to_string());
    match transport {
        SimulatedTransport::Tcp => {
            let std_listener = std::net::TcpListener::bind("127.0.0.1:0").map_err(io)?;
            std_listener.set_nonblocking(true).map_err(io)?;
            let listener = tokio::net::TcpListener::from_std(std_listener).map_err(io)?;
            let (addr, task) = serve_tcp(listener, service).map_err(io)?;
            Ok((ServedLink::Tcp(addr), task))
        }
        SimulatedTransport::Rtu => {
            let pty = pty_pair().map_err(|e| ServeError::Io(e.to_string()))?;
            let task = serve_rtu(pty.host, service);
            let settings = SerialSettings::new_8n1(&pty.device_path, baud);
            pty_ends.push(pty.device_end);
            Ok((ServedLink::Rtu(settings), task))
        }
    }
}
