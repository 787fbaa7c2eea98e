//! [`MergedSensors`]: several sensor streams as one, for a rig whose
//! instruments sit on separate links (the induction-machine rig's power
//! meter and encoder counter, each its own Modbus server). Each stream
//! keeps its own read in flight; batches are handed on as they arrive,
//! with the channel indices of stream `k` shifted past the channels of the
//! streams before it. A batch therefore carries only one stream's
//! channels: consumers hold the latest value of the others.
//!
//! Data times are each stream's own: streams built together (as
//! [`super::build_im_rig`] does) start their clocks within microseconds.
//! A stream's error ends the merged stream with that error.

use std::future::Future;
use std::pin::Pin;
use std::sync::{Arc, Mutex};

use async_trait::async_trait;
use futures_util::future::select_all;
use motorbench_drivers::{ChannelInfo, ChannelStats, DriverError, SampleBatch, SensorStream};

type Read = Pin<
    Box<
        dyn Future<
                Output = (
                    usize,
                    Box<dyn SensorStream>,
                    Result<SampleBatch, DriverError>,
                ),
            > + Send,
    >,
>;

/// Statistics and warnings of the streams while their reads are in flight.
#[derive(Default)]
struct Telemetry {
    stats: Vec<Vec<ChannelStats>>,
    warnings: Vec<String>,
}

/// Several sensor streams as one; see the module docs.
pub struct MergedSensors {
    id: String,
    channels: Vec<ChannelInfo>,
    offsets: Vec<usize>,
    pending: Vec<Read>,
    telemetry: Arc<Mutex<Telemetry>>,
}

impl std::fmt::Debug for MergedSensors {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("MergedSensors")
            .field("id", &self.id)
            .field("channels", &self.channels)
            .finish()
    }
}

fn lock(t: &Mutex<Telemetry>) -> std::sync::MutexGuard<'_, Telemetry> {
    t.lock().unwrap_or_else(|e| e.into_inner())
}

fn read(k: usize, mut stream: Box<dyn SensorStream>, telemetry: Arc<Mutex<Telemetry>>) -> Read {
    Box::pin(async move {
        let r = stream.next_batch().await;
        let warnings = stream.take_warnings();
        let stats = stream.sampling_stats();
        let mut t = lock(&telemetry);
        t.warnings.extend(warnings);
        if let Some(slot) = t.stats.get_mut(k) {
            *slot = stats;
        }
        drop(t);
        (k, stream, r)
    })
}

impl MergedSensors {
    /// Merge `streams` (in this order) under the id `id`.
    pub fn new(id: &str, streams: Vec<Box<dyn SensorStream>>) -> MergedSensors {
        let mut channels = Vec::new();
        let mut offsets = Vec::new();
        for s in &streams {
            offsets.push(channels.len());
            channels.extend(s.channels().iter().cloned());
        }
        let telemetry = Arc::new(Mutex::new(Telemetry {
            stats: vec![Vec::new(); streams.len()],
            warnings: Vec::new(),
        }));
        let pending = streams
            .into_iter()
            .enumerate()
            .map(|(k, s)| read(k, s, telemetry.clone()))
            .collect();
        MergedSensors {
            id: id.to_string(),
            channels,
            offsets,
            pending,
            telemetry,
        }
    }
}

#[async_trait]
impl SensorStream for MergedSensors {
    fn id(&self) -> &str {
        &self.id
    }

    fn channels(&self) -> &[ChannelInfo] {
        &self.channels
    }

    async fn next_batch(&mut self) -> Result<SampleBatch, DriverError> {
        if self.pending.is_empty() {
            return Err(DriverError::Ended {
                device: self.id.clone(),
            });
        }
        let pending = std::mem::take(&mut self.pending);
        let ((k, stream, result), _, rest) = select_all(pending).await;
        self.pending = rest;
        match result {
            Ok(mut batch) => {
                self.pending.push(read(k, stream, self.telemetry.clone()));
                for s in &mut batch.samples {
                    s.channel += self.offsets[k];
                }
                Ok(batch)
            }
            // The failed stream is dropped; the next call reads the others
            // only if the caller goes on, which the bench does not.
            Err(e) => Err(e),
        }
    }

    fn sampling_stats(&self) -> Vec<ChannelStats> {
        let t = lock(&self.telemetry);
        t.stats
            .iter()
            .enumerate()
            .flat_map(|(k, stats)| {
                let offset = self.offsets[k];
                stats.iter().cloned().map(move |mut s| {
                    s.channel += offset;
                    s
                })
            })
            .collect()
    }

    fn take_warnings(&mut self) -> Vec<String> {
        std::mem::take(&mut lock(&self.telemetry).warnings)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use motorbench_drivers::Sample;

    /// A stream of one channel that delivers `n` batches, one every
    /// `period_ms`, then fails.
    struct Ticks {
        channels: Vec<ChannelInfo>,
        period_ms: u64,
        left: u32,
        t_ns: u64,
    }

    #[async_trait]
    impl SensorStream for Ticks {
        fn id(&self) -> &str {
            "ticks"
        }
        fn channels(&self) -> &[ChannelInfo] {
            &self.channels
        }
        async fn next_batch(&mut self) -> Result<SampleBatch, DriverError> {
            tokio::time::sleep(std::time::Duration::from_millis(self.period_ms)).await;
            if self.left == 0 {
                return Err(DriverError::Ended {
                    device: self.channels[0].quantity.clone(),
                });
            }
            self.left -= 1;
            self.t_ns += self.period_ms * 1_000_000;
            Ok(SampleBatch {
                t_ns: self.t_ns,
                samples: vec![Sample {
                    channel: 0,
                    value: self.t_ns as f64,
                }],
            })
        }
    }

    fn ticks(q: &str, period_ms: u64, left: u32) -> Box<dyn SensorStream> {
        Box::new(Ticks {
            channels: vec![ChannelInfo {
                quantity: q.into(),
                unit: "".into(),
                source: "ticks".into(),
                rate_hz: 1000.0 / period_ms as f64,
            }],
            period_ms,
            left,
            t_ns: 0,
        })
    }

    #[tokio::test(start_paused = true)]
    async fn batches_of_both_streams_arrive_in_time_order_with_shifted_channels() {
        let mut m = MergedSensors::new("m", vec![ticks("a", 10, 100), ticks("b", 25, 100)]);
        assert_eq!(m.channels().len(), 2);
        assert_eq!(m.channels()[1].quantity, "b");
        let mut seen = [0u32; 2];
        let mut last = 0;
        for _ in 0..14 {
            let b = m.next_batch().await.unwrap();
            assert_eq!(b.samples.len(), 1);
            let ch = b.samples[0].channel;
            seen[ch] += 1;
            assert!(b.t_ns >= last, "{} after {last}", b.t_ns);
            last = b.t_ns;
        }
        // 100 ms of paced reads: 10 of `a`, 4 of `b`.
        assert_eq!(seen, [10, 4]);
    }

    #[tokio::test(start_paused = true)]
    async fn an_ending_stream_ends_the_merge_with_its_error() {
        let mut m = MergedSensors::new("m", vec![ticks("a", 10, 100), ticks("b", 15, 1)]);
        let mut result = Ok(());
        for _ in 0..10 {
            if let Err(e) = m.next_batch().await {
                result = Err(e);
                break;
            }
        }
        let e = result.unwrap_err();
        assert!(e.to_string().contains('b'), "{e}");
    }
}
