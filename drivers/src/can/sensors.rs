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
//! the speed derived from them would jump. Garbage on an adapter's line
//! ([`FrameStream::malformed`]) is warned of and counted as the link's
//! decode errors. The jitter statistics are those of the arrivals (what
//! the link did).

use async_trait::async_trait;
use tokio::time::Instant;

use super::stamp::PeriodicStamp;
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
        })
    }
}

impl<F> CanSignalSensors<F> {
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
                    self.stats[k].received(arrival_ns);
                    samples.push(Sample {
                        channel: k,
                        value: s.value,
                    });
                }
            }
            if let (false, Some(t_ns)) = (samples.is_empty(), t_ns) {
                return Ok(SampleBatch { t_ns, samples });
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
