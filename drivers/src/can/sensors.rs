//! [`CanSignalSensors`]: signals of a DBC file, received over any
//! [`FrameStream`], as a [`SensorStream`].
//!
//! Each received frame that carries configured signals becomes one batch.
//! CAN frames carry no time of their own and reach the host in bursts, so
//! a configured message is taken as periodic (at its channel's rate, as a
//! CANopen TPDO on its event timer) and stamped with its estimated send
//! time ([`PeriodicStamp`]): on the message's send grid, never after its
//! arrival. A CANopen PDO carries no sequence number either, so frames are
//! taken as delivered in order and none lost unless the message falls
//! silent for longer than [`RESYNC_SILENCE_S`] (and ten periods), or the
//! frames after a shorter silence come at the message's period instead
//! of in a burst ([`PeriodicStamp`]): a host that stalls for
//! a few periods (seen here: 21 ms on a loaded machine) then receives the
//! waiting frames in one burst, and they must count as late, not lost, or
//! the speed derived from them would jump. The frames after a short loss
//! are only known to follow a loss a few frames later ([`LagRun`]): until
//! then they are held back (a few periods), then restamped on the grid
//! after the loss, so none arrives behind the other streams and is
//! dropped as late. Garbage on an adapter's line
//! ([`FrameStream::malformed`]) is warned of and counted as the link's
//! decode errors. The jitter statistics are those of the arrivals (what
//! the link did).

use std::collections::VecDeque;

use async_trait::async_trait;
use tokio::time::Instant;

use super::stamp::{LagRun, PeriodicStamp};
use super::{CanId, FrameStream, SignalMap};
use crate::stats::IntervalStats;
use crate::{
    ChannelInfo, ChannelStats, DriverError, LinkCounts, LinkHealth, Sample, SampleBatch,
    SensorStream,
};

/// One channel: a DBC signal.
#[derive(Debug, Clone, PartialEq)]
pub struct CanChannel {
    /// The signal's name in the DBC file.
    pub signal: String,
    /// What the channel is (`rate_hz` is the message's nominal rate).
    pub info: ChannelInfo,
}

/// DBC signals received over a frame stream.
pub struct CanSignalSensors<F> {
    name: String,
    frames: F,
    map: SignalMap,
    channels: Vec<ChannelInfo>,
    /// Per channel: the message id and signal name.
    wiring: Vec<(CanId, String)>,
    started: Instant,
    stats: Vec<IntervalStats>,
    stamps: Vec<PeriodicStamp>,
    warnings: Vec<String>,
    health: LinkHealth,
    lost_frames: u64,
    /// Malformed lines of the interface reported so far.
    malformed: u64,
    /// Per message: frames of a run at a steady lag, held until the run
    /// is known to follow a loss or not, with their arrival times (ns).
    held: Vec<(CanId, Vec<(SampleBatch, u64)>)>,
    /// Batches ready to hand out, oldest first.
    ready: VecDeque<SampleBatch>,
}

/// A silence of a message longer than this (and than ten of its periods)
/// counts as lost frames; shorter ones as a late delivery, s.
pub const RESYNC_SILENCE_S: f64 = 0.25;

impl<F> std::fmt::Debug for CanSignalSensors<F> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("CanSignalSensors")
            .field("name", &self.name)
            .field("channels", &self.channels)
            .finish()
    }
}

impl<F: FrameStream> CanSignalSensors<F> {
    /// Channels of `map`'s signals, received on `frames`; an error names a
    /// signal the file does not have.
    pub fn new(
        name: &str,
        frames: F,
        map: SignalMap,
        channels: Vec<CanChannel>,
    ) -> Result<CanSignalSensors<F>, DriverError> {
        let mut wiring = Vec::new();
        for c in &channels {
            let (id, _) = map
                .find(&c.signal)
                .ok_or_else(|| DriverError::Unsupported {
                    device: name.to_string(),
                    what: "a signal that is not in its DBC file",
                })?;
            wiring.push((id, c.signal.clone()));
        }
        Ok(CanSignalSensors {
            name: name.to_string(),
            frames,
            map,
            stats: channels
                .iter()
                .enumerate()
                .map(|(k, c)| IntervalStats::new(k, c.info.rate_hz))
                .collect(),
            stamps: channels
                .iter()
                .map(|c| {
                    PeriodicStamp::new(
                        c.info.rate_hz,
                        (RESYNC_SILENCE_S * c.info.rate_hz).max(10.0),
                    )
                })
                .collect(),
            channels: channels.into_iter().map(|c| c.info).collect(),
            wiring,
            started: Instant::now(),
            warnings: Vec::new(),
            health: LinkHealth::new(name),
            lost_frames: 0,
            malformed: 0,
            held: Vec::new(),
            ready: VecDeque::new(),
        })
    }
}

impl<F> CanSignalSensors<F> {
    /// Hand `batch` (of message `id`, arrived at `arrival_ns`) on, or hold
    /// it, as its place in a run at a steady lag says ([`LagRun`]).
    fn settle(
        &mut self,
        id: CanId,
        batch: SampleBatch,
        arrival_ns: u64,
        run: LagRun,
        period_ns: f64,
    ) {
        let at = match self.held.iter().position(|(held_id, _)| *held_id == id) {
            Some(at) => at,
            None => {
                self.held.push((id, Vec::new()));
                self.held.len() - 1
            }
        };
        let held = &mut self.held[at].1;
        match run {
            LagRun::None => {
                self.ready.extend(held.drain(..).map(|(b, _)| b));
                self.ready.push_back(batch);
            }
            LagRun::Open(n) => {
                let others = held.len().saturating_sub(n as usize - 1);
                self.ready.extend(held.drain(..others).map(|(b, _)| b));
                held.push((batch, arrival_ns));
            }
            LagRun::Loss => {
                // The run's frames were sent a period apart up to this one:
                // on the new grid, never before their old stamps (the
                // stream stays in order) nor after their arrivals.
                let n = held.len();
                for (j, (mut b, arrived)) in held.drain(..).enumerate() {
                    let back = (n - j) as f64 * period_ns;
                    let t = (batch.t_ns as f64 - back).max(0.0).round() as u64;
                    b.t_ns = t.clamp(b.t_ns, arrived.max(b.t_ns));
                    self.ready.push_back(b);
                }
                self.ready.push_back(batch);
            }
        }
    }

    fn publish_health(&self) {
        self.health.publish(&LinkCounts {
            lost: self.lost_frames,
            decode_errors: self.malformed,
            ..LinkCounts::default()
        });
    }
}

#[async_trait]
impl<F: FrameStream> SensorStream for CanSignalSensors<F> {
    fn id(&self) -> &str {
        &self.name
    }

    fn channels(&self) -> &[ChannelInfo] {
        &self.channels
    }

    async fn next_batch(&mut self) -> Result<SampleBatch, DriverError> {
        loop {
            if let Some(batch) = self.ready.pop_front() {
                return Ok(batch);
            }
            let frame = self.frames.recv().await?;
            let arrival_ns = self.started.elapsed().as_nanos() as u64;
            let malformed = self.frames.malformed();
            if malformed > self.malformed {
                self.malformed = malformed;
                self.publish_health();
                self.warnings.push(format!(
                    "{}: garbage on the line: {malformed} line(s) refused so far",
                    self.name
                ));
            }
            let Some(decoded) = self.map.decode(&frame) else {
                continue;
            };
            let mut samples = Vec::new();
            let mut t_ns = None;
            let mut run = None;
            for (k, (id, signal)) in self.wiring.iter().enumerate() {
                if *id != frame.id() {
                    continue;
                }
                if let Some(s) = decoded.iter().find(|s| &s.name == signal) {
                    let stamped = self.stamps[k].arrived(arrival_ns);
                    if stamped.lost > 0 {
                        self.stats[k].lost(stamped.lost);
                        // A frame's signals share its loss: count it once.
                        if t_ns.is_none() {
                            self.lost_frames += stamped.lost;
                        }
                        self.publish_health();
                        self.warnings.push(format!(
                            "{}: {} frame(s) of {signal} missing (a gap in its send grid)",
                            self.name, stamped.lost
                        ));
                    }
                    // One instant per frame: its first channel's estimate.
                    t_ns.get_or_insert(stamped.t_ns);
                    run.get_or_insert((stamped.run, self.stamps[k].period_ns()));
                    self.stats[k].received(arrival_ns);
                    samples.push(Sample {
                        channel: k,
                        value: s.value,
                    });
                }
            }
            if let (false, Some(t_ns), Some((run, period_ns))) = (samples.is_empty(), t_ns, run) {
                let batch = SampleBatch { t_ns, samples };
                self.settle(frame.id(), batch, arrival_ns, run, period_ns);
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
    use crate::can::InProcessBus;

    /// The shipped CiA 406 encoder's DBC file.
    fn encoder_dbc() -> SignalMap {
        let path = concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../config/devices/cia406-encoder.dbc"
        );
        SignalMap::parse(path, &std::fs::read_to_string(path).unwrap()).unwrap()
    }

    /// Its position at 1 kHz as the one channel `name` reads on `frames`.
    fn positions<F: FrameStream>(name: &str, frames: F, map: &SignalMap) -> CanSignalSensors<F> {
        let info = ChannelInfo {
            quantity: "encoder_count".into(),
            unit: "count".into(),
            source: name.into(),
            rate_hz: 1000.0,
        };
        let channel = CanChannel {
            signal: "position".into(),
            info,
        };
        CanSignalSensors::new(name, frames, map.clone(), vec![channel]).unwrap()
    }

    #[tokio::test]
    async fn tpdo_positions_become_samples() {
        let map = encoder_dbc();
        let bus = InProcessBus::new(64);
        let mut encoder = bus.endpoint("encoder");
        let mut s = positions("can", bus.endpoint("host"), &map);
        let heartbeat = map
            .encode(CanId::Standard(0x701), &[("nmt_state", 5.0)])
            .unwrap();
        encoder.send(&heartbeat).await.unwrap();
        for p in [10.0, 20.0, 4_000_000_000.0] {
            let f = map
                .encode(CanId::Standard(0x181), &[("position", p)])
                .unwrap();
            encoder.send(&f).await.unwrap();
            let b = s.next_batch().await.unwrap();
            assert_eq!(
                b.samples,
                vec![Sample {
                    channel: 0,
                    value: p
                }]
            );
        }
        let missing = CanSignalSensors::new(
            "can",
            bus.endpoint("x"),
            map,
            vec![CanChannel {
                signal: "torque".into(),
                info: s.channels()[0].clone(),
            }],
        );
        assert!(missing.is_err());
    }

    /// After a short loss (50 frames of a 1 kHz message, far shorter than
    /// the resynchronising silence) every frame that was sent is handed
    /// on, in order, each stamped within a period of its send time: the
    /// first frames after the loss too, which used to trail the grid
    /// before the loss by 50 ms and be dropped downstream as late.
    #[tokio::test(start_paused = true)]
    async fn the_frames_after_a_short_loss_keep_their_send_times() {
        let map = encoder_dbc();
        let bus = InProcessBus::new(64);
        let mut encoder = bus.endpoint("encoder");
        let mut s = positions("can", bus.endpoint("host"), &map);
        let sent: Vec<u64> = (0..100).chain(150..170).collect();
        let frames = map.clone();
        let slots = sent.clone();
        tokio::spawn(async move {
            let start = tokio::time::Instant::now();
            for k in slots {
                tokio::time::sleep_until(start + std::time::Duration::from_millis(k)).await;
                let f = frames
                    .encode(CanId::Standard(0x181), &[("position", k as f64)])
                    .unwrap();
                encoder.send(&f).await.unwrap();
            }
        });
        let mut last = 0;
        for &k in &sent {
            let b = s.next_batch().await.unwrap();
            assert_eq!(
                b.samples[0].value, k as f64,
                "frames in order, none dropped"
            );
            assert!(b.t_ns >= last, "stamps in order");
            last = b.t_ns;
            let send_ns = k * 1_000_000;
            assert!(
                b.t_ns.abs_diff(send_ns) <= 1_000_000,
                "frame {k}: stamped {} ns, sent {send_ns} ns",
                b.t_ns
            );
        }
        assert_eq!(s.link_health()[0].counts().lost, 50);
    }

    /// Garbage on an SLCAN adapter's line costs the frames it hits, and
    /// is said: a warning with the count, and the link's decode errors.
    #[tokio::test]
    async fn garbage_on_an_slcan_line_is_counted_and_warned_of() {
        use tokio::io::AsyncWriteExt;

        let map = encoder_dbc();
        let (host_end, mut adapter) = tokio::io::duplex(4096);
        let opts = crate::can::SlcanOptions {
            bitrate: None,
            listen_only: false,
            ack_timeout: None,
        };
        let frames = crate::can::SlcanStream::open(host_end, "slcan", opts)
            .await
            .unwrap();
        let mut s = positions("slcan", frames, &map);
        let line = |p: f64| {
            crate::can::encode_frame(
                &map.encode(CanId::Standard(0x181), &[("position", p)])
                    .unwrap(),
            )
        };
        let mut bytes = line(1.0);
        bytes.extend_from_slice(b"\xFF\x00\xFF");
        bytes.extend(line(2.0));
        bytes.extend(line(3.0));
        adapter.write_all(&bytes).await.unwrap();
        let mut got = Vec::new();
        for _ in 0..2 {
            got.push(s.next_batch().await.unwrap().samples[0].value);
        }
        assert_eq!(got, vec![1.0, 3.0], "the frame after the noise is lost");
        let warnings = s.take_warnings();
        assert_eq!(
            warnings,
            vec!["slcan: garbage on the line: 1 line(s) refused so far".to_string()]
        );
        assert_eq!(s.link_health()[0].counts().decode_errors, 1);
    }
}
