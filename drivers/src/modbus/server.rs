//! A Modbus server over a register bank, for simulated devices served
//! behind the real protocol (TCP or RTU) and for tests.
//!
//! A [`RegisterBank`] holds the four tables; only addresses a device
//! defines exist (others answer `IllegalDataAddress`, as real devices do).
//! A [`SimulatedDevice`] hooks in before every read (to refresh measured
//! values) and after every write (to act on a command, or refuse it).

use std::collections::BTreeMap;
use std::future;
use std::io;
use std::net::SocketAddr;
use std::sync::{Arc, Mutex, MutexGuard};

use tokio::net::TcpListener;
use tokio::task::JoinHandle;
pub use tokio_modbus::prelude::ExceptionCode;
use tokio_modbus::prelude::{Request, Response, SlaveRequest};
use tokio_serial::SerialStream;

use super::profile::DeviceProfile;
use super::register_map::{Register, RegisterKind};

/// The four Modbus tables of a device; absent addresses do not exist.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct RegisterBank {
    /// Holding registers.
    pub holding: BTreeMap<u16, u16>,
    /// Input registers.
    pub input: BTreeMap<u16, u16>,
    /// Coils.
    pub coils: BTreeMap<u16, bool>,
    /// Discrete inputs.
    pub discrete: BTreeMap<u16, bool>,
}

impl RegisterBank {
    /// A bank with every register of `profile` present and zero.
    pub fn for_profile(profile: &DeviceProfile) -> RegisterBank {
        let mut bank = RegisterBank::default();
        for r in profile.registers.values() {
            for a in r.address..r.address + r.data_type.width() {
                match r.kind {
                    RegisterKind::Holding => bank.holding.insert(a, 0).map(|_| ()),
                    RegisterKind::Input => bank.input.insert(a, 0).map(|_| ()),
                    RegisterKind::Coil => bank.coils.insert(a, false).map(|_| ()),
                    RegisterKind::DiscreteInput => bank.discrete.insert(a, false).map(|_| ()),
                };
            }
        }
        bank
    }

    /// Store `value` (SI) in `register` (encoded per its map; out-of-range
    /// values saturate at the raw range).
    pub fn set(&mut self, register: &Register, value: f64) {
        let words = register.encode(value).unwrap_or_else(|e| {
            let clamped = (e.raw.clamp(e.min, e.max)) * register.scale + register.offset;
            register.encode(clamped).expect("a clamped value fits")
        });
        for (k, w) in words.into_iter().enumerate() {
            let a = register.address + k as u16;
            match register.kind {
                RegisterKind::Holding => {
                    self.holding.insert(a, w);
                }
                RegisterKind::Input => {
                    self.input.insert(a, w);
                }
                RegisterKind::Coil => {
                    self.coils.insert(a, w != 0);
                }
                RegisterKind::DiscreteInput => {
                    self.discrete.insert(a, w != 0);
                }
            }
        }
    }

    /// The value (SI) `register` holds; NaN where an address is missing.
    pub fn get(&self, register: &Register) -> f64 {
        let words: Option<Vec<u16>> = (0..register.data_type.width())
            .map(|k| {
                let a = register.address + k;
                match register.kind {
                    RegisterKind::Holding => self.holding.get(&a).copied(),
                    RegisterKind::Input => self.input.get(&a).copied(),
                    RegisterKind::Coil => self.coils.get(&a).map(|&b| u16::from(b)),
                    RegisterKind::DiscreteInput => self.discrete.get(&a).map(|&b| u16::from(b)),
                }
            })
            .collect();
        words.map_or(f64::NAN, |w| register.decode(&w))
    }

    fn words(map: &BTreeMap<u16, u16>, addr: u16, n: u16) -> Result<Vec<u16>, ExceptionCode> {
        (0..n)
            .map(|k| {
                addr.checked_add(k)
                    .and_then(|a| map.get(&a).copied())
                    .ok_or(ExceptionCode::IllegalDataAddress)
            })
            .collect()
    }

    fn bits(map: &BTreeMap<u16, bool>, addr: u16, n: u16) -> Result<Vec<bool>, ExceptionCode> {
        (0..n)
            .map(|k| {
                addr.checked_add(k)
                    .and_then(|a| map.get(&a).copied())
                    .ok_or(ExceptionCode::IllegalDataAddress)
            })
            .collect()
    }

    fn write_words(
        map: &mut BTreeMap<u16, u16>,
        addr: u16,
        w: &[u16],
    ) -> Result<(), ExceptionCode> {
        for k in 0..w.len() as u16 {
            if !addr.checked_add(k).is_some_and(|a| map.contains_key(&a)) {
                return Err(ExceptionCode::IllegalDataAddress);
            }
        }
        for (k, v) in w.iter().enumerate() {
            map.insert(addr + k as u16, *v);
        }
        Ok(())
    }
}

/// What a write touched: table, first address, count.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct WriteSpan {
    /// Table written.
    pub kind: RegisterKind,
    /// First address.
    pub address: u16,
    /// Registers or coils written.
    pub count: u16,
}

/// The behaviour of a simulated device behind a [`RegisterBank`].
pub trait SimulatedDevice: Send + Sync {
    /// Called before every read: refresh the measured values in `bank`.
    fn before_read(&self, _bank: &mut RegisterBank) {}

    /// Called after a write landed in `bank` (the previous contents are in
    /// `before`): act on it, or refuse it with an exception (the bank is
    /// then restored).
    fn after_write(
        &self,
        _bank: &mut RegisterBank,
        _before: &RegisterBank,
        _span: WriteSpan,
    ) -> Result<(), ExceptionCode> {
        Ok(())
    }
}

/// What a served device does in place of its answer (fault injection:
/// see [`Interference`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Interfere {
    /// No answer at all (the client times out).
    Silence,
    /// This exception code in place of the answer.
    Exception(u8),
}

/// Asked before every request addressed to the device: `Some` replaces
/// the answer (the request is not acted on). For simulated faults.
pub trait Interference: Send + Sync {
    /// What to do in place of answering, if anything.
    fn interfere(&self) -> Option<Interfere>;
}

/// A device that only stores what is written.
#[derive(Debug, Clone, Copy, Default)]
pub struct PassiveDevice;

impl SimulatedDevice for PassiveDevice {}

/// A bank shared between the server and whoever inspects it.
pub type SharedBank = Arc<Mutex<RegisterBank>>;

/// Lock a shared bank (a poisoned lock still gives the data).
pub fn lock_bank(bank: &SharedBank) -> MutexGuard<'_, RegisterBank> {
    bank.lock().unwrap_or_else(|e| e.into_inner())
}

/// The tokio-modbus service answering from a bank.
#[derive(Clone)]
pub struct BankService {
    unit: u8,
    bank: SharedBank,
    device: Arc<dyn SimulatedDevice>,
    interference: Option<Arc<dyn Interference>>,
}

impl BankService {
    /// Answer requests to `unit` (others are ignored, as on a shared line)
    /// from `bank`, with `device`'s behaviour.
    pub fn new(unit: u8, bank: SharedBank, device: Arc<dyn SimulatedDevice>) -> BankService {
        BankService {
            unit,
            bank,
            device,
            interference: None,
        }
    }

    /// The same service, asking `interference` before every answer.
    pub fn with_interference(mut self, interference: Arc<dyn Interference>) -> BankService {
        self.interference = Some(interference);
        self
    }

    fn handle(&self, req: Request<'static>) -> Result<Response, ExceptionCode> {
        let mut bank = lock_bank(&self.bank);
        let before = bank.clone();
        let span = |kind, address, count| WriteSpan {
            kind,
            address,
            count,
        };
        let (resp, written) = match req {
            Request::ReadHoldingRegisters(a, n) => {
                self.device.before_read(&mut bank);
                (
                    Response::ReadHoldingRegisters(RegisterBank::words(&bank.holding, a, n)?),
                    None,
                )
            }
            Request::ReadInputRegisters(a, n) => {
                self.device.before_read(&mut bank);
                (
                    Response::ReadInputRegisters(RegisterBank::words(&bank.input, a, n)?),
                    None,
                )
            }
            Request::ReadCoils(a, n) => {
                self.device.before_read(&mut bank);
                (
                    Response::ReadCoils(RegisterBank::bits(&bank.coils, a, n)?),
                    None,
                )
            }
            Request::ReadDiscreteInputs(a, n) => {
                self.device.before_read(&mut bank);
                (
                    Response::ReadDiscreteInputs(RegisterBank::bits(&bank.discrete, a, n)?),
                    None,
                )
            }
            Request::WriteSingleRegister(a, w) => {
                RegisterBank::write_words(&mut bank.holding, a, &[w])?;
                (
                    Response::WriteSingleRegister(a, w),
                    Some(span(RegisterKind::Holding, a, 1)),
                )
            }
            Request::WriteMultipleRegisters(a, ws) => {
                RegisterBank::write_words(&mut bank.holding, a, &ws)?;
                let n = ws.len() as u16;
                (
                    Response::WriteMultipleRegisters(a, n),
                    Some(span(RegisterKind::Holding, a, n)),
                )
            }
            Request::WriteSingleCoil(a, on) => {
                match bank.coils.get_mut(&a) {
                    Some(c) => *c = on,
                    None => return Err(ExceptionCode::IllegalDataAddress),
                }
                (
                    Response::WriteSingleCoil(a, on),
                    Some(span(RegisterKind::Coil, a, 1)),
                )
            }
            _ => return Err(ExceptionCode::IllegalFunction),
        };
        if let Some(span) = written {
            if let Err(e) = self.device.after_write(&mut bank, &before, span) {
                *bank = before;
                return Err(e);
            }
        }
        Ok(resp)
    }
}

impl tokio_modbus::server::Service for BankService {
    type Request = SlaveRequest<'static>;
    type Response = Option<Response>;
    type Exception = ExceptionCode;
    type Future = future::Ready<Result<Option<Response>, ExceptionCode>>;

    fn call(&self, req: Self::Request) -> Self::Future {
        if req.slave != self.unit {
            // Not addressed to us: silence, as on a shared RS-485 line.
            return future::ready(Ok(None));
        }
        match self.interference.as_ref().and_then(|i| i.interfere()) {
            Some(Interfere::Silence) => future::ready(Ok(None)),
            Some(Interfere::Exception(code)) => future::ready(Err(ExceptionCode::new(code))),
            None => future::ready(self.handle(req.request).map(Some)),
        }
    }
}

/// Serve `service` on `listener` (Modbus TCP), one task per connection.
/// Returns the address it listens on and the server task.
pub fn serve_tcp(
    listener: TcpListener,
    service: BankService,
) -> io::Result<(SocketAddr, JoinHandle<()>)> {
    let addr = listener.local_addr()?;
    let task = tokio::spawn(async move {
        let server = tokio_modbus::server::tcp::Server::new(listener);
        let on_connected = |stream, socket_addr| {
            let service = service.clone();
            async move {
                tokio_modbus::server::tcp::accept_tcp_connection(stream, socket_addr, move |_| {
                    Ok(Some(service.clone()))
                })
            }
        };
        let _ = server.serve(&on_connected, |_err| {}).await;
    });
    Ok((addr, task))
}

/// Serve `service` over a serial stream (Modbus RTU).
pub fn serve_rtu(serial: SerialStream, service: BankService) -> JoinHandle<()> {
    tokio::spawn(async move {
        let server = tokio_modbus::server::rtu::Server::new(serial);
        let _ = server.serve_forever(service).await;
    })
}
