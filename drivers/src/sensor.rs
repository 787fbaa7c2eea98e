//! The [`SensorStream`] trait: timestamped samples of named channels.

use async_trait::async_trait;

use crate::{ChannelStats, DriverError, LinkHealth};

/// Static description of one channel a stream delivers.
#[derive(Debug, Clone, PartialEq)]
pub struct ChannelInfo {
    /// The quantity measured, as a free-form name (the caller maps it).
    pub quantity: String,
    /// SI unit of the values.
    pub unit: String,
    /// Driver id of the device that measures it.
    pub source: String,
    /// Nominal sampling rate in hertz.
    pub rate_hz: f64,
}

/// One reading of one channel.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Sample {
    /// Index of the channel in [`SensorStream::channels`].
    pub channel: usize,
    /// Value in the channel's unit.
    pub value: f64,
}

/// Readings taken at one instant.
#[derive(Debug, Clone, PartialEq)]
pub struct SampleBatch {
    /// Nanoseconds since the stream started.
    pub t_ns: u64,
    /// The readings taken at `t_ns`.
    pub samples: Vec<Sample>,
}

impl SampleBatch {
    /// The reading of `channel` in this batch, if it has one.
    pub fn value(&self, channel: usize) -> Option<f64> {
        self.samples
            .iter()
            .find(|s| s.channel == channel)
            .map(|s| s.value)
    }
}

/// A source of timestamped samples.
///
/// `next_batch` waits for the next instant at which readings are available.
/// A simulated backend advances its virtual clock there; a hardware backend
/// waits for the device.
#[async_trait]
pub trait SensorStream: Send {
    /// Driver id of the stream.
    fn id(&self) -> &str;

    /// The channels this stream delivers, indexed by [`Sample::channel`].
    fn channels(&self) -> &[ChannelInfo];

    /// Wait for and return the next batch of readings.
    async fn next_batch(&mut self) -> Result<SampleBatch, DriverError>;

    /// Sampling statistics per channel so far (received, lost, jitter).
    /// Streams that keep none return an empty list (the default).
    fn sampling_stats(&self) -> Vec<ChannelStats> {
        Vec::new()
    }

    /// The health of the links this stream reads itself (a serial line, a
    /// CAN interface): errors by kind, for the daemon's metrics. Streams
    /// that poll through a bus task owned elsewhere (Modbus: the rig
    /// reports the bus) and simulated streams return none (the default).
    fn link_health(&self) -> Vec<LinkHealth> {
        Vec::new()
    }

    /// Warnings raised since the last call (lost readings, a late poll,
    /// garbage on the line), for the caller to record. Default: none.
    fn take_warnings(&mut self) -> Vec<String> {
        Vec::new()
    }

    /// The host instant `t_ns = 0` stands for, when the stream's times are
    /// host times (so that streams can be put on one time base: see
    /// [`crate::MergedSensors`]). Streams on a virtual clock return `None`
    /// (the default).
    fn epoch(&self) -> Option<tokio::time::Instant> {
        None
    }

    /// True when the readings come from a simulation on a virtual clock
    /// that advances only as the stream is read: nothing outside moves
    /// between reads, so a reader may take batches no faster than its
    /// consumer does. A live source (the default) must be read on
    /// regardless: a consumer that falls behind it has stalled.
    fn virtual_clock(&self) -> bool {
        false
    }
}
