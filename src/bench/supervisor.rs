//! The safety supervisor's checks, independent of the test sequencing.
//!
//! [`SafetyMonitor`] looks at every batch of samples before the sequencer
//! does and names the first reason to stop, a [`StopCause`]:
//!
//! - `[limits]`: voltage, current and speed magnitude (speed from a speed
//!   channel, or derived from encoder counts);
//! - `[supervisor]`: electrical power (an `input_power` channel, or
//!   voltage × current), the winding temperature estimated from I²t
//!   ([`WindingTemperature`]), a channel without a new reading for longer
//!   than the stale timeout (in data time), and the emergency-stop input
//!   (a reading ≥ 0.5 on the configured channel).
//!
//! - optionally, a winding heating budget ([`HeatingBudget`]: the
//!   induction-machine sweep's I²t above rated current).
//!
//! A non-finite reading on a checked channel counts as crossing its limit.
//! It is the one limit check of every test: the sequencer's reading path
//! (`src/bench/sequencer.rs`) checks each batch with it synchronously, under
//! `motorbench run` and under the daemon alike, and the daemon's
//! supervisor task ([`super::supervise`]) checks the same batches with its
//! own instance before forwarding them. Bus loss (no data at all, wall
//! clock), link failures and operator stops come from outside the monitor.

use motorbench_drivers::{ChannelInfo, SampleBatch};
use serde::Serialize;

use super::{SpeedFromEncoder, Trip, WindingTemperature};
use crate::config::{CommonConfig, Limits, Supervision};

/// A winding heating budget: the excess heat `∫ max(0, (I/I_rated)² − 1) dt`,
/// forgetting with a recovery time constant, may not pass `max_i2t_s` (the
/// induction-machine sweep's I²t limit, beside the temperature estimate).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HeatingBudget {
    /// The current it is counted above, A.
    pub rated_current: f64,
    /// The budget, s.
    pub max_i2t_s: f64,
    /// Time constant with which the budget recovers, s.
    pub time_constant_s: f64,
}

/// What a test's [`SafetyMonitor`] enforces: the `[limits]`, the
/// `[supervisor]` section, and a heating budget where the plan has one.
#[derive(Debug, Clone, PartialEq)]
pub struct SafetyRules {
    /// Voltage, current and speed magnitude.
    pub limits: Limits,
    /// Power, winding temperature, stale data, emergency stop.
    pub supervision: Supervision,
    /// The I²t budget, if any.
    pub heating: Option<HeatingBudget>,
}

impl SafetyRules {
    /// The rules of a test configured by `common` (its `[limits]` and
    /// `[supervisor]` section), with the plan's heating budget if any.
    pub fn of(common: &CommonConfig, heating: Option<HeatingBudget>) -> SafetyRules {
        SafetyRules {
            limits: common.limits,
            supervision: common.supervision.clone(),
            heating,
        }
    }

    /// A monitor of these rules for a stream with `channels` (see
    /// [`SafetyMonitor::new`]).
    pub fn monitor(
        &self,
        channels: &[ChannelInfo],
        counts_per_rev: Option<f64>,
        initial_rise_k: f64,
    ) -> Result<SafetyMonitor, MonitorError> {
        let monitor = SafetyMonitor::new(
            self.limits,
            self.supervision.clone(),
            channels,
            counts_per_rev,
            initial_rise_k,
        )?;
        Ok(match self.heating {
            Some(budget) => monitor.with_heating_budget(budget),
            None => monitor,
        })
    }
}

/// The heating budget's running state.
#[derive(Debug, Clone)]
struct Heating {
    budget: HeatingBudget,
    i2t_s: f64,
    /// Data time of the latest current reading, ns.
    last_t: Option<u64>,
}

impl Heating {
    /// Count the current `current` read at `t` (ns) since the previous
    /// reading (explicit Euler, as the budget is defined); `true` once spent.
    fn update(&mut self, current: f64, t: u64) -> bool {
        let dt = self
            .last_t
            .map_or(0.0, |last| t.saturating_sub(last) as f64 * 1e-9);
        self.last_t = Some(t);
        let b = &self.budget;
        let excess = ((current / b.rated_current).powi(2) - 1.0).max(0.0);
        self.i2t_s += (excess - self.i2t_s / b.time_constant_s.max(1e-9)) * dt;
        self.i2t_s.is_nan() || self.i2t_s > b.max_i2t_s
    }
}

/// Device id the supervisor uses in the driver errors it hands the
/// sequencer after a stop.
pub const SUPERVISOR_ID: &str = "safety-supervisor";

/// Why the supervisor stopped a test.
#[derive(Debug, Clone, PartialEq)]
pub enum StopCause {
    /// A reading crossed a limit.
    Limit(Trip),
    /// The estimated winding temperature crossed its limit.
    WindingTemperature {
        /// The estimate, °C.
        celsius: f64,
        /// The limit, °C.
        limit: f64,
    },
    /// The induction-machine sweep's winding heating budget (I²t above
    /// rated current) is spent.
    HeatingBudget {
        /// The budget used, s.
        i2t_s: f64,
        /// The budget, s.
        limit_s: f64,
        /// The rated current it is counted above, A.
        rated_current: f64,
    },
    /// A channel delivered no new reading for too long (data time).
    StaleChannel {
        /// The channel's quantity.
        quantity: String,
        /// How long it has been silent, s.
        silent_s: f64,
        /// The timeout, s.
        timeout_s: f64,
    },
    /// The sample time went backwards, or jumped ahead by more than the
    /// stale timeout from one batch to the next: the readings' clock
    /// cannot be trusted (nor any rate or integral computed on it).
    ClockJump {
        /// Data time of the batch before, s.
        from_s: f64,
        /// Data time of the batch that jumped, s.
        to_s: f64,
    },
    /// The sensor stream delivered nothing for too long (wall clock).
    BusLoss {
        /// Driver id of the stream.
        stream: String,
        /// The timeout that passed, s.
        timeout_s: f64,
    },
    /// A device reported an error (link, timeout or refusal).
    DeviceFault(String),
    /// The sequencer stopped taking samples.
    SequencerStalled,
    /// An emergency stop: the API call, or the input channel.
    EmergencyStop {
        /// Where it came from.
        source: String,
    },
    /// An operator asked to abort the test.
    OperatorAbort,
    /// The daemon is shutting down (SIGTERM).
    Shutdown,
}

impl StopCause {
    /// True for the causes that latch the rig until an operator resets it
    /// (everything except an operator abort and a shutdown).
    pub fn latches(&self) -> bool {
        !matches!(self, StopCause::OperatorAbort | StopCause::Shutdown)
    }

    /// A short machine-readable name: `limit`, `winding_temperature`,
    /// `heating_budget`, `stale_channel`, `clock_jump`, `bus_loss`, `device_fault`, `sequencer_stalled`,
    /// `emergency_stop`, `operator_abort`, `shutdown`.
    pub fn kind(&self) -> &'static str {
        match self {
            StopCause::Limit(_) => "limit",
            StopCause::WindingTemperature { .. } => "winding_temperature",
            StopCause::HeatingBudget { .. } => "heating_budget",
            StopCause::StaleChannel { .. } => "stale_channel",
            StopCause::ClockJump { .. } => "clock_jump",
            StopCause::BusLoss { .. } => "bus_loss",
            StopCause::DeviceFault(_) => "device_fault",
            StopCause::SequencerStalled => "sequencer_stalled",
            StopCause::EmergencyStop { .. } => "emergency_stop",
            StopCause::OperatorAbort => "operator_abort",
            StopCause::Shutdown => "shutdown",
        }
    }
}

impl std::fmt::Display for StopCause {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            StopCause::Limit(trip) => write!(f, "limit tripped: {trip}"),
            StopCause::WindingTemperature { celsius, limit } => write!(
                f,
                "estimated winding temperature {celsius:.1} °C beyond the limit {limit} °C"
            ),
            StopCause::HeatingBudget {
                i2t_s,
                limit_s,
                rated_current,
            } => write!(
                f,
                "winding heating budget spent: I²t {i2t_s:.1} s beyond {limit_s} s (rated current {rated_current} A)"
            ),
            StopCause::StaleChannel {
                quantity,
                silent_s,
                timeout_s,
            } => write!(
                f,
                "stale data: no new {quantity} reading for {silent_s:.3} s (timeout {timeout_s} s)"
            ),
            StopCause::ClockJump { from_s, to_s } => write!(
                f,
                "clock jump: the sample time went from {from_s:.4} s to {to_s:.4} s"
            ),
            StopCause::BusLoss { stream, timeout_s } => write!(
                f,
                "bus loss: sensor stream {stream} delivered nothing for {timeout_s} s"
            ),
            StopCause::DeviceFault(e) => write!(f, "device fault: {e}"),
            StopCause::SequencerStalled => {
                write!(f, "the test sequencer stopped taking samples")
            }
            StopCause::EmergencyStop { source } => write!(f, "emergency stop ({source})"),
            StopCause::OperatorAbort => write!(f, "operator abort"),
            StopCause::Shutdown => write!(f, "the daemon is shutting down"),
        }
    }
}

/// The latest readings the supervisor saw, for progress displays (and
/// the API's `Readings` schema).
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, utoipa::ToSchema)]
pub struct Readings {
    /// Data time of the batch, s.
    pub t_s: f64,
    /// Voltage, V.
    pub voltage: Option<f64>,
    /// Current, A.
    pub current: Option<f64>,
    /// Speed, rad/s.
    pub speed: Option<f64>,
    /// Electrical power, W.
    pub power: Option<f64>,
    /// Estimated winding temperature, °C.
    pub winding_c: f64,
}

/// What a channel means to the supervisor.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Role {
    Voltage,
    Current,
    Speed,
    Power,
    Encoder,
    EmergencyStop,
    Other,
}

/// Checks every batch of samples against the limits. See the module docs.
#[derive(Debug, Clone)]
pub struct SafetyMonitor {
    limits: Limits,
    supervision: Supervision,
    quantities: Vec<String>,
    roles: Vec<Role>,
    encoder: Option<SpeedFromEncoder>,
    /// Consecutive new encoder speed estimates beyond the speed limit.
    encoder_over: u32,
    last_seen: Vec<Option<u64>>,
    first_t: Option<u64>,
    last_t: Option<u64>,
    winding: WindingTemperature,
    heating: Option<Heating>,
    readings: Readings,
}

/// Why the safety checks cannot be set up for a rig's channels.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum MonitorError {
    /// The configured emergency-stop input is not among the channels.
    #[error("supervisor.estop_channel: the rig has no `{channel}` channel")]
    NoEstopChannel {
        /// The configured channel.
        channel: String,
    },
}

impl SafetyMonitor {
    /// A monitor for a stream with `channels`. `counts_per_rev` lets it
    /// derive speed from an `encoder_count` channel; the winding estimate
    /// starts `initial_rise_k` above ambient. Refused when the configured
    /// emergency-stop channel is not among `channels`.
    pub fn new(
        limits: Limits,
        supervision: Supervision,
        channels: &[ChannelInfo],
        counts_per_rev: Option<f64>,
        initial_rise_k: f64,
    ) -> Result<SafetyMonitor, MonitorError> {
        let estop = supervision.estop_channel.as_deref();
        let roles: Vec<Role> = channels
            .iter()
            .map(|c| match c.quantity.as_str() {
                q if Some(q) == estop => Role::EmergencyStop,
                "armature_voltage" | "line_voltage" => Role::Voltage,
                "armature_current" | "line_current" => Role::Current,
                "speed" => Role::Speed,
                "input_power" => Role::Power,
                "encoder_count" if counts_per_rev.is_some() => Role::Encoder,
                _ => Role::Other,
            })
            .collect();
        if let Some(q) = estop {
            if !roles.contains(&Role::EmergencyStop) {
                return Err(MonitorError::NoEstopChannel {
                    channel: q.to_string(),
                });
            }
        }
        Ok(SafetyMonitor {
            winding: WindingTemperature::new(supervision.thermal, initial_rise_k),
            limits,
            supervision,
            quantities: channels.iter().map(|c| c.quantity.clone()).collect(),
            last_seen: vec![None; roles.len()],
            roles,
            // Over at least four encoder periods: polled counts carry their
            // poll's timestamp jitter, a large part of one period.
            encoder_over: 0,
            encoder: counts_per_rev.map(|c| {
                let rate = channels
                    .iter()
                    .find(|ch| ch.quantity == "encoder_count")
                    .map_or(f64::INFINITY, |ch| ch.rate_hz);
                let baseline_ns = if rate.is_finite() && rate > 0.0 {
                    (4e9 / rate) as u64
                } else {
                    0
                };
                SpeedFromEncoder::with_baseline(c, baseline_ns)
            }),
            first_t: None,
            last_t: None,
            heating: None,
            readings: Readings::default(),
        })
    }

    /// Also check a heating budget (counted from the first current
    /// reading on).
    pub fn with_heating_budget(mut self, budget: HeatingBudget) -> SafetyMonitor {
        self.heating = Some(Heating {
            budget,
            i2t_s: 0.0,
            last_t: None,
        });
        self
    }

    /// What it enforces beyond the limits (and the supervisor's last
    /// resort).
    pub fn supervision(&self) -> &Supervision {
        &self.supervision
    }

    /// The latest readings.
    pub fn readings(&self) -> Readings {
        self.readings
    }

    /// Data time of the latest batch, ns (0 before the first).
    pub fn last_t_ns(&self) -> u64 {
        self.last_t.unwrap_or(0)
    }

    /// The winding-temperature estimate.
    pub fn winding(&self) -> &WindingTemperature {
        &self.winding
    }

    /// Check one batch; the first reason to stop, if any.
    pub fn check(&mut self, batch: &SampleBatch) -> Result<(), StopCause> {
        let t = batch.t_ns;
        if let Some(last) = self.last_t {
            let stale_ns = (self.supervision.stale_timeout * 1e9) as u64;
            if t < last || t - last > stale_ns {
                return Err(StopCause::ClockJump {
                    from_s: last as f64 * 1e-9,
                    to_s: t as f64 * 1e-9,
                });
            }
        }
        let dt_s = self
            .last_t
            .map_or(0.0, |last| t.saturating_sub(last) as f64 * 1e-9);
        self.first_t.get_or_insert(t);
        self.last_t = Some(t);
        let mut voltage = None;
        let mut current = None;
        let mut speed = None;
        let mut power = None;
        let mut encoder_speed = None;
        for s in &batch.samples {
            let Some(role) = self.roles.get(s.channel).copied() else {
                continue;
            };
            self.last_seen[s.channel] = Some(t);
            match role {
                Role::Voltage => voltage = voltage.or(Some(s.value)),
                Role::Current => current = current.or(Some(s.value)),
                Role::Speed => speed = speed.or(Some(s.value)),
                Role::Power => power = power.or(Some(s.value)),
                Role::Encoder => {
                    let Some(e) = self.encoder.as_mut() else {
                        continue;
                    };
                    let before = e.estimates();
                    if let Some(w) = e.update(t, s.value) {
                        speed = speed.or(Some(w));
                        if e.estimates() > before {
                            // A polled count whose timestamp is off makes
                            // one estimate high and the next low: only two
                            // new estimates beyond the limit in a row trip.
                            if w.abs() > self.limits.max_speed {
                                self.encoder_over += 1;
                            } else {
                                self.encoder_over = 0;
                            }
                        }
                        encoder_speed = Some(w);
                    }
                }
                Role::EmergencyStop => {
                    if s.value.is_nan() || s.value >= 0.5 {
                        return Err(StopCause::EmergencyStop {
                            source: format!("input `{}` = {}", self.quantities[s.channel], s.value),
                        });
                    }
                }
                Role::Other => {}
            }
        }
        let power = power.or(match (voltage, current) {
            (Some(u), Some(i)) => Some(u * i),
            _ => None,
        });
        // The estimate integrates the previous current over the interval
        // up to now, then this reading holds until the next batch.
        if let Some(i) = self.readings.current {
            self.winding.update(i, dt_s);
        }
        // A batch may carry some channels only (instruments polled
        // separately): the display holds the latest value of the others;
        // the checks below look at this batch's values.
        let held = self.readings;
        self.readings = Readings {
            t_s: t as f64 * 1e-9,
            voltage: voltage.or(held.voltage),
            current: current.or(held.current),
            speed: speed.or(held.speed),
            power: power.or(held.power),
            winding_c: self.winding.celsius(),
        };
        if current.is_some_and(|i| !i.is_finite()) {
            // A non-finite current poisons the estimate: trip on the limit.
            self.winding.update(f64::NAN, 1.0);
        }
        let l = &self.limits;
        let checks = [
            ("voltage", voltage, l.max_voltage, "V"),
            ("current", current, l.max_current, "A"),
            ("speed", speed, l.max_speed, "rad/s"),
            ("power", power, self.supervision.max_power, "W"),
        ];
        for (quantity, value, limit, unit) in checks {
            if let Some(value) = value {
                let unconfirmed = quantity == "speed"
                    && encoder_speed == Some(value)
                    && value.is_finite()
                    && self.encoder_over < 2;
                if (!value.is_finite() || value.abs() > limit) && !unconfirmed {
                    return Err(StopCause::Limit(Trip {
                        quantity,
                        value,
                        limit,
                        unit,
                    }));
                }
            }
        }
        if let (Some(h), Some(i)) = (self.heating.as_mut(), current) {
            if h.update(i, t) {
                return Err(StopCause::HeatingBudget {
                    i2t_s: h.i2t_s,
                    limit_s: h.budget.max_i2t_s,
                    rated_current: h.budget.rated_current,
                });
            }
        }
        if self.winding.over_limit() {
            return Err(StopCause::WindingTemperature {
                celsius: self.winding.celsius(),
                limit: self.winding.limit_celsius(),
            });
        }
        let stale_ns = (self.supervision.stale_timeout * 1e9) as u64;
        for (k, seen) in self.last_seen.iter().enumerate() {
            let since = seen.or(self.first_t).unwrap_or(t);
            let silent = t.saturating_sub(since);
            if silent > stale_ns {
                return Err(StopCause::StaleChannel {
                    quantity: self.quantities[k].clone(),
                    silent_s: silent as f64 * 1e-9,
                    timeout_s: self.supervision.stale_timeout,
                });
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::Config;
    use motorbench_drivers::Sample;

    fn info(q: &str) -> ChannelInfo {
        ChannelInfo {
            quantity: q.into(),
            unit: String::new(),
            source: "daq".into(),
            rate_hz: 1000.0,
        }
    }

    fn monitor(edit: impl FnOnce(&mut Config)) -> SafetyMonitor {
        let mut cfg = Config::embedded_default();
        edit(&mut cfg);
        let channels = [
            info("armature_voltage"),
            info("armature_current"),
            info("encoder_count"),
            info("emergency_stop"),
        ];
        SafetyMonitor::new(
            cfg.common.limits,
            cfg.common.supervision,
            &channels,
            Some(1000.0),
            0.0,
        )
        .unwrap()
    }

    fn batch(t_ms: u64, values: &[(usize, f64)]) -> SampleBatch {
        SampleBatch {
            t_ns: t_ms * 1_000_000,
            samples: values
                .iter()
                .map(|&(channel, value)| Sample { channel, value })
                .collect(),
        }
    }

    fn all(t_ms: u64, u: f64, i: f64, count: f64) -> SampleBatch {
        batch(t_ms, &[(0, u), (1, i), (2, count), (3, 0.0)])
    }

    #[test]
    fn in_limits_passes_and_each_limit_trips() {
        let mut m = monitor(|_| {});
        assert_eq!(m.check(&all(0, 100.0, 1.0, 0.0)), Ok(()));
        // Speed over at least four encoder periods (4 ms at 1 kHz): none yet.
        assert_eq!(m.check(&all(1, 100.0, 1.0, 10.0)), Ok(()));
        assert_eq!(m.readings().speed, None);
        assert_eq!(m.check(&all(4, 100.0, 1.0, 40.0)), Ok(()));
        let r = m.readings();
        // 40 counts of 1000 per turn in 4 ms: 20π rad/s.
        assert!((r.speed.unwrap() - 20.0 * std::f64::consts::PI).abs() < 1e-9);
        assert_eq!(r.power, Some(100.0));

        let kind = |m: &mut SafetyMonitor, b| match m.check(&b) {
            Err(StopCause::Limit(t)) => t.quantity,
            other => panic!("{other:?}"),
        };
        assert_eq!(
            kind(&mut monitor(|_| {}), all(0, 281.0, 0.0, 0.0)),
            "voltage"
        );
        assert_eq!(
            kind(&mut monitor(|_| {}), all(0, 0.0, -6.5, 0.0)),
            "current"
        );
        assert_eq!(
            kind(&mut monitor(|_| {}), all(0, f64::NAN, 0.0, 0.0)),
            "voltage"
        );
        let mut m = monitor(|_| {});
        m.check(&all(0, 0.0, 0.0, 0.0)).unwrap();
        // 160 counts in 4 ms: 251 rad/s > 230, twice in a row (one estimate
        // beyond the limit may be a polled count's late timestamp).
        assert_eq!(m.check(&all(4, 0.0, 0.0, 160.0)), Ok(()));
        assert_eq!(kind(&mut m, all(8, 0.0, 0.0, 320.0)), "speed");
        // One high estimate followed by a normal one does not trip.
        let mut m = monitor(|_| {});
        m.check(&all(0, 0.0, 0.0, 0.0)).unwrap();
        assert_eq!(m.check(&all(4, 0.0, 0.0, 160.0)), Ok(()));
        assert_eq!(m.check(&all(8, 0.0, 0.0, 200.0)), Ok(()));
        assert_eq!(m.check(&all(12, 0.0, 0.0, 360.0)), Ok(()));
        let mut m = monitor(|c| c.common.supervision.max_power = 500.0);
        assert_eq!(kind(&mut m, all(0, 250.0, 2.5, 0.0)), "power");
    }

    #[test]
    fn emergency_stop_input_trips() {
        let mut m = monitor(|c| c.common.supervision.estop_channel = Some("emergency_stop".into()));
        m.check(&all(0, 0.0, 0.0, 0.0)).unwrap();
        let e = m.check(&batch(1, &[(0, 0.0), (1, 0.0), (2, 0.0), (3, 1.0)]));
        assert!(matches!(e, Err(StopCause::EmergencyStop { .. })), "{e:?}");
        assert!(e.unwrap_err().latches());
        // A configured input the rig does not have is refused up front.
        let mut cfg = Config::embedded_default();
        cfg.common.supervision.estop_channel = Some("estop".into());
        let e = SafetyMonitor::new(
            cfg.common.limits,
            cfg.common.supervision,
            &[info("armature_current")],
            None,
            0.0,
        )
        .unwrap_err();
        assert_eq!(
            e,
            MonitorError::NoEstopChannel {
                channel: "estop".into()
            }
        );
        assert_eq!(
            e.to_string(),
            "supervisor.estop_channel: the rig has no `estop` channel"
        );
    }

    #[test]
    fn a_silent_channel_trips_after_the_stale_timeout() {
        let mut m = monitor(|c| c.common.supervision.stale_timeout = 0.010);
        m.check(&all(0, 0.0, 0.0, 0.0)).unwrap();
        // The current channel stops; the others go on.
        for t in 1..=10 {
            m.check(&batch(t, &[(0, 0.0), (2, 0.0), (3, 0.0)])).unwrap();
        }
        match m.check(&batch(11, &[(0, 0.0), (2, 0.0), (3, 0.0)])) {
            Err(StopCause::StaleChannel {
                quantity, silent_s, ..
            }) => {
                assert_eq!(quantity, "armature_current");
                assert!((silent_s - 0.011).abs() < 1e-12);
            }
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn a_clock_that_goes_back_or_jumps_ahead_trips() {
        let mut m = monitor(|_| {});
        m.check(&all(10, 0.0, 0.0, 0.0)).unwrap();
        m.check(&all(10, 0.0, 0.0, 0.0)).unwrap();
        let e = m.check(&all(9, 0.0, 0.0, 0.0)).unwrap_err();
        assert_eq!(e.kind(), "clock_jump");
        assert!(e.latches());
        let mut m = monitor(|_| {});
        m.check(&all(10, 0.0, 0.0, 0.0)).unwrap();
        // The default stale timeout is 0.25 s: 250 ms is no jump, 251 is.
        m.check(&all(260, 0.0, 0.0, 0.0)).unwrap();
        assert_eq!(
            m.check(&all(511, 0.0, 0.0, 0.0)),
            Err(StopCause::ClockJump {
                from_s: 0.26,
                to_s: 0.511
            })
        );
    }

    #[test]
    fn a_spent_heating_budget_trips() {
        // 3× rated current: an excess of 8 per second, no recovery to speak
        // of; a budget of 2.004 s is passed at 251 ms (2.008 s), not at
        // 250 ms (2.000 s).
        let budget = HeatingBudget {
            rated_current: 1.0,
            max_i2t_s: 2.004,
            time_constant_s: 1e9,
        };
        let mut m = monitor(|_| {}).with_heating_budget(budget);
        let mut tripped_at = None;
        for ms in 0..1000 {
            match m.check(&all(ms, 0.0, 3.0, 0.0)) {
                Ok(()) => {}
                Err(StopCause::HeatingBudget { i2t_s, limit_s, .. }) => {
                    assert!(i2t_s > limit_s);
                    tripped_at = Some(ms);
                    break;
                }
                Err(other) => panic!("{other}"),
            }
        }
        assert_eq!(tripped_at, Some(251));
        // Below rated current the budget is not touched.
        let mut m = monitor(|_| {}).with_heating_budget(budget);
        for ms in 0..1000 {
            assert_eq!(m.check(&all(ms, 0.0, 0.9, 0.0)), Ok(()));
        }
    }

    #[test]
    fn sustained_overcurrent_trips_on_the_winding_estimate() {
        // Fast thermal model: τ = 10 s, rated 1.1 A → 80 K; 3 A is within
        // the current limit but heats the winding to 40 + 595 °C in steady
        // state, crossing 130 °C after τ·ln(595/(595−90)) ≈ 1.64 s.
        let mut m = monitor(|c| c.common.supervision.thermal.time_constant = 10.0);
        let mut tripped_at = None;
        for ms in 0..5000 {
            match m.check(&all(ms, 100.0, 3.0, 0.0)) {
                Ok(()) => {}
                Err(StopCause::WindingTemperature { celsius, limit }) => {
                    assert!(celsius > limit);
                    tripped_at = Some(ms);
                    break;
                }
                Err(other) => panic!("{other}"),
            }
        }
        let expect = 10.0 * (595.04f64 / (595.04 - 90.0)).ln() * 1000.0;
        let at = tripped_at.expect("the winding estimate tripped") as f64;
        assert!(
            (at - expect).abs() <= 2.0,
            "tripped at {at} ms, expected ≈ {expect:.0} ms"
        );
    }
}
