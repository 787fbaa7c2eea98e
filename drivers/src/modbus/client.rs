//! A Modbus client with a deadline on every call, retries of idempotent
//! calls, reconnection after a link failure, and errors that keep "the
//! device answered with an exception" apart from "the link failed".
//!
//! Error mapping:
//!
//! | what happened | [`DriverError`] | retried? |
//! |---|---|---|
//! | no answer within [`CallPolicy::timeout`] | `Timeout` | yes, if idempotent |
//! | I/O error, connection refused or closed, garbled frame | `Link` | yes, if idempotent |
//! | the device answered with exception code *n* | `Device` | only `ServerDeviceBusy` (0x06), if idempotent |
//!
//! Idempotent (safe to send twice): every read, and writes of absolute
//! values (write single / multiple registers, write single / multiple
//! coils). A set point written twice leaves the same set point: a lost
//! answer to a write that did reach the device costs nothing when the write
//! is repeated. Not idempotent: mask writes, read/write-multiple and custom
//! function codes (their effect may depend on the state they find).
//!
//! After a `Link` or `Timeout` error the connection is dropped and opened
//! afresh on the next attempt: a late answer to an abandoned request must
//! not be taken for the answer to the next one.
//!
//! On an RTU line a frame ends with silence: the Modbus serial-line
//! specification (V1.02, 2.5.1.1) has every frame preceded by at least
//! 3.5 character times of idle line, fixed at 1.75 ms above 19 200 baud
//! ([`rtu_frame_gap`]). Every device on a multi-drop line listens to every
//! frame, and one that hears a reply and the next request with less
//! silence between them takes both for one garbled frame. So an RTU client
//! waits that long after the line last carried a frame (the previous
//! answer, or the attempt that timed out) before it sends.

use std::borrow::Cow;
use std::net::SocketAddr;
use std::time::Duration;

use tokio::io::{AsyncRead, AsyncWrite};
use tokio_modbus::client::{Client, Context};
use tokio_modbus::prelude::{ExceptionCode, Request, Response, Slave};

use crate::serial::port::{open_serial, SerialSettings};
use crate::DriverError;

/// Deadlines and retries of every call.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CallPolicy {
    /// Deadline of one attempt (and of opening the connection).
    pub timeout: Duration,
    /// Extra attempts of an idempotent call after a failed one.
    pub retries: u32,
    /// Pause before each retry.
    pub retry_delay: Duration,
}

impl Default for CallPolicy {
    fn default() -> Self {
        CallPolicy {
            timeout: Duration::from_millis(250),
            retries: 2,
            retry_delay: Duration::from_millis(20),
        }
    }
}

/// Counts kept by a client.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct LinkStats {
    /// Calls made (not attempts).
    pub calls: u64,
    /// Retries made.
    pub retries: u64,
    /// Attempts that timed out.
    pub timeouts: u64,
    /// Attempts that failed on the link.
    pub link_errors: u64,
    /// Exception answers.
    pub exceptions: u64,
    /// Connections opened.
    pub connects: u64,
}

impl From<LinkStats> for crate::LinkCounts {
    fn from(s: LinkStats) -> crate::LinkCounts {
        crate::LinkCounts {
            requests: s.calls,
            timeouts: s.timeouts,
            exceptions: s.exceptions,
            link_errors: s.link_errors,
            retries: s.retries,
            reconnects: s.connects.saturating_sub(1),
            ..crate::LinkCounts::default()
        }
    }
}

/// Whether a request may be sent again after an unknown outcome.
pub fn is_idempotent(req: &Request<'_>) -> bool {
    matches!(
        req,
        Request::ReadCoils(..)
            | Request::ReadDiscreteInputs(..)
            | Request::ReadInputRegisters(..)
            | Request::ReadHoldingRegisters(..)
            | Request::ReadDeviceIdentification(..)
            | Request::WriteSingleCoil(..)
            | Request::WriteMultipleCoils(..)
            | Request::WriteSingleRegister(..)
            | Request::WriteMultipleRegisters(..)
    )
}

/// The silence an RTU frame must be preceded by on a line of `serial`'s
/// framing: 3.5 character times, or the specification's fixed 1.75 ms
/// above 19 200 baud (where 3.5 characters would be too short for UARTs
/// and operating systems to time).
pub fn rtu_frame_gap(serial: &SerialSettings) -> Duration {
    if serial.baud_rate > 19_200 {
        RTU_FRAME_GAP_FAST
    } else {
        Duration::from_secs_f64(
            3.5 * f64::from(serial.bits_per_byte()) / f64::from(serial.baud_rate.max(1)),
        )
    }
}

/// The specification's fixed inter-frame silence above 19 200 baud; also
/// the gap of an attached RTU stream, whose baud rate the client does not
/// know ([`ModbusClient::set_frame_gap`] changes it).
pub const RTU_FRAME_GAP_FAST: Duration = Duration::from_micros(1750);

enum Link {
    Tcp(SocketAddr),
    Rtu(SerialSettings),
    /// A stream handed in by the caller: usable once, never reopened.
    Attached(Option<Context>),
}

/// A Modbus client for one device (one unit id) on one link.
pub struct ModbusClient {
    device: String,
    unit: u8,
    link: Link,
    ctx: Option<Context>,
    policy: CallPolicy,
    stats: LinkStats,
    /// When the latest attempt of a call was sent: after a retry, the
    /// reply's values are from then, not from the first attempt.
    last_sent: Option<tokio::time::Instant>,
    /// RTU: the silence to keep before each request.
    frame_gap: Option<Duration>,
    /// RTU: when the line last carried a frame (an answer's end, or the
    /// deadline of an attempt that got none).
    line_quiet_since: Option<tokio::time::Instant>,
}

impl std::fmt::Debug for ModbusClient {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ModbusClient")
            .field("device", &self.device)
            .field("unit", &self.unit)
            .field("policy", &self.policy)
            .field("stats", &self.stats)
            .finish()
    }
}

impl ModbusClient {
    fn new(device: &str, unit: u8, link: Link, policy: CallPolicy) -> ModbusClient {
        ModbusClient {
            device: device.to_string(),
            unit,
            link,
            ctx: None,
            policy,
            stats: LinkStats::default(),
            last_sent: None,
            frame_gap: None,
            line_quiet_since: None,
        }
    }

    /// Modbus TCP to `addr`, unit `unit` (connects on first use).
    pub fn tcp(device: &str, addr: SocketAddr, unit: u8, policy: CallPolicy) -> ModbusClient {
        ModbusClient::new(device, unit, Link::Tcp(addr), policy)
    }

    /// Modbus RTU on a serial port (opened on first use, reopened after a
    /// link failure).
    pub fn rtu(device: &str, serial: SerialSettings, unit: u8, policy: CallPolicy) -> ModbusClient {
        let gap = rtu_frame_gap(&serial);
        let mut c = ModbusClient::new(device, unit, Link::Rtu(serial), policy);
        c.frame_gap = Some(gap);
        c
    }

    /// Modbus TCP framing (MBAP header) over a stream the caller opened.
    /// After a link failure it cannot be reopened: later calls fail.
    pub fn attach_tcp<T>(device: &str, io: T, unit: u8, policy: CallPolicy) -> ModbusClient
    where
        T: AsyncRead + AsyncWrite + std::fmt::Debug + Unpin + Send + 'static,
    {
        let ctx = tokio_modbus::client::tcp::attach_slave(io, Slave(unit));
        ModbusClient::new(device, unit, Link::Attached(Some(ctx)), policy)
    }

    /// Modbus RTU framing (CRC) over a stream the caller opened (a PTY, a
    /// duplex). After a link failure it cannot be reopened. Frames keep
    /// [`RTU_FRAME_GAP_FAST`] of silence between them; a line at 19 200
    /// baud or slower wants [`Self::set_frame_gap`] with [`rtu_frame_gap`].
    pub fn attach_rtu<T>(device: &str, io: T, unit: u8, policy: CallPolicy) -> ModbusClient
    where
        T: AsyncRead + AsyncWrite + std::fmt::Debug + Unpin + Send + 'static,
    {
        let ctx = tokio_modbus::client::rtu::attach_slave(io, Slave(unit));
        let mut c = ModbusClient::new(device, unit, Link::Attached(Some(ctx)), policy);
        c.frame_gap = Some(RTU_FRAME_GAP_FAST);
        c
    }

    /// Set the silence kept before each request (RTU; `None` sends at
    /// once, as Modbus TCP does).
    pub fn set_frame_gap(&mut self, gap: Option<Duration>) {
        self.frame_gap = gap;
    }

    /// Address later calls to unit `unit` (several devices on one RTU
    /// line share one client).
    pub fn set_unit(&mut self, unit: u8) {
        use tokio_modbus::prelude::SlaveContext;
        if unit != self.unit {
            self.unit = unit;
            if let Some(ctx) = &mut self.ctx {
                ctx.set_slave(Slave(unit));
            }
        }
    }

    /// The unit id calls go to.
    pub fn unit(&self) -> u8 {
        self.unit
    }

    /// Driver id (used in errors).
    pub fn device(&self) -> &str {
        &self.device
    }

    /// The call policy.
    pub fn policy(&self) -> CallPolicy {
        self.policy
    }

    /// Counts so far.
    pub fn stats(&self) -> LinkStats {
        self.stats
    }

    fn link_error(&self, reason: String) -> DriverError {
        DriverError::Link {
            device: self.device.clone(),
            reason,
        }
    }

    fn timeout_error(&self) -> DriverError {
        DriverError::Timeout {
            device: self.device.clone(),
            timeout_ms: self.policy.timeout.as_millis() as u64,
        }
    }

    async fn connect(&mut self) -> Result<(), DriverError> {
        if self.ctx.is_some() {
            return Ok(());
        }
        let slave = Slave(self.unit);
        let ctx = match &mut self.link {
            Link::Tcp(addr) => {
                let addr = *addr;
                match tokio::time::timeout(
                    self.policy.timeout,
                    tokio_modbus::client::tcp::connect_slave(addr, slave),
                )
                .await
                {
                    Err(_) => return Err(self.timeout_error()),
                    Ok(Err(e)) => return Err(self.link_error(format!("connect to {addr}: {e}"))),
                    Ok(Ok(ctx)) => ctx,
                }
            }
            Link::Rtu(settings) => {
                let port = open_serial(settings)?;
                tokio_modbus::client::rtu::attach_slave(port, slave)
            }
            Link::Attached(ctx) => match ctx.take() {
                Some(ctx) => ctx,
                None => {
                    return Err(self.link_error(
                        "the attached stream failed earlier and cannot be reopened".into(),
                    ))
                }
            },
        };
        self.stats.connects += 1;
        self.ctx = Some(ctx);
        Ok(())
    }

    /// When the line will have been silent for the frame gap (RTU).
    fn frame_gap_ends(&self) -> Option<tokio::time::Instant> {
        self.frame_gap
            .zip(self.line_quiet_since)
            .map(|(g, q)| q + g)
    }

    async fn attempt(&mut self, req: Request<'static>) -> Result<Response, DriverError> {
        self.connect().await?;
        if let Some(at) = self.frame_gap_ends() {
            tokio::time::sleep_until(at).await;
        }
        self.last_sent = Some(tokio::time::Instant::now());
        let ctx = self.ctx.as_mut().expect("connected above");
        let answer = tokio::time::timeout(self.policy.timeout, ctx.call(req)).await;
        self.line_quiet_since = Some(tokio::time::Instant::now());
        match answer {
            Err(_) => {
                self.stats.timeouts += 1;
                Err(self.timeout_error())
            }
            Ok(Err(tokio_modbus::Error::Transport(e))) => {
                self.stats.link_errors += 1;
                Err(self.link_error(e.to_string()))
            }
            Ok(Err(tokio_modbus::Error::Protocol(e))) => {
                self.stats.link_errors += 1;
                Err(self.link_error(format!("garbled answer: {e}")))
            }
            Ok(Ok(Err(exception))) => {
                self.stats.exceptions += 1;
                Err(DriverError::Device {
                    device: self.device.clone(),
                    reason: format!(
                        "Modbus exception {:#04x} ({exception:?})",
                        u8::from(exception)
                    ),
                })
            }
            Ok(Ok(Ok(response))) => Ok(response),
        }
    }

    /// When the latest attempt of a call was sent.
    pub fn last_sent(&self) -> Option<tokio::time::Instant> {
        self.last_sent
    }

    /// Send one request; retry per the policy when it is idempotent.
    pub async fn call(&mut self, req: Request<'static>) -> Result<Response, DriverError> {
        self.stats.calls += 1;
        let attempts = if is_idempotent(&req) {
            1 + self.policy.retries
        } else {
            1
        };
        let mut last = None;
        for n in 0..attempts {
            if n > 0 {
                self.stats.retries += 1;
                tokio::time::sleep(self.policy.retry_delay).await;
            }
            match self.attempt(req.clone()).await {
                Ok(r) => return Ok(r),
                Err(e) if e.is_link_failure() => {
                    // Never reuse a connection after an unknown outcome.
                    self.ctx = None;
                    last = Some(e);
                }
                Err(e) if is_busy(&e) => last = Some(e),
                Err(e) => return Err(e),
            }
        }
        Err(last.expect("at least one attempt"))
    }

    /// Read `count` holding registers from `addr`.
    pub async fn read_holding(&mut self, addr: u16, count: u16) -> Result<Vec<u16>, DriverError> {
        match self
            .call(Request::ReadHoldingRegisters(addr, count))
            .await?
        {
            Response::ReadHoldingRegisters(words) => self.check_len(words, count),
            other => Err(self.unexpected(other)),
        }
    }

    /// Read `count` input registers from `addr`.
    pub async fn read_input(&mut self, addr: u16, count: u16) -> Result<Vec<u16>, DriverError> {
        match self.call(Request::ReadInputRegisters(addr, count)).await? {
            Response::ReadInputRegisters(words) => self.check_len(words, count),
            other => Err(self.unexpected(other)),
        }
    }

    /// Read `count` coils from `addr`.
    pub async fn read_coils(&mut self, addr: u16, count: u16) -> Result<Vec<bool>, DriverError> {
        match self.call(Request::ReadCoils(addr, count)).await? {
            Response::ReadCoils(mut bits) if bits.len() >= usize::from(count) => {
                bits.truncate(usize::from(count));
                Ok(bits)
            }
            other => Err(self.unexpected(other)),
        }
    }

    /// Read `count` discrete inputs from `addr`.
    pub async fn read_discrete(&mut self, addr: u16, count: u16) -> Result<Vec<bool>, DriverError> {
        match self.call(Request::ReadDiscreteInputs(addr, count)).await? {
            Response::ReadDiscreteInputs(mut bits) if bits.len() >= usize::from(count) => {
                bits.truncate(usize::from(count));
                Ok(bits)
            }
            other => Err(self.unexpected(other)),
        }
    }

    /// Write registers from `addr`: function 06 for one word, 16 for more.
    pub async fn write_registers(&mut self, addr: u16, words: &[u16]) -> Result<(), DriverError> {
        let req = if words.len() == 1 {
            Request::WriteSingleRegister(addr, words[0])
        } else {
            Request::WriteMultipleRegisters(addr, Cow::Owned(words.to_vec()))
        };
        self.call(req).await.map(|_| ())
    }

    /// Write one coil.
    pub async fn write_coil(&mut self, addr: u16, on: bool) -> Result<(), DriverError> {
        self.call(Request::WriteSingleCoil(addr, on))
            .await
            .map(|_| ())
    }

    fn check_len(&self, words: Vec<u16>, count: u16) -> Result<Vec<u16>, DriverError> {
        if words.len() == usize::from(count) {
            Ok(words)
        } else {
            Err(self.link_error(format!("asked for {count} registers, got {}", words.len())))
        }
    }

    fn unexpected(&self, r: Response) -> DriverError {
        self.link_error(format!("unexpected answer {r:?}"))
    }
}

fn is_busy(e: &DriverError) -> bool {
    let busy = format!("{:#04x}", u8::from(ExceptionCode::ServerDeviceBusy));
    matches!(e, DriverError::Device { reason, .. } if reason.contains(&busy))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reads_and_absolute_writes_are_idempotent_the_rest_not() {
        assert!(is_idempotent(&Request::ReadHoldingRegisters(0, 1)));
        assert!(is_idempotent(&Request::WriteSingleRegister(8, 6000)));
        assert!(is_idempotent(&Request::WriteMultipleRegisters(
            8,
            Cow::Owned(vec![1, 2])
        )));
        assert!(!is_idempotent(&Request::MaskWriteRegister(0, 0xFF, 0)));
        assert!(!is_idempotent(&Request::ReadWriteMultipleRegisters(
            0,
            1,
            2,
            Cow::Owned(vec![3])
        )));
        assert!(!is_idempotent(&Request::Custom(0x41, Cow::Owned(vec![]))));
    }

    #[tokio::test(start_paused = true)]
    async fn silence_is_a_timeout_after_the_retries_and_a_closed_stream_a_link_error() {
        let (ours, _theirs) = tokio::io::duplex(64);
        let policy = CallPolicy::default();
        let mut c = ModbusClient::attach_tcp("psu", ours, 1, policy);
        let err = c.read_holding(0, 1).await.unwrap_err();
        // The attached stream is dropped after the first timeout; the
        // retries then find no stream to reopen.
        assert!(err.is_link_failure(), "{err}");
        assert_eq!(c.stats().timeouts, 1);
        assert_eq!(c.stats().retries, 2);

        let (ours, theirs) = tokio::io::duplex(64);
        drop(theirs);
        let mut c = ModbusClient::attach_rtu("psu", ours, 1, policy);
        let err = c.write_registers(8, &[100]).await.unwrap_err();
        assert!(matches!(err, DriverError::Link { .. }), "{err}");
    }

    #[tokio::test(start_paused = true)]
    async fn a_retried_read_is_stamped_from_its_last_attempt() {
        use tokio::io::{AsyncReadExt, AsyncWriteExt};
        // A Modbus TCP server on a duplex: "busy" to the first request,
        // register 0 = 1234 to the second.
        let (ours, mut theirs) = tokio::io::duplex(256);
        tokio::spawn(async move {
            for n in 0..2 {
                let mut head = [0u8; 7];
                theirs.read_exact(&mut head).await.unwrap();
                let len = usize::from(u16::from_be_bytes([head[4], head[5]])) - 1;
                let mut pdu = vec![0u8; len];
                theirs.read_exact(&mut pdu).await.unwrap();
                let reply: Vec<u8> = if n == 0 {
                    vec![0x83, 0x06]
                } else {
                    vec![0x03, 2, 0x04, 0xD2]
                };
                let mut frame = head[..4].to_vec();
                frame.extend_from_slice(&(reply.len() as u16 + 1).to_be_bytes());
                frame.push(head[6]);
                frame.extend_from_slice(&reply);
                theirs.write_all(&frame).await.unwrap();
            }
        });
        let policy = CallPolicy::default();
        let mut c = ModbusClient::attach_tcp("daq", ours, 1, policy);
        let t0 = tokio::time::Instant::now();
        assert_eq!(c.read_holding(0, 1).await.unwrap(), vec![1234]);
        assert_eq!(c.stats().retries, 1);
        // The values are from the second attempt, sent a retry delay
        // after the first: a sample stamped at the first would be early.
        assert_eq!(c.last_sent(), Some(t0 + policy.retry_delay));
    }

    #[test]
    fn the_rtu_frame_gap_is_three_and_a_half_characters_or_the_fixed_fast_value() {
        let at = |baud, parity, stop_bits| {
            rtu_frame_gap(&SerialSettings {
                path: String::new(),
                baud_rate: baud,
                parity,
                stop_bits,
            })
        };
        use crate::serial::port::Parity;
        // 9600 baud, even parity: 11 bits a character, 3.5 of them 4.01 ms.
        let slow = at(9600, Parity::Even, 1).as_secs_f64();
        assert!((slow - 3.5 * 11.0 / 9600.0).abs() < 1e-9, "{slow}");
        // 19 200 baud 8N1: 10 bits, 1.82 ms; above it the fixed 1.75 ms.
        let edge = at(19_200, Parity::None, 1).as_secs_f64();
        assert!((edge - 3.5 * 10.0 / 19_200.0).abs() < 1e-9, "{edge}");
        assert_eq!(at(115_200, Parity::None, 1), RTU_FRAME_GAP_FAST);
        assert_eq!(at(38_400, Parity::Even, 1), Duration::from_micros(1750));
    }

    #[tokio::test(start_paused = true)]
    async fn an_rtu_request_waits_for_the_frame_gap_after_the_last_answer() {
        use tokio::io::{AsyncReadExt, AsyncWriteExt};
        const MODBUS_CRC: crc::Crc<u16> = crc::Crc::<u16>::new(&crc::CRC_16_MODBUS);
        // An RTU device on a duplex that answers every read of one input
        // register at once, and notes when each request arrived and when
        // each answer left.
        let (ours, mut theirs) = tokio::io::duplex(256);
        let device = tokio::spawn(async move {
            let mut log = Vec::new();
            for n in 0..3u16 {
                let mut req = [0u8; 8];
                theirs.read_exact(&mut req).await.unwrap();
                let arrived = tokio::time::Instant::now();
                let mut frame = vec![req[0], 0x04, 2, 0, n as u8];
                let crc = MODBUS_CRC.checksum(&frame);
                frame.extend_from_slice(&crc.to_le_bytes());
                theirs.write_all(&frame).await.unwrap();
                log.push((arrived, tokio::time::Instant::now()));
            }
            log
        });
        let mut c = ModbusClient::attach_rtu("daq", ours, 7, CallPolicy::default());
        for n in 0..3 {
            assert_eq!(c.read_input(0, 1).await.unwrap(), vec![n]);
        }
        let log = device.await.unwrap();
        for pair in log.windows(2) {
            let silence = pair[1].0 - pair[0].1;
            assert!(
                silence >= RTU_FRAME_GAP_FAST,
                "{silence:?} of silence before a request"
            );
        }

        // Modbus TCP keeps no gap: its frames are delimited by length.
        let tcp = ModbusClient::tcp(
            "psu",
            "127.0.0.1:1".parse().unwrap(),
            1,
            CallPolicy::default(),
        );
        assert_eq!(tcp.frame_gap, None);
    }

    #[tokio::test(start_paused = true)]
    async fn a_refused_tcp_connection_is_a_link_error() {
        // Bind and drop a listener: its port is closed now.
        let addr = std::net::TcpListener::bind("127.0.0.1:0")
            .unwrap()
            .local_addr()
            .unwrap();
        let mut c = ModbusClient::tcp("psu", addr, 1, CallPolicy::default());
        let err = c.read_input(0, 2).await.unwrap_err();
        assert!(matches!(err, DriverError::Link { .. }), "{err}");
        assert_eq!(c.stats().retries, 2);
    }
}
