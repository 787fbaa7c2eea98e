//! Sampling quality in the record: a sensor stream's warnings (lost
//! readings, late polls, garbage on a line) become `/bench/event`
//! warnings, capped so a failing link cannot flood the record, and its
//! per-channel statistics (received, lost, jitter) become one final event
//! per channel.

use motorbench_drivers::{ChannelInfo, ChannelStats};

use crate::record::EventLevel;

/// Warnings recorded per test before the rest are only counted.
pub const WARNING_CAP: usize = 50;

/// Decides which sampling messages go to the record.
#[derive(Debug, Clone, Default)]
pub struct SamplingEvents {
    recorded: usize,
    suppressed: usize,
}

impl SamplingEvents {
    /// A fresh counter.
    pub fn new() -> SamplingEvents {
        SamplingEvents::default()
    }

    /// The warnings to record now (the first [`WARNING_CAP`] of a test;
    /// later ones are counted and summarised at the end).
    pub fn admit(&mut self, warnings: Vec<String>) -> Vec<String> {
        let room = WARNING_CAP.saturating_sub(self.recorded);
        let n = warnings.len();
        let admitted: Vec<String> = warnings.into_iter().take(room).collect();
        self.recorded += admitted.len();
        self.suppressed += n - admitted.len();
        admitted
    }

    /// The final events: one statistics line per channel (a warning when
    /// it lost readings), and how many warnings were not recorded.
    pub fn summary(
        &self,
        stats: &[ChannelStats],
        channels: &[ChannelInfo],
    ) -> Vec<(EventLevel, String)> {
        let mut out: Vec<(EventLevel, String)> = stats
            .iter()
            .map(|s| {
                let name = channels
                    .get(s.channel)
                    .map_or_else(|| format!("channel {}", s.channel), |c| c.quantity.clone());
                let level = if s.lost > 0 {
                    EventLevel::Warn
                } else {
                    EventLevel::Info
                };
                (level, format!("sampling statistics, {name}: {s}"))
            })
            .collect();
        if self.suppressed > 0 {
            out.push((
                EventLevel::Warn,
                format!(
                    "{} more sampling warning(s) were not recorded (only the first {WARNING_CAP} are)",
                    self.suppressed
                ),
            ));
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use motorbench_drivers::IntervalStats;

    #[test]
    fn warnings_are_capped_and_the_rest_counted() {
        let mut e = SamplingEvents::new();
        let first = e.admit((0..40).map(|k| format!("w{k}")).collect());
        assert_eq!(first.len(), 40);
        let second = e.admit((0..30).map(|k| format!("x{k}")).collect());
        assert_eq!(second.len(), 10);
        assert_eq!(second[9], "x9");
        let s = e.summary(&[], &[]);
        assert_eq!(s.len(), 1);
        assert!(s[0].1.starts_with("20 more sampling warning(s)"), "{:?}", s);
    }

    #[test]
    fn a_channel_that_lost_readings_is_a_warning() {
        let ch = ChannelInfo {
            quantity: "armature_current".into(),
            unit: "A".into(),
            source: "daq".into(),
            rate_hz: 100.0,
        };
        let mut good = IntervalStats::new(0, 100.0);
        good.received(0);
        good.received(10_000_000);
        let mut bad = IntervalStats::new(1, 100.0);
        bad.lost(3);
        let s = SamplingEvents::new().summary(&[good.summary(), bad.summary()], &[ch.clone(), ch]);
        assert_eq!(s[0].0, EventLevel::Info);
        assert!(
            s[0].1.contains("armature_current: 2 received, 0 lost"),
            "{}",
            s[0].1
        );
        assert_eq!(s[1].0, EventLevel::Warn);
    }
}
