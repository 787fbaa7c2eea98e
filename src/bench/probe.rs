//! `motorbench probe`: check a rig's wiring before a test. Reads every
//! sensor channel once; with `actuate`, also drives each power stage in
//! turn at a harmless set point, reads again, and puts that stage in its
//! safe state, whatever happened; then reads once more so the user sees
//! the outputs gone.
//!
//! Harmless set points: a DC supply or an induction machine's supply VFD
//! at 5 % of the test's voltage limit, its current limit (where it has
//! one) at 10 % of the test's current limit; a dynamometer at 5 % of the
//! test's speed limit, with the supply off.

use std::time::Duration;

use motorbench_drivers::{ChannelInfo, DriverError, PowerStage, SensorStream};

use crate::machine::OpenedRig;
use crate::rig::ModbusProbe;

/// Fraction of `limits.max_voltage_V` used as the harmless set point
/// of a supply (and of `limits.max_speed_rad_s` of a dynamometer).
pub const PROBE_SETPOINT_FRACTION: f64 = 0.05;
/// Fraction of `limits.max_current_A` the supply's limit is set to.
pub const PROBE_CURRENT_FRACTION: f64 = 0.1;
/// How long the output stays on before the channels are read again.
pub const PROBE_HOLD: Duration = Duration::from_millis(500);
/// The most batches a stream's queue is drained of before a read (more
/// than a merged stream queues; an unpaced simulated rig, always ready,
/// stops there).
const MAX_QUEUED_BATCHES: usize = 10_000;

/// One line of a probe.
#[derive(Debug, Clone, PartialEq)]
pub enum ProbeLine {
    /// A channel read.
    Channel {
        /// The step it was read at (`idle`, `on`, `safe`).
        step: &'static str,
        /// The channel.
        info: ChannelInfo,
        /// Its value, or why it could not be read.
        value: Result<f64, String>,
    },
    /// A command to the power stage.
    Command {
        /// What was asked.
        what: String,
        /// How it went.
        result: Result<(), String>,
    },
}

impl std::fmt::Display for ProbeLine {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            ProbeLine::Channel { step, info, value } => match value {
                Ok(v) => write!(
                    f,
                    "[{step:>4}] {:<18} {v:>14.6} {:<6} ({})",
                    info.quantity, info.unit, info.source
                ),
                Err(e) => write!(f, "[{step:>4}] {:<18} FAILED: {e}", info.quantity),
            },
            ProbeLine::Command { what, result } => match result {
                Ok(()) => write!(f, "[cmd ] {what}: ok"),
                Err(e) => write!(f, "[cmd ] {what}: FAILED: {e}"),
            },
        }
    }
}

/// A probe's lines; it passed when none failed.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct ProbeReport {
    /// What was read and commanded, in order.
    pub lines: Vec<ProbeLine>,
}

impl ProbeReport {
    /// True when every read and command succeeded (an unsupported current
    /// limit counts as success).
    pub fn passed(&self) -> bool {
        self.lines.iter().all(|l| match l {
            ProbeLine::Channel { value, .. } => value.is_ok(),
            ProbeLine::Command { result, .. } => result.is_ok(),
        })
    }
}

/// Where a probe reads the channels: one at a time where the rig can
/// (Modbus sensors), else from the stream's batches.
struct Channels<'a> {
    modbus: Option<&'a ModbusProbe>,
    stream: &'a mut dyn SensorStream,
}

impl Channels<'_> {
    async fn read_all(&mut self, step: &'static str, out: &mut Vec<ProbeLine>) {
        if let Some(probe) = self.modbus {
            for (info, value) in probe.read_each().await {
                out.push(ProbeLine::Channel {
                    step,
                    info,
                    value: value.map_err(|e| e.to_string()),
                });
            }
            return;
        }
        // A stream that merges several links polls them in the background
        // and queues the readings: drop what is queued (at most
        // MAX_QUEUED_BATCHES) so that the values are read after the last
        // command, not before it.
        for _ in 0..MAX_QUEUED_BATCHES {
            match tokio::time::timeout(Duration::ZERO, self.stream.next_batch()).await {
                Ok(Ok(_)) => {}
                Ok(Err(_)) | Err(_) => break,
            }
        }
        // A batch carries the channels read at one instant, which need
        // not be all of them (channels of several links or rates): read
        // batches until every channel has a value, for at most 2 s.
        let channels = self.stream.channels().to_vec();
        let mut values: Vec<Option<f64>> = vec![None; channels.len()];
        let deadline = tokio::time::Instant::now() + Duration::from_secs(2);
        let mut failure = None;
        while values.iter().any(Option::is_none) {
            match tokio::time::timeout_at(deadline, self.stream.next_batch()).await {
                Ok(Ok(batch)) => {
                    for s in batch.samples {
                        if let Some(v) = values.get_mut(s.channel) {
                            *v = Some(s.value);
                        }
                    }
                }
                Ok(Err(e)) => {
                    failure = Some(e.to_string());
                    break;
                }
                Err(_) => break,
            }
        }
        if let (Some(why), true) = (&failure, values.iter().all(Option::is_none)) {
            return fail_all(channels, step, why, out);
        }
        for (info, value) in channels.into_iter().zip(values) {
            let value = value.ok_or_else(|| {
                failure
                    .clone()
                    .unwrap_or_else(|| "no reading within 2 s".to_string())
            });
            out.push(ProbeLine::Channel { step, info, value });
        }
    }
}

fn fail_all(channels: Vec<ChannelInfo>, step: &'static str, why: &str, out: &mut Vec<ProbeLine>) {
    for info in channels {
        out.push(ProbeLine::Channel {
            step,
            info,
            value: Err(why.to_string()),
        });
    }
}

fn command(out: &mut Vec<ProbeLine>, what: String, r: Result<(), DriverError>) -> bool {
    let ok = r.is_ok();
    out.push(ProbeLine::Command {
        what,
        result: r.map_err(|e| e.to_string()),
    });
    ok
}

/// A power stage a probe exercises, and its harmless set point.
struct ProbedStage<'a> {
    /// Put before each command (`supply: `), empty for a rig's only stage.
    label: String,
    stage: &'a mut dyn PowerStage,
    setpoint: f64,
    /// The current limit to set first, where one is asked for.
    current_limit: Option<f64>,
}

impl ProbedStage<'_> {
    /// Drive the stage at its set point, read, and put it in its safe
    /// state whatever happened.
    async fn exercise(&mut self, channels: &mut Channels<'_>, out: &mut Vec<ProbeLine>) {
        let label = &self.label;
        let mut ok = match self.current_limit {
            None => true,
            Some(amps) => match self.stage.set_current_limit(amps).await {
                Err(DriverError::Unsupported { .. }) => true,
                r => command(out, format!("{label}current limit {amps:.3} A"), r),
            },
        };
        let volts = self.setpoint;
        ok = ok
            && command(
                out,
                format!("{label}set point {volts:.3}"),
                self.stage.set_setpoint(volts).await,
            );
        ok = ok
            && command(
                out,
                format!("{label}output on"),
                self.stage.set_output_enabled(true).await,
            );
        if ok {
            tokio::time::sleep(PROBE_HOLD).await;
            channels.read_all("on", out).await;
        }
        let safe = self.stage.safe_state().await;
        command(out, format!("{label}safe state"), safe);
    }
}

/// Read every channel; with `actuate`, exercise each stage in turn, then
/// read once more.
async fn probe_stages(
    mut channels: Channels<'_>,
    stages: Vec<ProbedStage<'_>>,
    actuate: bool,
) -> ProbeReport {
    let mut lines = Vec::new();
    channels.read_all("idle", &mut lines).await;
    if !actuate {
        return ProbeReport { lines };
    }
    for mut stage in stages {
        stage.exercise(&mut channels, &mut lines).await;
    }
    tokio::time::sleep(PROBE_HOLD).await;
    channels.read_all("safe", &mut lines).await;
    ProbeReport { lines }
}

/// Probe an opened rig: read every channel; with `actuate`, drive each
/// stage in turn (the one feeding the machine first, with its current
/// limited to [`PROBE_CURRENT_FRACTION`] of `max_current`) at
/// [`PROBE_SETPOINT_FRACTION`] of its largest set point, then put it in
/// its safe state, and read once more.
pub async fn probe(rig: &mut OpenedRig, max_current: f64, actuate: bool) -> ProbeReport {
    let channels = Channels {
        modbus: rig.modbus_probe.as_ref(),
        stream: rig.sensors.as_mut(),
    };
    let only = rig.stages.len() == 1;
    let stages = rig
        .stages
        .iter_mut()
        .enumerate()
        .map(|(k, s)| ProbedStage {
            label: if only {
                String::new()
            } else {
                format!("{}: ", s.name)
            },
            stage: s.stage.as_mut(),
            setpoint: PROBE_SETPOINT_FRACTION * s.max_setpoint,
            current_limit: (k == 0).then_some(PROBE_CURRENT_FRACTION * max_current),
        })
        .collect();
    probe_stages(channels, stages, actuate).await
}
