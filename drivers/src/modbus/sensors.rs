//! [`ModbusSensors`]: registers polled at configured rates, as a
//! [`SensorStream`].
//!
//! Channels with the same rate are read together (one request where their
//! addresses allow). Each poll group keeps its own schedule on the host's
//! monotonic clock; a reading's timestamp is the midpoint between the
//! request leaving and the answer arriving (the best estimate of when a
//! device that samples on request took it). A poll that fails after the
//! client's retries counts as lost for its channels; a schedule slot that
//! passed while the bus was busy counts as lost too. After
//! `max_consecutive_failures` failed polls in a row the stream reports the
//! link failure (the cable is gone); a device exception ends it at once (a
//! wrong register map does not heal).

use async_trait::async_trait;
use tokio::time::{Duration, Instant};

use super::bus::{BusHandle, Priority};
use super::register_map::Register;
use crate::stats::IntervalStats;
use crate::{ChannelInfo, ChannelStats, DriverError, Sample, SampleBatch, SensorStream};

/// One polled channel.
#[derive(Debug, Clone, PartialEq)]
pub struct PolledChannel {
    /// Unit id of the device.
    pub unit: u8,
    /// The register read.
    pub register: Register,
    /// What the channel is (its `rate_hz` sets the poll rate).
    pub info: ChannelInfo,
}

#[derive(Debug)]
struct PollGroup {
    unit: u8,
    period: Duration,
    channels: Vec<usize>,
    next_due: Instant,
    failures_in_a_row: u32,
}

/// Registers polled over a Modbus link.
#[derive(Debug)]
pub struct ModbusSensors {
    id: String,
    bus: BusHandle,
    channels: Vec<ChannelInfo>,
    registers: Vec<Register>,
    groups: Vec<PollGroup>,
    started: Instant,
    stats: Vec<IntervalStats>,
    warnings: Vec<String>,
    max_consecutive_failures: u32,
    max_read_gap: u16,
}

impl ModbusSensors {
    /// Poll `channels` over `bus`. `max_consecutive_failures` failed polls
    /// of one group in a row end the stream.
    pub fn new(
        id: &str,
        bus: BusHandle,
        channels: Vec<PolledChannel>,
        max_consecutive_failures: u32,
    ) -> ModbusSensors {
        let started = Instant::now();
        let mut groups: Vec<PollGroup> = Vec::new();
        for (k, c) in channels.iter().enumerate() {
            let period = Duration::from_secs_f64(1.0 / c.info.rate_hz);
            match groups
                .iter_mut()
                .find(|g| g.unit == c.unit && g.period == period)
            {
                Some(g) => g.channels.push(k),
                None => groups.push(PollGroup {
                    unit: c.unit,
                    period,
                    channels: vec![k],
                    next_due: started,
                    failures_in_a_row: 0,
                }),
            }
        }
        ModbusSensors {
            id: id.to_string(),
            bus,
            stats: channels
                .iter()
                .enumerate()
                .map(|(k, c)| IntervalStats::new(k, c.info.rate_hz))
                .collect(),
            registers: channels.iter().map(|c| c.register.clone()).collect(),
            channels: channels.into_iter().map(|c| c.info).collect(),
            groups,
            started,
            warnings: Vec::new(),
            max_consecutive_failures: max_consecutive_failures.max(1),
            max_read_gap: 0,
        }
    }

    /// Let one request span up to `gap` undefined addresses between
    /// channels (for devices that allow it; the profile's
    /// `max_read_gap`).
    pub fn with_max_read_gap(mut self, gap: u16) -> ModbusSensors {
        self.max_read_gap = gap;
        self
    }

    /// Read every channel once, now (for `probe`): values in channel order.
    pub async fn read_all_once(&self) -> Result<Vec<f64>, DriverError> {
        let mut out = vec![f64::NAN; self.registers.len()];
        for g in &self.groups {
            let regs = g
                .channels
                .iter()
                .map(|&k| self.registers[k].clone())
                .collect();
            let r = self
                .bus
                .read_spanning(g.unit, regs, self.max_read_gap, Priority::Routine)
                .await?;
            for (v, &k) in r.values.iter().zip(&g.channels) {
                out[k] = *v;
            }
        }
        Ok(out)
    }
}

#[async_trait]
impl SensorStream for ModbusSensors {
    fn id(&self) -> &str {
        &self.id
    }

    fn channels(&self) -> &[ChannelInfo] {
        &self.channels
    }

    async fn next_batch(&mut self) -> Result<SampleBatch, DriverError> {
        loop {
            let gi = (0..self.groups.len())
                .min_by_key(|&i| self.groups[i].next_due)
                .ok_or_else(|| DriverError::Ended {
                    device: self.id.clone(),
                })?;
            let due = self.groups[gi].next_due;
            tokio::time::sleep_until(due).await;
            let g = &self.groups[gi];
            let regs: Vec<Register> = g
                .channels
                .iter()
                .map(|&k| self.registers[k].clone())
                .collect();
            let result = self
                .bus
                .read_spanning(g.unit, regs, self.max_read_gap, Priority::Routine)
                .await;
            // Next slot: one period on; slots that passed meanwhile are lost.
            let now = Instant::now();
            let g = &mut self.groups[gi];
            let mut next = due + g.period;
            let mut skipped = 0u64;
            while next <= now {
                next += g.period;
                skipped += 1;
            }
            g.next_due = next;
            let channels = g.channels.clone();
            if skipped > 0 {
                for &k in &channels {
                    self.stats[k].lost(skipped);
                }
                self.warnings.push(format!(
                    "{}: poll of {} late: {skipped} sample slot(s) lost",
                    self.id,
                    channels
                        .iter()
                        .map(|&k| self.channels[k].quantity.as_str())
                        .collect::<Vec<_>>()
                        .join(", ")
                ));
            }
            match result {
                Ok(reading) => {
                    self.groups[gi].failures_in_a_row = 0;
                    let t_ns = (reading.midpoint() - self.started).as_nanos() as u64;
                    let samples = channels
                        .iter()
                        .zip(&reading.values)
                        .map(|(&k, &value)| {
                            self.stats[k].received(t_ns);
                            Sample { channel: k, value }
                        })
                        .collect();
                    return Ok(SampleBatch { t_ns, samples });
                }
                Err(e @ DriverError::Device { .. }) => return Err(e),
                Err(e) => {
                    for &k in &channels {
                        self.stats[k].lost(1);
                    }
                    let g = &mut self.groups[gi];
                    g.failures_in_a_row += 1;
                    if g.failures_in_a_row >= self.max_consecutive_failures {
                        return Err(e);
                    }
                    self.warnings
                        .push(format!("{}: poll failed, sample lost: {e}", self.id));
                }
            }
        }
    }

    fn sampling_stats(&self) -> Vec<ChannelStats> {
        self.stats.iter().map(IntervalStats::summary).collect()
    }

    fn take_warnings(&mut self) -> Vec<String> {
        std::mem::take(&mut self.warnings)
    }

    fn epoch(&self) -> Option<Instant> {
        Some(self.started)
    }
}
