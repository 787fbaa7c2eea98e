//! [`FaultySensors`]: a sensor stream with the sensor faults of a
//! `[[fault]]` plan applied to its readings, on the readings' own time: a
//! channel stuck at one value, a spike, a NaN or infinite reading, a
//! timestamp that jumps, an encoder count that loses counts. Everything
//! else (channels, statistics, warnings, the clock kind) is the wrapped
//! stream's.

use async_trait::async_trait;
use motorbench_drivers::{
    ChannelInfo, ChannelStats, DriverError, LinkHealth, SampleBatch, SensorStream,
};

use super::FaultClock;
use crate::config::{Fault, FaultKind};
use crate::rig::RigError;

/// One fault with the channel it acts on and its running state.
#[derive(Debug)]
struct Acting {
    fault: Fault,
    /// The channel (sensor faults on a reading).
    channel: Option<usize>,
    /// The value a stuck channel holds, once it started.
    held: Option<f64>,
    /// A one-reading spike has been applied.
    fired: bool,
}

/// The sensor stream with faults. See the module docs.
pub struct FaultySensors {
    inner: Box<dyn SensorStream>,
    acting: Vec<Acting>,
    clock: FaultClock,
    /// The latest reading of each channel before any fault acted on it.
    last: Vec<Option<f64>>,
    /// The clock jumps so far, ns (signed).
    jump_ns: i128,
    /// The encoder count as delivered, and the raw count it follows.
    encoder: Option<(f64, f64)>,
}

impl FaultySensors {
    /// `inner` with `faults` (the sensor faults of a plan) applied; the
    /// readings' time goes to `clock`. Refused when a fault names a
    /// channel `inner` does not deliver.
    pub fn new(
        inner: Box<dyn SensorStream>,
        faults: Vec<Fault>,
        clock: FaultClock,
    ) -> Result<FaultySensors, RigError> {
        let mut acting = Vec::with_capacity(faults.len());
        for fault in faults {
            let wanted = match fault.kind {
                FaultKind::ClockJump => None,
                FaultKind::EncoderLosesCounts => Some(
                    fault
                        .target
                        .as_deref()
                        .unwrap_or("encoder_count")
                        .to_string(),
                ),
                _ => fault.target.clone(),
            };
            let channel = match wanted {
                None => None,
                Some(q) => Some(
                    inner
                        .channels()
                        .iter()
                        .position(|c| c.quantity == q)
                        .ok_or_else(|| {
                            RigError::Fault(format!(
                                "{}.target: the rig has no `{q}` channel (it has: {})",
                                fault.key(),
                                inner
                                    .channels()
                                    .iter()
                                    .map(|c| c.quantity.as_str())
                                    .collect::<Vec<_>>()
                                    .join(", ")
                            ))
                        })?,
                ),
            };
            acting.push(Acting {
                fault,
                channel,
                held: None,
                fired: false,
            });
        }
        let n = inner.channels().len();
        Ok(FaultySensors {
            inner,
            acting,
            clock,
            last: vec![None; n],
            jump_ns: 0,
            encoder: None,
        })
    }

    /// Apply the faults to `batch` (read at plant time `batch.t_ns`).
    fn apply(&mut self, mut batch: SampleBatch) -> SampleBatch {
        let t_s = batch.t_ns as f64 * 1e-9;
        self.clock.set(batch.t_ns);
        for a in &mut self.acting {
            let active = a.fault.active(t_s);
            match a.fault.kind {
                FaultKind::ClockJump => {
                    if active && !a.fired {
                        a.fired = true;
                        self.jump_ns += (a.fault.value.unwrap_or(0.0) * 1e9) as i128;
                    }
                }
                FaultKind::EncoderLosesCounts => {
                    let Some(ch) = a.channel else { continue };
                    let lost = if active {
                        a.fault.value.unwrap_or(1.0)
                    } else {
                        0.0
                    };
                    for s in batch.samples.iter_mut().filter(|s| s.channel == ch) {
                        let (out, raw) = self.encoder.unwrap_or((s.value, s.value));
                        let delivered = out + (s.value - raw) * (1.0 - lost);
                        self.encoder = Some((delivered, s.value));
                        s.value = delivered.round();
                    }
                }
                kind => {
                    let Some(ch) = a.channel else { continue };
                    let spike_over = kind == FaultKind::Spike && a.fault.for_s.is_none() && a.fired;
                    if !active || spike_over {
                        continue;
                    }
                    for s in batch.samples.iter_mut().filter(|s| s.channel == ch) {
                        s.value = match kind {
                            FaultKind::Stuck => *a
                                .held
                                .get_or_insert(a.fault.value.or(self.last[ch]).unwrap_or(s.value)),
                            FaultKind::Spike => s.value + a.fault.value.unwrap_or(0.0),
                            FaultKind::Nan => f64::NAN,
                            FaultKind::Inf if a.fault.value.is_some_and(|v| v < 0.0) => {
                                f64::NEG_INFINITY
                            }
                            FaultKind::Inf => f64::INFINITY,
                            _ => s.value,
                        };
                        a.fired = true;
                    }
                }
            }
        }
        batch.t_ns = (i128::from(batch.t_ns) + self.jump_ns).clamp(0, i128::from(u64::MAX)) as u64;
        batch
    }

    /// Keep each channel's latest reading before the faults act on it.
    fn remember(&mut self, batch: &SampleBatch) {
        for s in &batch.samples {
            if let Some(l) = self.last.get_mut(s.channel) {
                *l = Some(s.value);
            }
        }
    }
}

#[async_trait]
impl SensorStream for FaultySensors {
    fn id(&self) -> &str {
        self.inner.id()
    }

    fn channels(&self) -> &[ChannelInfo] {
        self.inner.channels()
    }

    async fn next_batch(&mut self) -> Result<SampleBatch, DriverError> {
        let batch = self.inner.next_batch().await?;
        let out = self.apply(batch.clone());
        self.remember(&batch);
        Ok(out)
    }

    fn sampling_stats(&self) -> Vec<ChannelStats> {
        self.inner.sampling_stats()
    }

    fn link_health(&self) -> Vec<LinkHealth> {
        self.inner.link_health()
    }

    fn take_warnings(&mut self) -> Vec<String> {
        self.inner.take_warnings()
    }

    fn epoch(&self) -> Option<tokio::time::Instant> {
        self.inner.epoch()
    }

    fn virtual_clock(&self) -> bool {
        self.inner.virtual_clock()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use motorbench_drivers::Sample;

    /// A stream of `ramp` readings on two channels, 1 ms apart.
    struct Ramp {
        channels: Vec<ChannelInfo>,
        n: u64,
    }

    #[async_trait]
    impl SensorStream for Ramp {
        fn id(&self) -> &str {
            "ramp"
        }
        fn channels(&self) -> &[ChannelInfo] {
            &self.channels
        }
        async fn next_batch(&mut self) -> Result<SampleBatch, DriverError> {
            self.n += 1;
            Ok(SampleBatch {
                t_ns: self.n * 1_000_000,
                samples: vec![
                    Sample {
                        channel: 0,
                        value: self.n as f64,
                    },
                    Sample {
                        channel: 1,
                        value: 10.0 * self.n as f64,
                    },
                ],
            })
        }
    }

    fn ramp() -> Box<dyn SensorStream> {
        let info = |q: &str| ChannelInfo {
            quantity: q.into(),
            unit: String::new(),
            source: "ramp".into(),
            rate_hz: 1000.0,
        };
        Box::new(Ramp {
            channels: vec![info("armature_current"), info("encoder_count")],
            n: 0,
        })
    }

    fn fault(
        kind: FaultKind,
        at_s: f64,
        for_s: Option<f64>,
        target: Option<&str>,
        value: Option<f64>,
    ) -> Fault {
        Fault {
            index: 0,
            kind,
            at_s,
            for_s,
            target: target.map(str::to_string),
            value,
        }
    }

    async fn read(faults: Vec<Fault>, n: usize) -> Vec<SampleBatch> {
        let mut s = FaultySensors::new(ramp(), faults, FaultClock::default()).unwrap();
        let mut out = Vec::new();
        for _ in 0..n {
            out.push(s.next_batch().await.unwrap());
        }
        out
    }

    #[tokio::test]
    async fn each_sensor_fault_acts_on_its_channel_in_its_window() {
        let i = |b: &Vec<SampleBatch>, k: usize| b[k].value(0).unwrap();
        let stuck = read(
            vec![fault(
                FaultKind::Stuck,
                0.003,
                Some(0.0015),
                Some("armature_current"),
                None,
            )],
            6,
        )
        .await;
        assert_eq!(
            (0..6).map(|k| i(&stuck, k)).collect::<Vec<_>>(),
            [1.0, 2.0, 2.0, 2.0, 5.0, 6.0]
        );
        let spike = read(
            vec![fault(
                FaultKind::Spike,
                0.002,
                None,
                Some("armature_current"),
                Some(100.0),
            )],
            4,
        )
        .await;
        assert_eq!(
            (0..4).map(|k| i(&spike, k)).collect::<Vec<_>>(),
            [1.0, 102.0, 3.0, 4.0]
        );
        let nan = read(
            vec![fault(
                FaultKind::Nan,
                0.002,
                None,
                Some("armature_current"),
                None,
            )],
            3,
        )
        .await;
        assert!(i(&nan, 0).is_finite() && i(&nan, 1).is_nan() && i(&nan, 2).is_nan());
        let inf = read(
            vec![fault(
                FaultKind::Inf,
                0.0,
                None,
                Some("armature_current"),
                Some(-1.0),
            )],
            1,
        )
        .await;
        assert_eq!(i(&inf, 0), f64::NEG_INFINITY);
        // The other channel is untouched.
        assert_eq!(nan[2].value(1), Some(30.0));
    }

    #[tokio::test]
    async fn the_clock_jumps_once_and_the_encoder_loses_counts() {
        let jump = read(
            vec![fault(
                FaultKind::ClockJump,
                0.002,
                None,
                None,
                Some(-0.0015),
            )],
            4,
        )
        .await;
        let t: Vec<u64> = jump.iter().map(|b| b.t_ns / 100_000).collect();
        assert_eq!(t, [10, 5, 15, 25]);
        let lost = read(
            vec![fault(
                FaultKind::EncoderLosesCounts,
                0.002,
                Some(0.0015),
                None,
                Some(0.5),
            )],
            5,
        )
        .await;
        let counts: Vec<f64> = lost.iter().map(|b| b.value(1).unwrap()).collect();
        // 10 per reading; half of them lost at 2 and 3 ms.
        assert_eq!(counts, [10.0, 15.0, 20.0, 30.0, 40.0]);
        let e = FaultySensors::new(
            ramp(),
            vec![fault(FaultKind::Nan, 0.0, None, Some("speed"), None)],
            FaultClock::default(),
        )
        .err()
        .unwrap();
        assert!(
            e.to_string()
                .contains("fault[0].target: the rig has no `speed` channel"),
            "{e}"
        );
    }
}
