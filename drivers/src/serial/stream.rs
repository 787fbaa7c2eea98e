//! [`SerialSensors`]: a streaming sensor on a byte stream, as a
//! [`SensorStream`].

use std::collections::VecDeque;

use async_trait::async_trait;
use tokio::io::{AsyncRead, AsyncReadExt};
use tokio::time::Instant;

use super::ascii::AsciiDecoder;
use super::binary::BinaryDecoder;
use super::{DecodeCounts, StreamRecord};
use crate::stats::IntervalStats;
use crate::{
    ChannelInfo, ChannelStats, DriverError, LinkCounts, LinkHealth, Sample, SampleBatch,
    SensorStream,
};

/// Which of the two line protocols a device speaks.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum SerialFraming {
    /// `$MB,…*HH` lines ([`super::ascii`]).
    Ascii,
    /// COBS frames with CRC-16 ([`super::binary`]).
    Binary,
}

/// One channel of a serial sensor.
#[derive(Debug, Clone, PartialEq)]
pub struct SerialChannel {
    /// The value's key in a record: its name (ASCII framing) or its
    /// position from 0 as text (binary framing).
    pub key: String,
    /// What the channel is.
    pub info: ChannelInfo,
}

enum Decoder {
    Ascii(AsciiDecoder),
    Binary(BinaryDecoder),
}

impl Decoder {
    fn feed(&mut self, bytes: &[u8], out: &mut Vec<StreamRecord>) {
        match self {
            Decoder::Ascii(d) => d.feed(bytes, out),
            Decoder::Binary(d) => d.feed(bytes, out),
        }
    }

    fn counts(&self) -> DecodeCounts {
        match self {
            Decoder::Ascii(d) => d.counts(),
            Decoder::Binary(d) => d.counts(),
        }
    }
}

/// A sensor that streams records over a byte stream (a serial port, a
/// PTY). Timestamps come from the device: a record's `t_ns` is the host
/// time of the first record (since this stream was made) plus the device
/// time elapsed since that record, so the device's own sample clock sets
/// the intervals (no host scheduling jitter), while drift between the two
/// clocks is not corrected.
pub struct SerialSensors<T> {
    name: String,
    io: T,
    decoder: Decoder,
    channels: Vec<ChannelInfo>,
    keys: Vec<String>,
    pending: VecDeque<StreamRecord>,
    started: Instant,
    time_base: Option<(u64, u64)>,
    last_seq: Option<u32>,
    stats: Vec<IntervalStats>,
    reported: DecodeCounts,
    warnings: Vec<String>,
    health: LinkHealth,
    lost_records: u64,
}

impl<T> std::fmt::Debug for SerialSensors<T> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("SerialSensors")
            .field("name", &self.name)
            .field("channels", &self.channels)
            .finish()
    }
}

impl<T: AsyncRead + Unpin + Send> SerialSensors<T> {
    /// A stream of `channels` decoded from `io` with `framing`.
    pub fn new(
        name: &str,
        io: T,
        framing: SerialFraming,
        channels: Vec<SerialChannel>,
    ) -> SerialSensors<T> {
        let decoder = match framing {
            SerialFraming::Ascii => Decoder::Ascii(AsciiDecoder::new()),
            SerialFraming::Binary => Decoder::Binary(BinaryDecoder::new()),
        };
        SerialSensors {
            name: name.to_string(),
            io,
            decoder,
            stats: channels
                .iter()
                .enumerate()
                .map(|(k, c)| IntervalStats::new(k, c.info.rate_hz))
                .collect(),
            keys: channels.iter().map(|c| c.key.clone()).collect(),
            channels: channels.into_iter().map(|c| c.info).collect(),
            pending: VecDeque::new(),
            started: Instant::now(),
            time_base: None,
            last_seq: None,
            reported: DecodeCounts::default(),
            warnings: Vec::new(),
            health: LinkHealth::new(name),
            lost_records: 0,
        }
    }

    /// What the decoder decoded and refused so far.
    pub fn decode_counts(&self) -> DecodeCounts {
        self.decoder.counts()
    }

    /// Refused frames and lost records, for [`SensorStream::link_health`].
    fn publish_health(&self) {
        self.health.publish(&LinkCounts {
            decode_errors: self.decoder.counts().rejected,
            lost: self.lost_records,
            ..LinkCounts::default()
        });
    }

    fn batch_of(&mut self, r: StreamRecord) -> SampleBatch {
        let (dev0, host0) = *self
            .time_base
            .get_or_insert_with(|| (r.t_us, self.started.elapsed().as_nanos() as u64));
        let t_ns = host0 + r.t_us.saturating_sub(dev0) * 1000;
        let gap = self
            .last_seq
            .map_or(0, |last| r.seq.wrapping_sub(last).wrapping_sub(1));
        self.last_seq = Some(r.seq);
        // A gap of more than half the sequence space is a device restart
        // or a reordering, not a loss.
        let gap = if gap < u32::MAX / 2 { gap } else { 0 };
        let mut samples = Vec::with_capacity(self.channels.len());
        for (k, key) in self.keys.iter().enumerate() {
            if gap > 0 {
                self.stats[k].lost(u64::from(gap));
            }
            if let Some((_, v)) = r.values.iter().find(|(name, _)| name == key) {
                samples.push(Sample {
                    channel: k,
                    value: *v,
                });
                self.stats[k].received(t_ns);
            }
        }
        if gap > 0 {
            self.lost_records += u64::from(gap);
            self.publish_health();
            self.warnings.push(format!(
                "{}: {gap} record(s) lost before sequence number {}",
                self.name, r.seq
            ));
        }
        SampleBatch { t_ns, samples }
    }
}

#[async_trait]
impl<T: AsyncRead + Unpin + Send> SensorStream for SerialSensors<T> {
    fn id(&self) -> &str {
        &self.name
    }

    fn channels(&self) -> &[ChannelInfo] {
        &self.channels
    }

    async fn next_batch(&mut self) -> Result<SampleBatch, DriverError> {
        loop {
            if let Some(r) = self.pending.pop_front() {
                return Ok(self.batch_of(r));
            }
            let mut buf = [0u8; 1024];
            let n = self
                .io
                .read(&mut buf)
                .await
                .map_err(|e| DriverError::Link {
                    device: self.name.clone(),
                    reason: e.to_string(),
                })?;
            if n == 0 {
                return Err(DriverError::Ended {
                    device: self.name.clone(),
                });
            }
            let mut out = Vec::new();
            self.decoder.feed(&buf[..n], &mut out);
            self.pending.extend(out);
            let c = self.decoder.counts();
            if c.rejected > self.reported.rejected || c.skipped_bytes > self.reported.skipped_bytes
            {
                self.warnings.push(format!(
                    "{}: garbage on the line: {} frame(s) refused, {} byte(s) skipped so far",
                    self.name, c.rejected, c.skipped_bytes
                ));
                self.reported = c;
                self.publish_health();
            }
        }
    }

    fn sampling_stats(&self) -> Vec<ChannelStats> {
        self.stats.iter().map(IntervalStats::summary).collect()
    }

    fn link_health(&self) -> Vec<LinkHealth> {
        vec![self.health.clone()]
    }

    fn take_warnings(&mut self) -> Vec<String> {
        std::mem::take(&mut self.warnings)
    }

    fn epoch(&self) -> Option<Instant> {
        Some(self.started)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::serial::{ascii, binary};
    use tokio::io::AsyncWriteExt;

    fn channels(keys: &[&str]) -> Vec<SerialChannel> {
        keys.iter()
            .map(|k| SerialChannel {
                key: k.to_string(),
                info: ChannelInfo {
                    quantity: format!("q_{k}"),
                    unit: "V".into(),
                    source: "daq".into(),
                    rate_hz: 2000.0,
                },
            })
            .collect()
    }

    fn rec(seq: u32, a: f64) -> StreamRecord {
        StreamRecord {
            seq,
            t_us: 7_000_000 + u64::from(seq) * 500,
            values: vec![("a".into(), a), ("b".into(), -a)],
        }
    }

    #[tokio::test]
    async fn ascii_records_become_batches_on_the_device_clock_and_gaps_count_as_loss() {
        let (mut dev, host) = tokio::io::duplex(4096);
        let mut s = SerialSensors::new("daq", host, SerialFraming::Ascii, channels(&["b", "a"]));
        for seq in [1, 2, 5] {
            dev.write_all(&ascii::encode(&rec(seq, f64::from(seq))))
                .await
                .unwrap();
        }
        dev.write_all(b"garbage$MB,bad*00\r\n").await.unwrap();
        dev.write_all(&ascii::encode(&rec(6, 6.0))).await.unwrap();
        drop(dev);
        let b1 = s.next_batch().await.unwrap();
        assert_eq!(
            b1.samples,
            vec![
                Sample {
                    channel: 0,
                    value: -1.0
                },
                Sample {
                    channel: 1,
                    value: 1.0
                }
            ]
        );
        let b2 = s.next_batch().await.unwrap();
        assert_eq!(b2.t_ns - b1.t_ns, 500_000, "device clock sets the interval");
        let b5 = s.next_batch().await.unwrap();
        assert_eq!(b5.t_ns - b1.t_ns, 2_000_000);
        let _b6 = s.next_batch().await.unwrap();
        assert!(matches!(
            s.next_batch().await,
            Err(DriverError::Ended { .. })
        ));
        let st = s.sampling_stats();
        assert_eq!((st[0].received, st[0].lost), (4, 2));
        let w = s.take_warnings().join("\n");
        assert!(
            w.contains("2 record(s) lost before sequence number 5"),
            "{w}"
        );
        assert!(w.contains("garbage"), "{w}");
        assert_eq!(s.decode_counts().rejected, 1);
        // The link's health says the same, by kind, under the stream's name.
        let health = s.link_health();
        assert_eq!(health.len(), 1);
        assert_eq!(health[0].name(), "daq");
        let c = health[0].counts();
        assert_eq!((c.decode_errors, c.lost, c.timeouts), (1, 2, 0));
    }

    #[tokio::test]
    async fn binary_records_map_by_position() {
        let (mut dev, host) = tokio::io::duplex(4096);
        let mut s = SerialSensors::new("daq", host, SerialFraming::Binary, channels(&["1"]));
        dev.write_all(&[0]).await.unwrap();
        dev.write_all(&binary::encode(&rec(1, 3.5))).await.unwrap();
        let b = s.next_batch().await.unwrap();
        assert_eq!(
            b.samples,
            vec![Sample {
                channel: 0,
                value: -3.5
            }]
        );
    }
}
