//! The DC test plans (steps and coast-down): drive the plan's steps
//! through a power stage and detect settling, reading through the shared
//! [`Sequencer`] (which records every batch, checks it with the safety
//! monitor, and waits on the stop and the stale-data timeout).
//!
//! On any fault (a limit crossed, a driver error, a stale sensor, an
//! operator stop) the power stage is commanded to its safe state *first*;
//! only then is the cause recorded and the test ended as aborted. Under
//! the safety supervisor a check failed here first is handed to the
//! supervisor (see [`StopPath`]), so it latches like the supervisor's own
//! trips and the record goes on to a sample read in the safe state.

use motorbench_drivers::{ChannelInfo, DriverError, PowerStage, SensorStream};

use super::{PlanStep, SupplyLimitDetector};
use crate::bench::sequencer::{
    driver_stop_reason, safe_state_all, Halt, Read, Sequencer, SpeedChannel,
};
use crate::bench::{
    sensor_channels_with_speed, BenchError, Outcome, Progress, RecordSink, SafetyRules,
    SettleDetector, StopPath,
};
use crate::config::Config;
use crate::record::{ChannelSpec, Entry, EventLevel, RecordError, SegmentPhase};

/// Fraction of `limits.max_current_A` the supply's own current limit is
/// set to at the start of a test.
pub const SUPPLY_LIMIT_FRACTION: f64 = 0.9;

/// Channels recorded for a DC test: every sensor channel in order, then
/// the derived speed, then the armature-voltage command.
pub fn record_channels(sensors: &[ChannelInfo], stage_id: &str) -> Vec<ChannelSpec> {
    let mut out = sensor_channels_with_speed(sensors);
    out.push(ChannelSpec::command("armature_voltage", "V", stage_id));
    out
}

struct Channels {
    voltage: usize,
    current: usize,
    speed: SpeedChannel,
    command_rec: usize,
    /// The encoder's rate, Hz: settling is judged on its readings.
    encoder_rate_hz: f64,
}

impl Channels {
    fn find(sensors: &[ChannelInfo], counts_per_rev: f64) -> Result<Channels, BenchError> {
        let find = |q: &'static str| {
            sensors
                .iter()
                .position(|c| c.quantity == q)
                .ok_or(BenchError::MissingChannel(q))
        };
        let encoder = find("encoder_count")?;
        Ok(Channels {
            voltage: find("armature_voltage")?,
            current: find("armature_current")?,
            speed: SpeedChannel {
                encoder,
                speed_rec: sensors.len(),
                counts_per_rev,
            },
            command_rec: sensors.len() + 1,
            encoder_rate_hz: sensors[encoder].rate_hz,
        })
    }
}

struct Bench<'a> {
    cfg: &'a Config,
    stage: &'a mut dyn PowerStage,
    seq: Sequencer<'a>,
    ch: Channels,
    /// Whether the supply follows its set point, level by level.
    supply: SupplyLimitDetector,
    /// When each watched quantity was last read (a batch carries the
    /// channels read at its instant, which need not be all of them when
    /// channels have their own rates or links).
    latest: Latest,
    /// The latest armature current, A.
    held_current: f64,
}

/// When each quantity the plan watches was last read, ns.
#[derive(Debug, Default)]
struct Latest {
    voltage: Option<u64>,
    current: Option<u64>,
    encoder: Option<u64>,
}

impl Latest {
    /// Every watched quantity has a reading at or after `t_ns`.
    fn all_since(&self, t_ns: u64) -> bool {
        [self.voltage, self.current, self.encoder]
            .iter()
            .all(|t| t.is_some_and(|t| t >= t_ns))
    }
}

/// One reading of the quantities the plan watches.
struct Reading {
    current: f64,
    speed: Option<f64>,
}

impl Bench<'_> {
    fn t_ns(&self) -> u64 {
        self.seq.t_ns()
    }

    async fn marker(
        &mut self,
        index: usize,
        step: &PlanStep,
        phase: SegmentPhase,
    ) -> Result<(), RecordError> {
        self.seq
            .marker(index, step.kind(), phase, step.label())
            .await
    }

    /// Next batch of readings, recorded and checked (see [`Sequencer`]).
    async fn read(&mut self) -> Result<Reading, Halt> {
        let Read { batch, speed } = self.seq.next().await?;
        let t = batch.t_ns;
        let voltage = batch.value(self.ch.voltage);
        let current = batch.value(self.ch.current);
        if voltage.is_some() {
            self.latest.voltage = Some(t);
        }
        if let Some(i) = current {
            self.latest.current = Some(t);
            self.held_current = i;
        }
        if batch.value(self.ch.speed.encoder).is_some() {
            self.latest.encoder = Some(t);
        }
        self.supply.reading(t, voltage, current);
        Ok(Reading {
            current: self.held_current,
            speed,
        })
    }

    async fn command(&mut self, volts: f64) -> Result<(), Halt> {
        if let Err(e) = self.stage.set_setpoint(volts).await {
            return Err(Halt::Fault(driver_stop_reason("power stage", &e)));
        }
        self.seq.command(self.ch.command_rec, volts).await?;
        Ok(())
    }

    /// Hold a level until settled (plus the averaging hold) or timeout.
    async fn level(&mut self, volts: f64) -> Result<(), Halt> {
        self.command(volts).await?;
        let st = self.cfg.settle;
        let window = (st.window_s * self.ch.encoder_rate_hz).round() as usize;
        let mut settle = SettleDetector::new(window, st.tolerance, 2);
        let start = self.t_ns();
        let mut settled_at = None;
        let mut hold_done = None;
        loop {
            let r = self.read().await?;
            let now = self.t_ns();
            let elapsed = (now - start) as f64 * 1e-9;
            if let Some(w) = r.speed {
                if settle.push(&[r.current, w]) && elapsed >= st.min_hold_s && settled_at.is_none()
                {
                    settled_at = Some(now);
                }
            }
            if let Some(ts) = settled_at {
                if (now - ts) as f64 * 1e-9 >= st.hold_s {
                    // End on a reading of every watched channel taken after
                    // the hold, so that none is held over from earlier (a
                    // channel polled slower than the others would otherwise
                    // leave the segment's last instants to be interpolated
                    // towards the next level's readings).
                    let done_at = *hold_done.get_or_insert(now);
                    if self.latest.all_since(done_at) {
                        return Ok(());
                    }
                }
            }
            if elapsed >= st.timeout_s {
                let msg = format!(
                    "level {volts} V did not settle within {} s; moving on",
                    st.timeout_s
                );
                self.seq.event(EventLevel::Warn, msg).await?;
                return Ok(());
            }
        }
    }

    /// Open the armature and record until the rotor rests (no encoder
    /// count for one settle window) or the coast-down timeout.
    async fn coastdown(&mut self) -> Result<(), Halt> {
        if let Err(e) = self.stage.set_output_enabled(false).await {
            return Err(Halt::Fault(driver_stop_reason("power stage", &e)));
        }
        self.seq
            .event(
                EventLevel::Info,
                "armature opened for the coast-down".into(),
            )
            .await?;
        let window = (self.cfg.settle.window_s * self.ch.encoder_rate_hz).round() as usize;
        let start = self.t_ns();
        let mut still = 0usize;
        loop {
            let r = self.read().await?;
            // Only encoder readings count (other channels may come between).
            match r.speed {
                Some(0.0) => still += 1,
                Some(_) => still = 0,
                None => {}
            }
            if still >= window {
                return Ok(());
            }
            if (self.t_ns() - start) as f64 * 1e-9 >= self.cfg.settle.coastdown_timeout_s {
                let msg = format!(
                    "rotor still turning after {} s of coast-down",
                    self.cfg.settle.coastdown_timeout_s
                );
                self.seq.event(EventLevel::Warn, msg).await?;
                return Ok(());
            }
        }
    }

    async fn run(&mut self, steps: &[PlanStep]) -> Result<Outcome, RecordError> {
        // The supply limits its current a little below the trip limit, so a
        // transient peak is held by the supply rather than ending the test.
        let supply_limit = SUPPLY_LIMIT_FRACTION * self.cfg.common.limits.max_current;
        match self.stage.set_current_limit(supply_limit).await {
            Ok(()) => self.supply = SupplyLimitDetector::new(Some(supply_limit)),
            Err(DriverError::Unsupported { .. }) => {}
            Err(e) => {
                return self
                    .abort(None, driver_stop_reason("power stage", &e))
                    .await
            }
        }
        let start = async {
            self.stage.set_setpoint(0.0).await?;
            self.stage.set_output_enabled(true).await
        };
        if let Err(e) = start.await {
            return self
                .abort(None, driver_stop_reason("power stage", &e))
                .await;
        }
        for (index, step) in steps.iter().enumerate() {
            self.seq.segment(index, steps.len(), step.label());
            self.marker(index, step, SegmentPhase::Start).await?;
            let commanded = match step {
                PlanStep::Level { volts, .. } => Some(*volts),
                PlanStep::Coastdown { .. } => None,
            };
            self.supply.start(index as u32, commanded);
            let result = match step {
                PlanStep::Level { volts, .. } => self.level(*volts).await,
                PlanStep::Coastdown { .. } => self.coastdown().await,
            };
            match result {
                Ok(()) => {
                    self.supply_limits(step).await?;
                    self.marker(index, step, SegmentPhase::End).await?;
                }
                Err(Halt::Fault(reason)) => return self.abort(Some((index, step)), reason).await,
                Err(Halt::Record(e)) => return Err(e),
            }
        }
        let safe = self.stage.safe_state().await;
        self.seq.sampling_summary().await?;
        let message = match &safe {
            Ok(()) => "test complete; power stage in its safe state".to_string(),
            Err(e) => format!("test complete, but the safe-state command failed: {e}"),
        };
        let level = if safe.is_ok() {
            EventLevel::Info
        } else {
            EventLevel::Warn
        };
        self.seq.event(level, message).await?;
        Ok(Outcome::Completed)
    }

    /// Where the supply did not follow its set point in the segment of
    /// `step`: one `/bench/supply_limit` entry and one warning each.
    async fn supply_limits(&mut self, step: &PlanStep) -> Result<(), RecordError> {
        for limit in self.supply.finish() {
            let message = format!(
                "{}: the segment's voltage is not the commanded step",
                limit.describe(step.label())
            );
            let t_ns = self.t_ns();
            self.seq.push(Entry::SupplyLimit { t_ns, limit }).await?;
            self.seq.event(EventLevel::Warn, message).await?;
        }
        Ok(())
    }

    /// Safe state first, then the record of why.
    async fn abort(
        &mut self,
        open: Option<(usize, &PlanStep)>,
        reason: String,
    ) -> Result<Outcome, RecordError> {
        self.seq.hand_over(&reason).await;
        let safe = safe_state_all(&mut [&mut *self.stage]).await.remove(0);
        let message = match &safe {
            Ok(()) => format!("{reason}; power stage commanded to its safe state"),
            Err(e) => format!("{reason}; SAFE-STATE COMMAND FAILED: {e}"),
        };
        self.seq.event(EventLevel::Abort, message.clone()).await?;
        if let Some((index, step)) = open {
            self.supply_limits(step).await?;
            self.marker(index, step, SegmentPhase::End).await?;
        }
        self.seq.sampling_summary().await?;
        Ok(Outcome::Aborted { reason: message })
    }
}

/// Run the plan's `steps` on a rig. Returns how the test ended; an `Err`
/// only when recording failed (the stage is then in its safe state too).
/// `stops` is an operator-stop flag, or the supervisor's handle when the
/// rig is supervised (see [`StopPath`]).
#[allow(clippy::too_many_arguments)]
pub async fn run_test<'s>(
    cfg: &Config,
    steps: &[PlanStep],
    stage: &mut dyn PowerStage,
    sensors: &mut dyn SensorStream,
    counts_per_rev: f64,
    sink: &mut RecordSink,
    progress: &dyn Progress,
    stops: impl Into<StopPath<'s>>,
) -> Result<Outcome, BenchError> {
    let ch = match Channels::find(sensors.channels(), counts_per_rev) {
        Ok(ch) => ch,
        Err(e) => {
            let _ = stage.safe_state().await;
            return Err(e);
        }
    };
    let monitor = match SafetyRules::of(&cfg.common, None).monitor(
        sensors.channels(),
        Some(counts_per_rev),
        0.0,
    ) {
        Ok(m) => m,
        Err(e) => {
            let _ = stage.safe_state().await;
            return Err(BenchError::Safety(e));
        }
    };
    let speed = ch.speed;
    let seq = Sequencer::new(
        sensors,
        sink,
        progress,
        stops.into(),
        monitor,
        speed,
        cfg.common.sample_rate_hz,
    );
    let mut bench = Bench {
        cfg,
        stage,
        seq,
        ch,
        supply: SupplyLimitDetector::new(None),
        latest: Latest::default(),
        held_current: 0.0,
    };
    match bench.run(steps).await {
        Ok(outcome) => Ok(outcome),
        Err(e) => {
            // Recording failed mid-test: never run a rig blind.
            let _ = bench.stage.safe_state().await;
            Err(e.into())
        }
    }
}
