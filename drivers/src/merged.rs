//! [`MergedSensors`]: several sensor streams as one, each source owned by
//! its own task (so one bus never waits on another), their batches put on
//! one time base and delivered in time order.
//!
//! - **Channels**: the sources' channels in order, source after source;
//!   a sample keeps its own source's timestamp (taken by that source as
//!   close to its read as it can), so channels of different sources and
//!   rates are never forced onto a common instant. A batch therefore
//!   carries one source's channels only: a consumer that needs every
//!   channel at once holds the latest value of each.
//! - **Time base**: each source's `t_ns` is relative to its own
//!   [`SensorStream::epoch`]; the merged stream counts from the earliest
//!   of them and shifts every other source by the difference. A source
//!   without an epoch is taken to start when the merge is made.
//! - **Order**: batches wait in a reorder buffer for `reorder` after their
//!   own time before they are delivered, earliest first, so a source whose
//!   batches arrive a little after they were stamped (a Modbus poll stamped
//!   at its midpoint, a serial record stamped by the device) still lands
//!   in order. A batch that arrives later than that, behind a batch already
//!   delivered, is dropped, counted as lost for its channels and reported
//!   as a warning: timestamps are never altered.
//! - **Failure**: the first error of any source ends the merged stream at
//!   once (a pulled cable must stop the test, not wait behind the others).
//! - **Statistics and warnings**: each source's own (received, lost,
//!   jitter, and its warnings), renumbered to the merged channels, plus
//!   the merge's own drops.

use std::cmp::Reverse;
use std::collections::BinaryHeap;
use std::sync::{Arc, Mutex, MutexGuard};

use async_trait::async_trait;
use tokio::sync::mpsc;
use tokio::task::JoinHandle;
use tokio::time::{Duration, Instant};

use crate::{ChannelInfo, ChannelStats, DriverError, LinkHealth, SampleBatch, SensorStream};

/// What a source's task shares with the merged stream besides batches.
#[derive(Debug, Default)]
struct SourceState {
    stats: Vec<ChannelStats>,
    warnings: Vec<String>,
}

fn lock(s: &Mutex<SourceState>) -> MutexGuard<'_, SourceState> {
    s.lock().unwrap_or_else(|e| e.into_inner())
}

enum Message {
    Batch(SampleBatch),
    Failed(DriverError),
}

/// A batch waiting in the reorder buffer: earliest time first, then
/// arrival order.
#[derive(Debug, PartialEq, Eq, PartialOrd, Ord)]
struct Pending {
    t_ns: u64,
    arrival: u64,
    samples: Vec<(usize, u64)>,
}

/// Several sensor streams merged into one. See the module docs.
pub struct MergedSensors {
    id: String,
    channels: Vec<ChannelInfo>,
    epoch: Instant,
    reorder: Duration,
    rx: mpsc::Receiver<Message>,
    pending: BinaryHeap<Reverse<Pending>>,
    arrivals: u64,
    last_delivered: Option<u64>,
    offsets: Vec<usize>,
    states: Vec<Arc<Mutex<SourceState>>>,
    dropped: Vec<u64>,
    warnings: Vec<String>,
    tasks: Vec<JoinHandle<()>>,
    links: Vec<LinkHealth>,
}

impl std::fmt::Debug for MergedSensors {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("MergedSensors")
            .field("id", &self.id)
            .field("channels", &self.channels)
            .field("reorder", &self.reorder)
            .finish()
    }
}

/// Default reorder window: long enough for a poll's round trip or a
/// scheduling delay on a loaded host, short against a limit's reaction.
pub const DEFAULT_REORDER: Duration = Duration::from_millis(10);

impl MergedSensors {
    /// Merge `sources` (channels in this order); batches wait `reorder`
    /// after their time before delivery. Each source moves into its own
    /// task on the current tokio runtime.
    pub fn new(id: &str, sources: Vec<Box<dyn SensorStream>>, reorder: Duration) -> MergedSensors {
        let now = Instant::now();
        let epoch = sources
            .iter()
            .filter_map(|s| s.epoch())
            .min()
            .unwrap_or(now)
            .min(now);
        let mut channels = Vec::new();
        let mut offsets = Vec::new();
        let mut states = Vec::new();
        let mut tasks = Vec::new();
        // Room for a second's worth of batches from fast sources before a
        // source task waits for the consumer.
        let (tx, rx) = mpsc::channel(4096);
        let mut links = Vec::new();
        for mut source in sources {
            links.extend(source.link_health());
            let offset = channels.len();
            offsets.push(offset);
            channels.extend(source.channels().iter().cloned());
            let shift_ns = source
                .epoch()
                .unwrap_or(now)
                .duration_since(epoch)
                .as_nanos() as u64;
            let state = Arc::new(Mutex::new(SourceState::default()));
            states.push(state.clone());
            let tx = tx.clone();
            tasks.push(tokio::spawn(async move {
                loop {
                    let result = source.next_batch().await;
                    {
                        let mut s = lock(&state);
                        s.stats = source.sampling_stats();
                        s.warnings.extend(source.take_warnings());
                    }
                    let message = match result {
                        Ok(mut batch) => {
                            batch.t_ns += shift_ns;
                            for s in &mut batch.samples {
                                s.channel += offset;
                            }
                            Message::Batch(batch)
                        }
                        Err(e) => Message::Failed(e),
                    };
                    let failed = matches!(message, Message::Failed(_));
                    if tx.send(message).await.is_err() || failed {
                        return;
                    }
                }
            }));
        }
        MergedSensors {
            id: id.to_string(),
            dropped: vec![0; channels.len()],
            channels,
            epoch,
            reorder,
            rx,
            pending: BinaryHeap::new(),
            arrivals: 0,
            last_delivered: None,
            offsets,
            states,
            warnings: Vec::new(),
            tasks,
            links,
        }
    }

    fn deliver(&mut self, p: Pending) -> SampleBatch {
        self.last_delivered = Some(p.t_ns);
        SampleBatch {
            t_ns: p.t_ns,
            samples: p
                .samples
                .into_iter()
                .map(|(channel, bits)| crate::Sample {
                    channel,
                    value: f64::from_bits(bits),
                })
                .collect(),
        }
    }

    fn admit(&mut self, batch: SampleBatch) {
        if self.last_delivered.is_some_and(|last| batch.t_ns < last) {
            let behind_ms = (self.last_delivered.unwrap_or(0) - batch.t_ns) as f64 * 1e-6;
            for s in &batch.samples {
                if let Some(d) = self.dropped.get_mut(s.channel) {
                    *d += 1;
                }
            }
            let names: Vec<&str> = batch
                .samples
                .iter()
                .filter_map(|s| self.channels.get(s.channel))
                .map(|c| c.quantity.as_str())
                .collect();
            self.warnings.push(format!(
                "{}: a batch of {} arrived {behind_ms:.1} ms behind one already delivered (reorder window {} ms): dropped",
                self.id,
                names.join(", "),
                self.reorder.as_millis()
            ));
            return;
        }
        self.arrivals += 1;
        self.pending.push(Reverse(Pending {
            t_ns: batch.t_ns,
            arrival: self.arrivals,
            samples: batch
                .samples
                .iter()
                .map(|s| (s.channel, s.value.to_bits()))
                .collect(),
        }));
    }
}

impl Drop for MergedSensors {
    fn drop(&mut self) {
        for t in &self.tasks {
            t.abort();
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
        loop {
            // Take whatever has already arrived before deciding.
            while let Ok(m) = self.rx.try_recv() {
                match m {
                    Message::Batch(batch) => self.admit(batch),
                    Message::Failed(e) => return Err(e),
                }
            }
            let release = self
                .pending
                .peek()
                .map(|Reverse(p)| self.epoch + Duration::from_nanos(p.t_ns) + self.reorder);
            if let Some(at) = release {
                if Instant::now() >= at {
                    let Some(Reverse(p)) = self.pending.pop() else {
                        continue;
                    };
                    return Ok(self.deliver(p));
                }
            }
            tokio::select! {
                m = self.rx.recv() => match m {
                    Some(Message::Batch(batch)) => self.admit(batch),
                    Some(Message::Failed(e)) => return Err(e),
                    None => {
                        return Err(DriverError::Ended {
                            device: self.id.clone(),
                        })
                    }
                },
                _ = tokio::time::sleep_until(release.unwrap_or_else(Instant::now)), if release.is_some() => {}
            }
        }
    }

    fn sampling_stats(&self) -> Vec<ChannelStats> {
        let mut out = Vec::new();
        for (state, &offset) in self.states.iter().zip(&self.offsets) {
            for s in &lock(state).stats {
                let mut s = s.clone();
                s.channel += offset;
                let dropped = self.dropped.get(s.channel).copied().unwrap_or(0);
                s.received = s.received.saturating_sub(dropped);
                s.lost += dropped;
                out.push(s);
            }
        }
        out
    }

    fn link_health(&self) -> Vec<LinkHealth> {
        self.links.clone()
    }

    fn take_warnings(&mut self) -> Vec<String> {
        let mut out = Vec::new();
        for state in &self.states {
            out.append(&mut lock(state).warnings);
        }
        out.append(&mut self.warnings);
        out
    }

    fn epoch(&self) -> Option<Instant> {
        Some(self.epoch)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{IntervalStats, Sample};

    /// A source that delivers scripted batches at given host times
    /// (relative to its epoch), stamped with given times.
    struct Scripted {
        id: String,
        channels: Vec<ChannelInfo>,
        epoch: Instant,
        /// (deliver at, stamped t_ns, value) per batch; one channel.
        script: Vec<(u64, u64, f64)>,
        next: usize,
        stats: IntervalStats,
        fail_at_end: bool,
    }

    fn info(q: &str, rate: f64) -> ChannelInfo {
        ChannelInfo {
            quantity: q.into(),
            unit: "".into(),
            source: "test".into(),
            rate_hz: rate,
        }
    }

    fn scripted(q: &str, epoch: Instant, script: Vec<(u64, u64, f64)>) -> Box<Scripted> {
        Box::new(Scripted {
            id: q.into(),
            channels: vec![info(q, 100.0)],
            epoch,
            script,
            next: 0,
            stats: IntervalStats::new(0, 100.0),
            fail_at_end: false,
        })
    }

    #[async_trait]
    impl SensorStream for Scripted {
        fn id(&self) -> &str {
            &self.id
        }
        fn channels(&self) -> &[ChannelInfo] {
            &self.channels
        }
        async fn next_batch(&mut self) -> Result<SampleBatch, DriverError> {
            let Some(&(at, t_ns, value)) = self.script.get(self.next) else {
                if self.fail_at_end {
                    return Err(DriverError::Link {
                        device: self.id.clone(),
                        reason: "cable pulled".into(),
                    });
                }
                std::future::pending::<()>().await;
                unreachable!()
            };
            tokio::time::sleep_until(self.epoch + Duration::from_nanos(at)).await;
            self.next += 1;
            self.stats.received(t_ns);
            Ok(SampleBatch {
                t_ns,
                samples: vec![Sample { channel: 0, value }],
            })
        }
        fn sampling_stats(&self) -> Vec<ChannelStats> {
            vec![self.stats.summary()]
        }
        fn take_warnings(&mut self) -> Vec<String> {
            if self.next == 2 {
                vec![format!("{}: second batch", self.id)]
            } else {
                Vec::new()
            }
        }
        fn epoch(&self) -> Option<Instant> {
            Some(self.epoch)
        }
        fn link_health(&self) -> Vec<LinkHealth> {
            vec![LinkHealth::new(&self.id)]
        }
    }

    const MS: u64 = 1_000_000;

    #[tokio::test(start_paused = true)]
    async fn batches_come_in_time_order_on_one_time_base() {
        let t0 = Instant::now();
        // Source b starts 3 ms after source a: its times shift by 3 ms.
        let a = scripted("a", t0, vec![(2 * MS, MS, 1.0), (12 * MS, 11 * MS, 2.0)]);
        let b = scripted(
            "b",
            t0 + Duration::from_millis(3),
            // Stamped 0 and 5 ms on b's clock (3 and 8 ms merged), the
            // first delivered late (at 6 ms merged): still in order.
            vec![(3 * MS, 0, 10.0), (5 * MS, 5 * MS, 20.0)],
        );
        let mut m = MergedSensors::new("merged", vec![a, b], Duration::from_millis(5));
        assert_eq!(m.channels().len(), 2);
        assert_eq!(m.channels()[1].quantity, "b");
        let mut got = Vec::new();
        for _ in 0..4 {
            let batch = m.next_batch().await.unwrap();
            got.push((batch.t_ns, batch.samples[0].channel, batch.samples[0].value));
        }
        assert_eq!(
            got,
            vec![
                (MS, 0, 1.0),
                (3 * MS, 1, 10.0),
                (8 * MS, 1, 20.0),
                (11 * MS, 0, 2.0)
            ]
        );
        let stats = m.sampling_stats();
        assert_eq!(stats.len(), 2);
        assert_eq!((stats[1].channel, stats[1].received), (1, 2));
        let w = m.take_warnings();
        assert!(w.contains(&"a: second batch".to_string()), "{w:?}");
        assert!(w.contains(&"b: second batch".to_string()), "{w:?}");
        assert_eq!(m.epoch(), Some(t0));
        let links: Vec<String> = m.link_health().iter().map(|l| l.name().into()).collect();
        assert_eq!(links, ["a", "b"], "every source's links, in order");
    }

    #[tokio::test(start_paused = true)]
    async fn a_batch_behind_the_reorder_window_is_dropped_and_counted() {
        let t0 = Instant::now();
        let a = scripted("a", t0, vec![(MS, MS, 1.0), (30 * MS, 30 * MS, 2.0)]);
        // Stamped at 2 ms but arrives at 20 ms: after a's 1 ms batch and…
        let b = scripted("b", t0, vec![(20 * MS, 2 * MS, 10.0)]);
        let mut m = MergedSensors::new("merged", vec![a, b], Duration::from_millis(5));
        let first = m.next_batch().await.unwrap();
        assert_eq!(first.t_ns, MS);
        // …its 2 ms stamp is still ahead of the 1 ms delivered: kept.
        let second = m.next_batch().await.unwrap();
        assert_eq!((second.t_ns, second.samples[0].channel), (2 * MS, 1));

        let a = scripted("a", t0, vec![(MS, MS, 1.0), (10 * MS, 10 * MS, 2.0)]);
        let b = scripted(
            "b",
            t0,
            vec![(40 * MS, 5 * MS, 10.0), (50 * MS, 50 * MS, 11.0)],
        );
        let mut m = MergedSensors::new("merged", vec![a, b], Duration::from_millis(5));
        assert_eq!(m.next_batch().await.unwrap().t_ns, MS);
        assert_eq!(m.next_batch().await.unwrap().t_ns, 10 * MS);
        // b's 5 ms batch comes at 40 ms, behind 10 ms: dropped, and the
        // next one is delivered.
        let next = m.next_batch().await.unwrap();
        assert_eq!((next.t_ns, next.samples[0].value), (50 * MS, 11.0));
        let stats = m.sampling_stats();
        assert_eq!((stats[1].received, stats[1].lost), (1, 1));
        let w = m.take_warnings();
        assert!(
            w.iter().any(|w| w.contains("b arrived 5.0 ms behind")),
            "{w:?}"
        );
    }

    #[tokio::test(start_paused = true)]
    async fn a_failed_source_ends_the_stream_at_once() {
        let t0 = Instant::now();
        let a = scripted("a", t0, (1..100).map(|k| (k * MS, k * MS, 0.0)).collect());
        let mut b = scripted("b", t0, vec![(5 * MS, 5 * MS, 1.0)]);
        b.fail_at_end = true;
        let mut m = MergedSensors::new("merged", vec![a, b], Duration::from_millis(5));
        let mut delivered = 0;
        let err = loop {
            match m.next_batch().await {
                Ok(_) => delivered += 1,
                Err(e) => break e,
            }
        };
        assert!(err.is_link_failure(), "{err}");
        assert!(delivered < 10, "{delivered} batches after the failure");
    }
}
