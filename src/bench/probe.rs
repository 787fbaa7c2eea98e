//! `motorbench probe`: check a rig's wiring before a test. Reads every
//! sensor channel once; with `actuate`, also drives the power stage at a
//! harmless set point (5 % of the test's voltage limit, with the supply's
//! current limit at 10 % of the test's current limit), reads again, and
//! puts the stage in its safe state, whatever happened, then reads once
//! more so the user sees the output gone.

use std::time::Duration;

use motorbench_drivers::{ChannelInfo, DriverError};

use super::rig::Rig;
use crate::config::Config;

/// Fraction of `limits.max_voltage_V` used as the harmless set point.
pub const PROBE_SETPOINT_FRACTION: f64 = 0.05;
/// Fraction of `limits.max_current_A` the supply's limit is set to.
pub const PROBE_CURRENT_FRACTION: f64 = 0.1;
/// How long the output stays on before the channels are read again.
pub const PROBE_HOLD: Duration = Duration::from_millis(500);

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

async fn read_all(rig: &mut Rig, step: &'static str, out: &mut Vec<ProbeLine>) {
    match &rig.modbus_sensors {
        Some(probe) => {
            for (info, value) in probe.read_each().await {
                out.push(ProbeLine::Channel {
                    step,
                    info,
                    value: value.map_err(|e| e.to_string()),
                });
            }
        }
        None => {
            // A batch carries the channels read at one instant, which need
            // not be all of them (channels of several links or rates): read
            // batches until every channel has a value, for at most 2 s.
            let channels = rig.sensors.channels().to_vec();
            let mut values: Vec<Option<f64>> = vec![None; channels.len()];
            let deadline = tokio::time::Instant::now() + Duration::from_secs(2);
            let mut failure = None;
            while values.iter().any(Option::is_none) {
                match tokio::time::timeout_at(deadline, rig.sensors.next_batch()).await {
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

/// Probe `rig` (built from `cfg`).
pub async fn probe(cfg: &Config, rig: &mut Rig, actuate: bool) -> ProbeReport {
    let mut lines = Vec::new();
    read_all(rig, "idle", &mut lines).await;
    if !actuate {
        return ProbeReport { lines };
    }
    let volts = PROBE_SETPOINT_FRACTION * cfg.limits.max_voltage;
    let amps = PROBE_CURRENT_FRACTION * cfg.limits.max_current;
    let mut ok = match rig.stage.set_current_limit(amps).await {
        Err(DriverError::Unsupported { .. }) => true,
        r => command(&mut lines, format!("current limit {amps:.3} A"), r),
    };
    ok = ok
        && command(
            &mut lines,
            format!("set point {volts:.3}"),
            rig.stage.set_setpoint(volts).await,
        );
    ok = ok
        && command(
            &mut lines,
            "output on".into(),
            rig.stage.set_output_enabled(true).await,
        );
    if ok {
        tokio::time::sleep(PROBE_HOLD).await;
        read_all(rig, "on", &mut lines).await;
    }
    // Whatever happened: safe state, then read once more.
    let safe = rig.stage.safe_state().await;
    command(&mut lines, "safe state".into(), safe);
    tokio::time::sleep(PROBE_HOLD).await;
    read_all(rig, "safe", &mut lines).await;
    ProbeReport { lines }
}
