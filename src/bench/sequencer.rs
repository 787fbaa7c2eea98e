//! The one reading path of every test: both test plans, the DC step plan
//! ([`super::run_test`]) and the induction-machine slip sweep
//! ([`super::run_im_sweep`]), read their sensors through a [`Sequencer`],
//! under `motorbench run` and under the daemon alike.
//!
//! Each read waits for the next batch *or* an operator stop, whichever
//! comes first (a stop never waits for a batch), and for at most the
//! stale-data timeout (a silent sensor ends the test rather than stalling
//! it). Every batch is recorded (with the speed derived from the encoder
//! count), the sensors' sampling warnings become events, and the batch is
//! checked synchronously with the test's [`SafetyMonitor`], the same
//! checks the daemon's supervisor task makes. A check failed under the
//! supervisor is handed to it (see [`StopPath`]): it latches the rig and
//! ends the stream after a batch read in the safe state, which is still
//! recorded. Without a supervisor the plan ends the test as aborted, and
//! [`safe_state_all`] commands every stage to its safe state *before* the
//! cause is recorded.

use std::time::Duration;

use motorbench_drivers::{DriverError, PowerStage, SampleBatch, SensorStream};
use tokio::sync::watch;

use super::{Progress, RecordSink, SafetyMonitor, SamplingEvents, SpeedFromEncoder, StopCause};
use super::{StopPath, StuckDetector, SUPERVISOR_ID};
use crate::record::{
    Entry, Event, EventLevel, RecordError, SegmentKind, SegmentMarker, SegmentPhase,
};

/// Why a test cannot go on.
#[derive(Debug)]
pub(crate) enum Halt {
    /// A fault, a trip or a stop: the test ends as aborted, for this reason.
    Fault(String),
    /// Recording failed: the test cannot go on without losing data.
    Record(RecordError),
}

impl From<RecordError> for Halt {
    fn from(e: RecordError) -> Halt {
        Halt::Record(e)
    }
}

/// One batch as read: recorded and checked.
pub(crate) struct Read {
    /// The batch.
    pub batch: SampleBatch,
    /// The speed derived from its encoder count, rad/s, when there is one.
    pub speed: Option<f64>,
}

/// Where the plan's channels are in the record.
#[derive(Debug, Clone, Copy)]
pub(crate) struct SpeedChannel {
    /// The sensor channel of the encoder count.
    pub encoder: usize,
    /// The record channel of the derived speed.
    pub speed_rec: usize,
    /// Encoder counts per revolution.
    pub counts_per_rev: f64,
}

/// What one batch brought.
enum Checked {
    Batch(Read),
    Stop(String),
    Trip(StopCause),
}

/// The reading core of a test. See the module docs.
pub(crate) struct Sequencer<'a> {
    sensors: &'a mut dyn SensorStream,
    sink: &'a mut RecordSink,
    progress: &'a dyn Progress,
    stops: StopPath<'a>,
    /// The operator's stop flag (unsupervised tests).
    operator: Option<watch::Receiver<bool>>,
    monitor: SafetyMonitor,
    stale: Duration,
    speed: SpeedChannel,
    encoder: SpeedFromEncoder,
    sampling: SamplingEvents,
    /// The stuck-sensor warning, when configured.
    stuck: Option<StuckDetector>,
    t_ns: u64,
    /// The supervisor has taken a trip of ours: record on, check nothing,
    /// until it ends the stream.
    tripped: bool,
}

/// The stale-data timeout of a stream whose channels run at `rates_hz`
/// (and nominally at `nominal_hz`): fifty periods of the slowest, at least
/// half a second.
pub(crate) fn stale_timeout(rates_hz: impl Iterator<Item = f64>, nominal_hz: f64) -> Duration {
    let slowest = rates_hz
        .filter(|r| r.is_finite() && *r > 0.0)
        .fold(nominal_hz, f64::min);
    let periods = if slowest.is_finite() && slowest > 0.0 {
        50.0 / slowest
    } else {
        0.0
    };
    Duration::from_secs_f64(periods.max(0.5))
}

impl<'a> Sequencer<'a> {
    /// A sequencer reading `sensors` into `sink`, checking with `monitor`;
    /// `nominal_hz` is the rig's sample rate (for the stale timeout).
    pub fn new(
        sensors: &'a mut dyn SensorStream,
        sink: &'a mut RecordSink,
        progress: &'a dyn Progress,
        stops: StopPath<'a>,
        monitor: SafetyMonitor,
        speed: SpeedChannel,
        nominal_hz: f64,
    ) -> Sequencer<'a> {
        let stale = stale_timeout(sensors.channels().iter().map(|c| c.rate_hz), nominal_hz);
        let stuck = monitor.supervision().stuck_after.map(|after| {
            let quantities = sensors.channels().iter().map(|c| c.quantity.clone());
            StuckDetector::new(quantities.collect(), after)
        });
        Sequencer {
            stuck,
            operator: stops.operator_flag(),
            sensors,
            sink,
            progress,
            stops,
            monitor,
            stale,
            encoder: SpeedFromEncoder::new(speed.counts_per_rev),
            speed,
            sampling: SamplingEvents::new(),
            t_ns: 0,
            tripped: false,
        }
    }

    /// Data time of the latest batch, ns.
    pub fn t_ns(&self) -> u64 {
        self.t_ns
    }

    /// Record one entry (an operating point also goes to the progress
    /// display).
    pub async fn push(&mut self, entry: Entry) -> Result<(), RecordError> {
        let point = match &entry {
            Entry::OperatingPoint { point, .. } => Some(*point),
            _ => None,
        };
        self.sink.push(entry).await?;
        if let Some(p) = point {
            self.progress.operating_point(&p);
        }
        Ok(())
    }

    /// Record an event at the latest data time.
    pub async fn event(&mut self, level: EventLevel, message: String) -> Result<(), RecordError> {
        let t_ns = self.t_ns;
        self.progress.event(t_ns as f64 * 1e-9, level, &message);
        self.push(Entry::Event {
            t_ns,
            event: Event { level, message },
        })
        .await
    }

    /// Record a segment marker at the latest data time.
    pub async fn marker(
        &mut self,
        index: usize,
        kind: SegmentKind,
        phase: SegmentPhase,
        label: &str,
    ) -> Result<(), RecordError> {
        let marker = SegmentMarker {
            index: index as u32,
            kind,
            phase,
            label: label.to_string(),
        };
        let t_ns = self.t_ns;
        self.push(Entry::Segment { t_ns, marker }).await
    }

    /// Record a command value on record channel `channel`.
    pub async fn command(&mut self, channel: usize, value: f64) -> Result<(), RecordError> {
        let t_ns = self.t_ns;
        if let Some(s) = &mut self.stuck {
            s.command(t_ns);
        }
        self.push(Entry::Samples {
            t_ns,
            values: vec![(channel, value)],
        })
        .await
    }

    /// The segment `index` of `total` started (progress display).
    pub fn segment(&self, index: usize, total: usize, label: &str) {
        self.progress.segment(index, total, label);
    }

    /// The next batch, recorded and checked. A check failed under the
    /// supervisor is handed to it; the batches it then delivers up to the
    /// end of the stream are recorded, and its stop is returned.
    pub async fn next(&mut self) -> Result<Read, Halt> {
        loop {
            match self.read_one().await? {
                Checked::Batch(_) if self.tripped => {}
                Checked::Batch(read) => return Ok(read),
                Checked::Stop(reason) => return Err(Halt::Fault(reason)),
                Checked::Trip(cause) => {
                    if !self.stops.trip(cause.clone(), self.t_ns).await {
                        return Err(Halt::Fault(trip_reason(&cause)));
                    }
                    self.tripped = true;
                }
            }
        }
    }

    /// One batch (or the stop that came first), recorded and, unless
    /// tripped, checked.
    async fn read_one(&mut self) -> Result<Checked, RecordError> {
        let stale = self.stale;
        let read = tokio::select! {
            biased;
            () = stop_requested(&mut self.operator) => {
                return Ok(Checked::Stop("operator stop".into()));
            }
            read = tokio::time::timeout(stale, self.sensors.next_batch()) => read,
        };
        let batch = match read {
            Err(_) => {
                return Ok(Checked::Stop(format!(
                    "sensor stream {} delivered nothing for {} ms",
                    self.sensors.id(),
                    stale.as_millis()
                )))
            }
            Ok(Err(e)) => return Ok(Checked::Stop(sensor_stop_reason(&e))),
            Ok(Ok(batch)) => batch,
        };
        self.t_ns = self.t_ns.max(batch.t_ns);
        let mut values: Vec<(usize, f64)> =
            batch.samples.iter().map(|s| (s.channel, s.value)).collect();
        let speed = batch
            .value(self.speed.encoder)
            .and_then(|count| self.encoder.update(batch.t_ns, count));
        if let Some(w) = speed {
            values.push((self.speed.speed_rec, w));
        }
        self.sink
            .push(Entry::Samples {
                t_ns: batch.t_ns,
                values,
            })
            .await?;
        self.progress.tick(self.t_ns as f64 * 1e-9);
        for message in self.sampling.admit(self.sensors.take_warnings()) {
            self.event(EventLevel::Warn, message).await?;
        }
        let stuck = match &mut self.stuck {
            Some(s) if !self.tripped => s.check(&batch),
            _ => Vec::new(),
        };
        for message in stuck {
            self.event(EventLevel::Warn, message).await?;
        }
        if !self.tripped {
            if let Err(cause) = self.monitor.check(&batch) {
                return Ok(Checked::Trip(cause));
            }
        }
        Ok(Checked::Batch(Read { batch, speed }))
    }

    /// Hand a fault the plan saw itself (a command refused or failed) to
    /// the supervisor as a device fault, so that it commands the safe
    /// state (escalating if a stage ignores it), records the stop and
    /// latches the rig as for its own trips. A stop of the supervisor's
    /// own is not handed back. `false` without a supervisor.
    pub async fn hand_over(&mut self, reason: &str) -> bool {
        if reason.starts_with("stopped by the safety supervisor") {
            return false;
        }
        let cause = StopCause::DeviceFault(reason.to_string());
        self.stops.trip(cause, self.t_ns).await
    }

    /// The sensors' sampling statistics, one event per channel.
    pub async fn sampling_summary(&mut self) -> Result<(), RecordError> {
        let stats = self.sensors.sampling_stats();
        let events = self.sampling.summary(&stats, self.sensors.channels());
        for (level, message) in events {
            self.event(level, message).await?;
        }
        Ok(())
    }
}

/// Resolves once the operator's flag is raised; never without a flag (or
/// once its sender is gone).
async fn stop_requested(flag: &mut Option<watch::Receiver<bool>>) {
    if let Some(rx) = flag {
        if rx.wait_for(|stop| *stop).await.is_ok() {
            return;
        }
    }
    std::future::pending().await
}

/// The abort reason of a failed check: a stale channel is a sensor fault.
fn trip_reason(cause: &StopCause) -> String {
    match cause {
        StopCause::StaleChannel { .. } => format!("sensor fault: {cause}"),
        _ => cause.to_string(),
    }
}

/// How a sensor-stream error reads in the abort event: a stop by the
/// safety supervisor (see [`super::supervise`]) is named as such, any
/// other error is a sensor fault.
fn sensor_stop_reason(e: &DriverError) -> String {
    driver_stop_reason("sensor", e)
}

/// How a driver's error reads in the abort event: a stop by the safety
/// supervisor (a stream ended or a command refused after the stop) is
/// named as such, any other error as a fault of `what` (`sensor`,
/// `power stage`).
pub fn driver_stop_reason(what: &str, e: &DriverError) -> String {
    match e {
        DriverError::Device { device, reason } if device == SUPERVISOR_ID => {
            format!("stopped by the safety supervisor: {reason}")
        }
        _ => format!("{what} fault: {e}"),
    }
}

/// Command every stage to its safe state at once (the commands go out in
/// the order given: put the stage that feeds the machine first); each
/// stage's result, in that order.
pub(crate) async fn safe_state_all(
    stages: &mut [&mut dyn PowerStage],
) -> Vec<Result<(), DriverError>> {
    futures_util::future::join_all(stages.iter_mut().map(|s| s.safe_state())).await
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_command_the_supervisor_refused_names_the_supervisor_not_a_fault() {
        let refused = DriverError::Device {
            device: SUPERVISOR_ID.into(),
            reason: "set point refused after the stop: operator abort".into(),
        };
        assert_eq!(
            driver_stop_reason("power stage", &refused),
            "stopped by the safety supervisor: set point refused after the stop: operator abort"
        );
        let broken = DriverError::Device {
            device: "supply".into(),
            reason: "no reply".into(),
        };
        let reason = driver_stop_reason("power stage", &broken);
        assert!(reason.starts_with("power stage fault: "), "{reason}");
        assert!(sensor_stop_reason(&broken).starts_with("sensor fault: "));
    }
}
