//! Where every test's readings go ([`RecordSink`]: the recorder and the
//! in-memory record, fed the same entries), the channels every test
//! records, and how a test ends ([`Outcome`], [`BenchError`]).

use motorbench_drivers::ChannelInfo;
use thiserror::Error;

use crate::record::{ChannelSpec, Entry, Record, RecordBuilder, RecordError, Recorder, TestMeta};

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
    /// The safety checks cannot be set up for these sensors.
    #[error("safety monitor: {0}")]
    Safety(#[from] super::MonitorError),
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
