//! Sampling quality in the record: a sensor stream's warnings (lost
//! readings, late polls, garbage on a line) become `/bench/event`
//! warnings, capped so a failing link cannot flood the record (and a flood
//! of one kind cannot crowd out the first warning of another), and its
//! per-channel statistics (received, lost, jitter) become one final event
//! per channel.

use std::collections::HashMap;

use motorbench_drivers::{ChannelInfo, ChannelStats};

use crate::record::EventLevel;

/// Warnings recorded per test before the rest are only counted.
pub const WARNING_CAP: usize = 50;

/// Warnings of one kind (the same text but for its numbers) recorded per
/// test: a link that drops a batch every few milliseconds fills no more
/// than this, and a different fault later in the test still shows.
pub const KIND_CAP: usize = 10;

/// Decides which sampling messages go to the record.
#[derive(Debug, Clone, Default)]
pub struct SamplingEvents {
    recorded: usize,
    suppressed: usize,
    per_kind: HashMap<String, usize>,
}

/// A warning's kind: its text with every number replaced by `#`.
fn kind_of(warning: &str) -> String {
    let mut kind = String::with_capacity(warning.len());
    let mut in_number = false;
    for c in warning.chars() {
        let numeric = c.is_ascii_digit() || (in_number && c == '.');
        if numeric && !in_number {
            kind.push('#');
        } else if !numeric {
            kind.push(c);
        }
        in_number = numeric;
    }
    kind
}

impl SamplingEvents {
    /// A fresh counter.
    pub fn new() -> SamplingEvents {
        SamplingEvents::default()
    }

    /// The warnings to record now (the first [`KIND_CAP`] of each kind,
    /// [`WARNING_CAP`] in all, of a test; later ones are counted and
    /// summarised at the end).
    pub fn admit(&mut self, warnings: Vec<String>) -> Vec<String> {
        let mut admitted = Vec::new();
        for w in warnings {
            let seen = self.per_kind.entry(kind_of(&w)).or_insert(0);
            if self.recorded < WARNING_CAP && *seen < KIND_CAP {
                *seen += 1;
                self.recorded += 1;
                admitted.push(w);
            } else {
                self.suppressed += 1;
            }
        }
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
                    "{} more sampling warning(s) were not recorded (only the first {KIND_CAP} \
                     of a kind, {WARNING_CAP} in all, are)",
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

    /// Distinct warnings: `n` kinds of text (no numbers in them).
    fn distinct(prefix: &str, n: usize) -> Vec<String> {
        (0..n)
            .map(|k| format!("{prefix}{}", "x".repeat(k)))
            .collect()
    }

    #[test]
    fn warnings_are_capped_and_the_rest_counted() {
        let mut e = SamplingEvents::new();
        let first = e.admit(distinct("w", 40));
        assert_eq!(first.len(), 40);
        let second = e.admit(distinct("v", 30));
        assert_eq!(second.len(), 10);
        assert_eq!(second[9], format!("v{}", "x".repeat(9)));
        let s = e.summary(&[], &[]);
        assert_eq!(s.len(), 1);
        assert!(s[0].1.starts_with("20 more sampling warning(s)"), "{:?}", s);
    }

    /// A flood of one kind (a late batch every poll, each with its own
    /// delay) stops at the kind's cap; a warning of another kind after it
    /// is still recorded (a heavily loaded machine once hid "garbage on
    /// the line" behind 50 late batches).
    #[test]
    fn a_flood_of_one_kind_does_not_hide_another() {
        assert_eq!(
            kind_of("a batch arrived 129.6 ms behind (window 10 ms)"),
            "a batch arrived # ms behind (window # ms)"
        );
        let mut e = SamplingEvents::new();
        let late: Vec<String> = (0..60)
            .map(|k| format!("a batch arrived {}.6 ms behind (window 10 ms)", 130 - k))
            .collect();
        assert_eq!(e.admit(late).len(), KIND_CAP);
        let garbage = e.admit(vec!["garbage on the line: 3 bytes skipped".into()]);
        assert_eq!(garbage, ["garbage on the line: 3 bytes skipped"]);
        let s = e.summary(&[], &[]);
        assert!(s[0].1.starts_with("50 more sampling warning(s)"), "{:?}", s);
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
