//! Test sequencing: drive the plan's steps through a power stage, read
//! the sensors, check limits, detect settling, and feed every reading to
//! the record.
//!
//! On any fault (a limit crossed, a driver error, a stale sensor, an
//! operator stop) the power stage is commanded to its safe state *first*;
//! only then is the cause recorded and the test ended as aborted. Under
//! the safety supervisor a limit this sequencer sees first is handed to
//! the supervisor (see [`StopPath`]), so it latches like the supervisor's
//! own trips and the record goes on to a sample read in the safe state.

use std::time::Duration;

use motorbench_drivers::{ChannelInfo, DriverError, PowerStage, SensorStream};
use thiserror::Error;

use super::{
    check_limits, PlanStep, Progress, SamplingEvents, SettleDetector, SpeedFromEncoder, StopCause,
    StopPath, SupplyLimitDetector,
};
use crate::config::Config;
use crate::record::{
    ChannelSpec, Entry, Event, EventLevel, Record, RecordBuilder, RecordError, Recorder,
    SegmentMarker, SegmentPhase, TestMeta,
};

/// Fraction of `limits.max_current_A` the supply's own current limit is
/// set to at the start of a test.
pub const SUPPLY_LIMIT_FRACTION: f64 = 0.9;

/// How a test ended.
#[derive(Debug, Clone, PartialEq)]
pub enum Outcome {
    /// Every step of the plan ran.
    Completed,
    /// The test was stopped and the rig put in its safe state.
    Aborted {
        /// Why, for a person.
        reason: String,
    },
}

/// Errors that stop the bench before or outside a test's own faults.
#[derive(Debug, Error)]
pub enum BenchError {
    /// Recording failed: the test cannot go on without losing data.
    #[error(transparent)]
    Record(#[from] RecordError),
    /// The sensors do not provide a channel the plan needs.
    #[error("the sensors provide no `{0}` channel")]
    MissingChannel(&'static str),
}

/// Where readings go: the MCAP recorder (when recording) and the
/// in-memory record that identification reads. Both receive exactly the
/// same entries, so a replay of the file sees the same data.
pub struct RecordSink {
    recorder: Option<Recorder>,
    builder: RecordBuilder,
    last_t_ns: u64,
}

impl RecordSink {
    /// A sink over `channels`; `recorder` is `None` for a dry run.
    pub fn new(
        recorder: Option<Recorder>,
        meta: Option<TestMeta>,
        channels: Vec<ChannelSpec>,
    ) -> RecordSink {
        RecordSink {
            recorder,
            builder: RecordBuilder::new(meta, channels),
            last_t_ns: 0,
        }
    }

    /// The latest time of any entry pushed so far, ns.
    pub fn last_t_ns(&self) -> u64 {
        self.last_t_ns
    }

    /// Record one entry (waits when the recorder's queue is full).
    pub async fn push(&mut self, entry: Entry) -> Result<(), RecordError> {
        self.last_t_ns = self.last_t_ns.max(entry.t_ns());
        self.builder.push(&entry);
        if let Some(r) = &self.recorder {
            r.send(entry).await?;
        }
        Ok(())
    }

    /// The recorder (still open) and the record built so far.
    pub fn into_parts(self) -> (Option<Recorder>, Record) {
        (self.recorder, self.builder.finish())
    }
}

/// Every sensor channel in order, then the speed derived from the encoder
/// count (the channels every test records before its commands).
pub fn sensor_channels_with_speed(sensors: &[ChannelInfo]) -> Vec<ChannelSpec> {
    let mut out: Vec<ChannelSpec> = sensors
        .iter()
        .map(|c| ChannelSpec::sensor(&c.quantity, &c.unit, &c.source))
        .collect();
    let encoder = sensors
        .iter()
        .find(|c| c.quantity == "encoder_count")
        .map_or("encoder", |c| c.source.as_str());
    out.push(ChannelSpec::sensor(
        "speed",
        "rad/s",
        &format!("{encoder}/derived"),
    ));
    out
}

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
    encoder: usize,
    speed_rec: usize,
    command_rec: usize,
    /// The encoder's rate, Hz: settling is judged on its readings.
    encoder_rate_hz: f64,
}

impl Channels {
    fn find(sensors: &[ChannelInfo]) -> Result<Channels, BenchError> {
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
            encoder,
            speed_rec: sensors.len(),
            command_rec: sensors.len() + 1,
            encoder_rate_hz: sensors[encoder].rate_hz,
        })
    }
}

/// Why a step stopped early.
enum Stop {
    Fault(String),
}

/// What one batch of readings brought.
enum Checked {
    Reading(Reading),
    Stop(Stop),
    /// A limit crossed: handed to the supervisor when there is one.
    Trip(StopCause),
}

struct Bench<'a> {
    cfg: &'a Config,
    stage: &'a mut dyn PowerStage,
    sensors: &'a mut dyn SensorStream,
    sink: &'a mut RecordSink,
    progress: &'a dyn Progress,
    stops: StopPath<'a>,
    /// The supervisor has taken a trip of ours: record on, check nothing,
    /// until it ends the stream.
    tripped: bool,
    ch: Channels,
    encoder: SpeedFromEncoder,
    t_ns: u64,
    stale: Duration,
    sampling: SamplingEvents,
    /// Whether the supply follows its set point, level by level.
    supply: SupplyLimitDetector,
    /// Latest armature voltage and current, and when each was read (a
    /// batch carries the channels read at its instant, which need not be
    /// all of them when channels have their own rates or links).
    latest: Latest,
}

/// The latest reading of each quantity the plan watches.
#[derive(Debug, Default)]
struct Latest {
    first_t_ns: Option<u64>,
    voltage: Option<(u64, f64)>,
    current: Option<(u64, f64)>,
    encoder_t_ns: Option<u64>,
}

impl Latest {
    /// Every watched quantity has a reading at or after `t_ns`.
    fn all_since(&self, t_ns: u64) -> bool {
        [
            self.voltage.map(|v| v.0),
            self.current.map(|v| v.0),
            self.encoder_t_ns,
        ]
        .iter()
        .all(|t| t.is_some_and(|t| t >= t_ns))
    }

    /// The first watched quantity with no reading for longer than
    /// `stale` at `t_ns` (data time).
    fn silent(&self, t_ns: u64, stale: Duration) -> Option<(&'static str, u64)> {
        let since =
            |last: Option<u64>| t_ns.saturating_sub(last.or(self.first_t_ns).unwrap_or(t_ns));
        [
            ("armature_voltage", self.voltage.map(|v| v.0)),
            ("armature_current", self.current.map(|v| v.0)),
            ("encoder_count", self.encoder_t_ns),
        ]
        .into_iter()
        .map(|(q, last)| (q, since(last)))
        .find(|&(_, silent)| silent > stale.as_nanos() as u64)
    }
}

/// One reading of the quantities the plan watches.
struct Reading {
    current: f64,
    speed: Option<f64>,
}

impl Bench<'_> {
    async fn event(&mut self, level: EventLevel, message: String) -> Result<(), RecordError> {
        self.sink
            .push(Entry::Event {
                t_ns: self.t_ns,
                event: Event { level, message },
            })
            .await
    }

    async fn marker(
        &mut self,
        index: usize,
        step: &PlanStep,
        phase: SegmentPhase,
    ) -> Result<(), RecordError> {
        let marker = SegmentMarker {
            index: index as u32,
            kind: step.kind(),
            phase,
            label: step.label().to_string(),
        };
        self.sink
            .push(Entry::Segment {
                t_ns: self.t_ns,
                marker,
            })
            .await
    }

    /// Next batch of readings, recorded and checked against the limits.
    /// A limit crossed under the supervisor is handed to it; the batches
    /// up to the end of the stream it then delivers (the last one read in
    /// the safe state) are recorded, and its stop is returned.
    async fn read(&mut self) -> Result<Result<Reading, Stop>, RecordError> {
        loop {
            match self.read_batch().await? {
                Checked::Trip(cause) => {
                    if !self.stops.trip(cause.clone(), self.t_ns).await {
                        return Ok(Err(Stop::Fault(cause.to_string())));
                    }
                    self.tripped = true;
                }
                Checked::Reading(_) if self.tripped => {}
                Checked::Reading(r) => return Ok(Ok(r)),
                Checked::Stop(stop) => return Ok(Err(stop)),
            }
        }
    }

    /// One batch, recorded and (unless tripped) checked.
    async fn read_batch(&mut self) -> Result<Checked, RecordError> {
        if self.stops.operator_stop() {
            return Ok(Checked::Stop(Stop::Fault("operator stop".into())));
        }
        let batch = match tokio::time::timeout(self.stale, self.sensors.next_batch()).await {
            Err(_) => {
                return Ok(Checked::Stop(Stop::Fault(format!(
                    "sensor stream {} delivered nothing for {} ms",
                    self.sensors.id(),
                    self.stale.as_millis()
                ))))
            }
            Ok(Err(e)) => return Ok(Checked::Stop(Stop::Fault(sensor_stop_reason(&e)))),
            Ok(Ok(b)) => b,
        };
        self.t_ns = batch.t_ns;
        let mut values: Vec<(usize, f64)> =
            batch.samples.iter().map(|s| (s.channel, s.value)).collect();
        let get = |c: usize| batch.value(c);
        let t = batch.t_ns;
        self.latest.first_t_ns.get_or_insert(t);
        if let Some(v) = get(self.ch.voltage) {
            self.latest.voltage = Some((t, v));
        }
        if let Some(i) = get(self.ch.current) {
            self.latest.current = Some((t, i));
        }
        self.supply
            .reading(t, get(self.ch.voltage), get(self.ch.current));
        let count = get(self.ch.encoder);
        if count.is_some() {
            self.latest.encoder_t_ns = Some(t);
        }
        let speed = count.and_then(|c| self.encoder.update(t, c));
        if let Some(w) = speed {
            values.push((self.ch.speed_rec, w));
        }
        self.sink
            .push(Entry::Samples {
                t_ns: batch.t_ns,
                values,
            })
            .await?;
        self.progress.tick(batch.t_ns as f64 * 1e-9);
        for message in self.sampling.admit(self.sensors.take_warnings()) {
            self.event(EventLevel::Warn, message).await?;
        }
        let voltage = self.latest.voltage.map_or(0.0, |v| v.1);
        let current = self.latest.current.map_or(0.0, |v| v.1);
        if self.tripped {
            return Ok(Checked::Reading(Reading { current, speed }));
        }
        if let Some(trip) = check_limits(&self.cfg.limits, voltage, current, speed) {
            return Ok(Checked::Trip(StopCause::Limit(trip)));
        }
        if let Some((quantity, silent_ns)) = self.latest.silent(t, self.stale) {
            return Ok(Checked::Stop(Stop::Fault(format!(
                "sensor fault: no {quantity} reading for {} ms",
                silent_ns / 1_000_000
            ))));
        }
        Ok(Checked::Reading(Reading { current, speed }))
    }

    async fn command(&mut self, volts: f64) -> Result<Result<(), Stop>, RecordError> {
        if let Err(e) = self.stage.set_setpoint(volts).await {
            return Ok(Err(Stop::Fault(format!("power stage fault: {e}"))));
        }
        let entry = Entry::Samples {
            t_ns: self.t_ns,
            values: vec![(self.ch.command_rec, volts)],
        };
        self.sink.push(entry).await?;
        Ok(Ok(()))
    }

    /// Hold a level until settled (plus the averaging hold) or timeout.
    async fn level(&mut self, volts: f64) -> Result<Result<(), Stop>, RecordError> {
        if let Err(stop) = self.command(volts).await? {
            return Ok(Err(stop));
        }
        let st = self.cfg.settle;
        let window = (st.window_s * self.ch.encoder_rate_hz).round() as usize;
        let mut settle = SettleDetector::new(window, st.tolerance, 2);
        let start = self.t_ns;
        let mut settled_at = None;
        let mut hold_done = None;
        loop {
            let r = match self.read().await? {
                Ok(r) => r,
                Err(stop) => return Ok(Err(stop)),
            };
            let elapsed = (self.t_ns - start) as f64 * 1e-9;
            if let Some(w) = r.speed {
                if settle.push(&[r.current, w]) && elapsed >= st.min_hold_s && settled_at.is_none()
                {
                    settled_at = Some(self.t_ns);
                }
            }
            if let Some(ts) = settled_at {
                if (self.t_ns - ts) as f64 * 1e-9 >= st.hold_s {
                    // End on a reading of every watched channel taken after
                    // the hold, so that none is held over from earlier (a
                    // channel polled slower than the others would otherwise
                    // leave the segment's last instants to be interpolated
                    // towards the next level's readings).
                    let done_at = *hold_done.get_or_insert(self.t_ns);
                    if self.latest.all_since(done_at) {
                        return Ok(Ok(()));
                    }
                }
            }
            if elapsed >= st.timeout_s {
                let msg = format!(
                    "level {volts} V did not settle within {} s; moving on",
                    st.timeout_s
                );
                self.event(EventLevel::Warn, msg).await?;
                return Ok(Ok(()));
            }
        }
    }

    /// Open the armature and record until the rotor rests (no encoder
    /// count for one settle window) or the coast-down timeout.
    async fn coastdown(&mut self) -> Result<Result<(), Stop>, RecordError> {
        if let Err(e) = self.stage.set_output_enabled(false).await {
            return Ok(Err(Stop::Fault(format!("power stage fault: {e}"))));
        }
        self.event(
            EventLevel::Info,
            "armature opened for the coast-down".into(),
        )
        .await?;
        let window = (self.cfg.settle.window_s * self.ch.encoder_rate_hz).round() as usize;
        let start = self.t_ns;
        let mut still = 0usize;
        loop {
            let r = match self.read().await? {
                Ok(r) => r,
                Err(stop) => return Ok(Err(stop)),
            };
            // Only encoder readings count (other channels may come between).
            match r.speed {
                Some(0.0) => still += 1,
                Some(_) => still = 0,
                None => {}
            }
            if still >= window {
                return Ok(Ok(()));
            }
            if (self.t_ns - start) as f64 * 1e-9 >= self.cfg.settle.coastdown_timeout_s {
                let msg = format!(
                    "rotor still turning after {} s of coast-down",
                    self.cfg.settle.coastdown_timeout_s
                );
                self.event(EventLevel::Warn, msg).await?;
                return Ok(Ok(()));
            }
        }
    }

    async fn run(&mut self, steps: &[PlanStep]) -> Result<Outcome, RecordError> {
        // The supply limits its current a little below the trip limit, so a
        // transient peak is held by the supply rather than ending the test.
        let supply_limit = SUPPLY_LIMIT_FRACTION * self.cfg.limits.max_current;
        match self.stage.set_current_limit(supply_limit).await {
            Ok(()) => self.supply = SupplyLimitDetector::new(Some(supply_limit)),
            Err(DriverError::Unsupported { .. }) => {}
            Err(e) => return self.abort(None, format!("power stage fault: {e}")).await,
        }
        let start = async {
            self.stage.set_setpoint(0.0).await?;
            self.stage.set_output_enabled(true).await
        };
        if let Err(e) = start.await {
            return self.abort(None, format!("power stage fault: {e}")).await;
        }
        for (index, step) in steps.iter().enumerate() {
            self.progress.segment(index, steps.len(), step.label());
            self.marker(index, step, SegmentPhase::Start).await?;
            let commanded = match step {
                PlanStep::Level { volts, .. } => Some(*volts),
                PlanStep::Coastdown { .. } => None,
            };
            self.supply.start(index as u32, commanded);
            let result = match step {
                PlanStep::Level { volts, .. } => self.level(*volts).await?,
                PlanStep::Coastdown { .. } => self.coastdown().await?,
            };
            match result {
                Ok(()) => {
                    self.supply_limits(step).await?;
                    self.marker(index, step, SegmentPhase::End).await?;
                }
                Err(Stop::Fault(reason)) => return self.abort(Some((index, step)), reason).await,
            }
        }
        let safe = self.stage.safe_state().await;
        self.sampling_summary().await?;
        let message = match &safe {
            Ok(()) => "test complete; power stage in its safe state".to_string(),
            Err(e) => format!("test complete, but the safe-state command failed: {e}"),
        };
        let level = if safe.is_ok() {
            EventLevel::Info
        } else {
            EventLevel::Warn
        };
        self.event(level, message).await?;
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
            self.sink
                .push(Entry::SupplyLimit {
                    t_ns: self.t_ns,
                    limit,
                })
                .await?;
            self.event(EventLevel::Warn, message).await?;
        }
        Ok(())
    }

    /// The sensors' sampling statistics, one event per channel.
    async fn sampling_summary(&mut self) -> Result<(), RecordError> {
        let stats = self.sensors.sampling_stats();
        let events = self.sampling.summary(&stats, self.sensors.channels());
        for (level, message) in events {
            self.event(level, message).await?;
        }
        Ok(())
    }

    /// Safe state first, then the record of why.
    async fn abort(
        &mut self,
        open: Option<(usize, &PlanStep)>,
        reason: String,
    ) -> Result<Outcome, RecordError> {
        let safe = self.stage.safe_state().await;
        let message = match &safe {
            Ok(()) => format!("{reason}; power stage commanded to its safe state"),
            Err(e) => format!("{reason}; SAFE-STATE COMMAND FAILED: {e}"),
        };
        self.event(EventLevel::Abort, message.clone()).await?;
        if let Some((index, step)) = open {
            self.supply_limits(step).await?;
            self.marker(index, step, SegmentPhase::End).await?;
        }
        self.sampling_summary().await?;
        Ok(Outcome::Aborted { reason: message })
    }
}

/// How a sensor-stream error reads in the abort event: a stop by the
/// safety supervisor (see [`super::supervise`]) is named as such, any
/// other error is a sensor fault.
fn sensor_stop_reason(e: &DriverError) -> String {
    match e {
        DriverError::Device { device, reason } if device == super::SUPERVISOR_ID => {
            format!("stopped by the safety supervisor: {reason}")
        }
        _ => format!("sensor fault: {e}"),
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
    let ch = match Channels::find(sensors.channels()) {
        Ok(ch) => ch,
        Err(e) => {
            let _ = stage.safe_state().await;
            return Err(e);
        }
    };
    // Fifty periods of the slowest channel, at least half a second.
    let slowest_hz = sensors
        .channels()
        .iter()
        .map(|c| c.rate_hz)
        .filter(|r| r.is_finite() && *r > 0.0)
        .fold(cfg.sample_rate_hz, f64::min);
    let stale = Duration::from_secs_f64((50.0 / slowest_hz).max(0.5));
    let mut bench = Bench {
        cfg,
        stage,
        sensors,
        sink,
        progress,
        stops: stops.into(),
        tripped: false,
        ch,
        encoder: SpeedFromEncoder::new(counts_per_rev),
        t_ns: 0,
        stale,
        sampling: SamplingEvents::new(),
        supply: SupplyLimitDetector::new(None),
        latest: Latest::default(),
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
