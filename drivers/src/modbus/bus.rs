//! One task owns each Modbus link; power stages and sensor pollers talk to
//! it through a [`BusHandle`].
//!
//! The task serves two queues: urgent (set points, enable, safe state) and
//! routine (polls, heartbeats). An urgent request waiting goes before any
//! routine one, so a safe-state command never waits behind a queue of
//! polls, only behind the one transaction on the wire.
//!
//! After every request the task publishes its client's counts (requests,
//! timeouts, exceptions, retries, reconnections) to the bus's
//! [`LinkHealth`], which any holder of a handle reads
//! ([`BusHandle::health`]).

use std::time::Duration;

use tokio::sync::{mpsc, oneshot};
use tokio::time::Instant;

use super::client::ModbusClient;
use super::register_map::{Register, RegisterKind};
use crate::{DriverError, LinkHealth};

/// Most registers in one read request (the Modbus limit is 125).
const MAX_READ_WORDS: u32 = 120;

/// A read's values and when it happened.
#[derive(Debug, Clone, PartialEq)]
pub struct Reading {
    /// One value per register asked for, in SI units.
    pub values: Vec<f64>,
    /// When the request went out.
    pub sent: Instant,
    /// When the answer was in.
    pub answered: Instant,
}

impl Reading {
    /// The best estimate of when the device took the values: halfway
    /// between request and answer.
    pub fn midpoint(&self) -> Instant {
        self.sent + (self.answered - self.sent) / 2
    }
}

enum Job {
    Read {
        unit: u8,
        max_gap: u16,
        registers: Vec<Register>,
        reply: oneshot::Sender<Result<Reading, DriverError>>,
    },
    Write {
        unit: u8,
        register: Register,
        words: Vec<u16>,
        reply: oneshot::Sender<Result<(), DriverError>>,
    },
}

/// Urgency of a request.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Priority {
    /// Commands: served before any routine request waiting.
    Urgent,
    /// Polls and heartbeats.
    Routine,
}

/// A handle to a bus task (cheap to clone; the task ends when every
/// handle is dropped).
#[derive(Debug, Clone)]
pub struct BusHandle {
    name: String,
    urgent: mpsc::Sender<Job>,
    routine: mpsc::Sender<Job>,
    health: LinkHealth,
}

/// Start the task that owns `client`'s link; its health is named for the
/// client's device.
pub fn spawn_bus(client: ModbusClient) -> BusHandle {
    let link = client.device().to_string();
    spawn_bus_as(client, &link)
}

/// Start the task that owns `client`'s link, its health named `link` (a
/// name that stays the same from test to test: the link's address). The
/// task publishes the client's counts after every request.
pub fn spawn_bus_as(client: ModbusClient, link: &str) -> BusHandle {
    let (urgent, mut urgent_rx) = mpsc::channel::<Job>(16);
    let (routine, mut routine_rx) = mpsc::channel::<Job>(64);
    let name = client.device().to_string();
    let health = LinkHealth::new(link);
    let published = health.clone();
    let mut client = client;
    tokio::spawn(async move {
        loop {
            let job = tokio::select! {
                biased;
                Some(job) = urgent_rx.recv() => job,
                Some(job) = routine_rx.recv() => job,
                else => break,
            };
            run(&mut client, job).await;
            published.publish(&client.stats().into());
        }
    });
    BusHandle {
        name,
        urgent,
        routine,
        health,
    }
}

async fn run(client: &mut ModbusClient, job: Job) {
    match job {
        Job::Read {
            unit,
            max_gap,
            registers,
            reply,
        } => {
            client.set_unit(unit);
            let sent = Instant::now();
            let retries = client.stats().retries;
            let values = read_registers(client, &registers, max_gap).await;
            let answered = Instant::now();
            // A retried request's values are from its last attempt: stamped
            // from the first, a count read after a 0.2 s timeout would make
            // a speed estimate 0.2 s too short (a false overspeed).
            let sent = match client.last_sent() {
                Some(last) if client.stats().retries > retries => last.max(sent),
                _ => sent,
            };
            let _ = reply.send(values.map(|values| Reading {
                values,
                sent,
                answered,
            }));
        }
        Job::Write {
            unit,
            register,
            words,
            reply,
        } => {
            client.set_unit(unit);
            let r = match register.kind {
                RegisterKind::Coil => client.write_coil(register.address, words[0] != 0).await,
                _ => client.write_registers(register.address, &words).await,
            };
            let _ = reply.send(r);
        }
    }
}

/// Read `registers` with few requests: registers of one table are read
/// together when the addresses between them number at most `max_gap` and
/// the span fits one request. With `max_gap` 0 only adjacent registers
/// are merged: many devices refuse a read that touches an address they do
/// not define.
pub async fn read_registers(
    client: &mut ModbusClient,
    registers: &[Register],
    max_gap: u16,
) -> Result<Vec<f64>, DriverError> {
    let mut values = vec![f64::NAN; registers.len()];
    for kind in [
        RegisterKind::Holding,
        RegisterKind::Input,
        RegisterKind::Coil,
        RegisterKind::DiscreteInput,
    ] {
        let mut idx: Vec<usize> = (0..registers.len())
            .filter(|&i| registers[i].kind == kind)
            .collect();
        idx.sort_by_key(|&i| registers[i].address);
        let mut k = 0;
        while k < idx.len() {
            let start = registers[idx[k]].address;
            let mut end = k;
            let mut span_end = u32::from(start) + u32::from(registers[idx[k]].data_type.width());
            while end + 1 < idx.len() {
                let r = &registers[idx[end + 1]];
                let e = u32::from(r.address) + u32::from(r.data_type.width());
                let gap = u32::from(r.address).saturating_sub(span_end);
                if gap > u32::from(max_gap) || e.max(span_end) - u32::from(start) > MAX_READ_WORDS {
                    break;
                }
                span_end = span_end.max(e);
                end += 1;
            }
            let count = (span_end - u32::from(start)) as u16;
            let words: Vec<u16> = match kind {
                RegisterKind::Holding => client.read_holding(start, count).await?,
                RegisterKind::Input => client.read_input(start, count).await?,
                RegisterKind::Coil => bits(client.read_coils(start, count).await?),
                RegisterKind::DiscreteInput => bits(client.read_discrete(start, count).await?),
            };
            for &i in &idx[k..=end] {
                let r = &registers[i];
                let off = usize::from(r.address - start);
                values[i] = r.decode(&words[off..off + usize::from(r.data_type.width())]);
            }
            k = end + 1;
        }
    }
    Ok(values)
}

fn bits(b: Vec<bool>) -> Vec<u16> {
    b.into_iter().map(u16::from).collect()
}

impl BusHandle {
    /// Driver id of the link.
    pub fn name(&self) -> &str {
        &self.name
    }

    /// The link's request and error counts, as its task publishes them.
    pub fn health(&self) -> &LinkHealth {
        &self.health
    }

    fn gone(&self) -> DriverError {
        DriverError::Link {
            device: self.name.clone(),
            reason: "the bus task has stopped".into(),
        }
    }

    fn queue(&self, p: Priority) -> &mpsc::Sender<Job> {
        match p {
            Priority::Urgent => &self.urgent,
            Priority::Routine => &self.routine,
        }
    }

    /// Read `registers` of unit `unit`, merging only adjacent ones.
    pub async fn read(
        &self,
        unit: u8,
        registers: Vec<Register>,
        p: Priority,
    ) -> Result<Reading, DriverError> {
        self.read_spanning(unit, registers, 0, p).await
    }

    /// Read `registers` of unit `unit`, merging registers up to `max_gap`
    /// addresses apart into one request (see [`read_registers`]).
    pub async fn read_spanning(
        &self,
        unit: u8,
        registers: Vec<Register>,
        max_gap: u16,
        p: Priority,
    ) -> Result<Reading, DriverError> {
        let (reply, rx) = oneshot::channel();
        self.queue(p)
            .send(Job::Read {
                unit,
                max_gap,
                registers,
                reply,
            })
            .await
            .map_err(|_| self.gone())?;
        rx.await.map_err(|_| self.gone())?
    }

    /// Write `value` (SI) to `register` of unit `unit`.
    pub async fn write(
        &self,
        unit: u8,
        register: &Register,
        value: f64,
        p: Priority,
    ) -> Result<(), DriverError> {
        let words = register.encode(value).map_err(|e| DriverError::Device {
            device: self.name.clone(),
            reason: e.to_string(),
        })?;
        self.write_words(unit, register, words, p).await
    }

    /// Write raw words to `register` of unit `unit`.
    pub async fn write_words(
        &self,
        unit: u8,
        register: &Register,
        words: Vec<u16>,
        p: Priority,
    ) -> Result<(), DriverError> {
        let (reply, rx) = oneshot::channel();
        self.queue(p)
            .send(Job::Write {
                unit,
                register: register.clone(),
                words,
                reply,
            })
            .await
            .map_err(|_| self.gone())?;
        rx.await.map_err(|_| self.gone())?
    }
}

/// The longest a caller should wait for one bus request: every attempt's
/// deadline and pause, plus one transaction ahead of it in the queue.
pub fn worst_case_latency(policy: super::client::CallPolicy) -> Duration {
    let attempts = 1 + policy.retries;
    (policy.timeout + policy.retry_delay) * (attempts + 1)
}
