//! The stuck-sensor warning: a channel that holds exactly one value for
//! longer than `supervisor.stuck_after_s` while the drive changed (a
//! command went out during the hold) is likely stuck — a frozen ADC, an
//! encoder that stopped counting, a device that repeats its last reading.
//! A live, noisy reading never repeats bit for bit for long; a channel at
//! rest before any command changes (the encoder before the motor turns, a
//! reading after the last command) is not suspect. The test goes on: the
//! warning is an event in the record, once per hold.

use motorbench_drivers::SampleBatch;

/// One channel's current hold.
#[derive(Debug, Clone, Copy)]
struct Hold {
    value: f64,
    since_ns: u64,
    warned: bool,
}

/// Watches every channel's holds. See the module docs.
#[derive(Debug, Clone)]
pub struct StuckDetector {
    after_ns: u64,
    quantities: Vec<String>,
    holds: Vec<Option<Hold>>,
    /// Data time of the latest drive change, ns.
    last_command_ns: Option<u64>,
}

impl StuckDetector {
    /// A detector for channels named `quantities`, warning after a hold
    /// of `after_s` seconds.
    pub fn new(quantities: Vec<String>, after_s: f64) -> StuckDetector {
        StuckDetector {
            after_ns: (after_s * 1e9) as u64,
            holds: vec![None; quantities.len()],
            quantities,
            last_command_ns: None,
        }
    }

    /// The drive changed (a command went out) at data time `t_ns`.
    pub fn command(&mut self, t_ns: u64) {
        self.last_command_ns = Some(t_ns);
    }

    /// Check one batch: a warning for each channel newly found stuck.
    pub fn check(&mut self, batch: &SampleBatch) -> Vec<String> {
        let t = batch.t_ns;
        let mut out = Vec::new();
        for s in &batch.samples {
            let Some(slot) = self.holds.get_mut(s.channel) else {
                continue;
            };
            if !s.value.is_finite() {
                *slot = None;
                continue;
            }
            let hold = match slot {
                Some(h) if h.value.to_bits() == s.value.to_bits() => h,
                _ => {
                    *slot = Some(Hold {
                        value: s.value,
                        since_ns: t,
                        warned: false,
                    });
                    continue;
                }
            };
            let held_ns = t.saturating_sub(hold.since_ns);
            let drive_changed = self.last_command_ns.is_some_and(|c| c > hold.since_ns);
            if !hold.warned && drive_changed && held_ns >= self.after_ns {
                hold.warned = true;
                out.push(format!(
                    "stuck sensor? `{}` has held exactly {} for {:.3} s (since test time {:.3} s) while the drive changed",
                    self.quantities[s.channel],
                    hold.value,
                    held_ns as f64 * 1e-9,
                    hold.since_ns as f64 * 1e-9,
                ));
            }
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use motorbench_drivers::Sample;

    fn batch(t_ms: u64, a: f64, b: f64) -> SampleBatch {
        SampleBatch {
            t_ns: t_ms * 1_000_000,
            samples: vec![
                Sample {
                    channel: 0,
                    value: a,
                },
                Sample {
                    channel: 1,
                    value: b,
                },
            ],
        }
    }

    #[test]
    fn a_hold_warns_once_and_only_when_the_drive_changed_during_it() {
        let mut d = StuckDetector::new(vec!["current".into(), "count".into()], 0.1);
        // At rest before any command: no warning however long.
        for ms in 0..200 {
            assert!(d.check(&batch(ms, 1.0, 0.0)).is_empty());
        }
        d.command(200_000_000);
        let mut warnings = Vec::new();
        for ms in 200..400 {
            // The count moves, the current is stuck at 1.0.
            warnings.extend(d.check(&batch(ms, 1.0, ms as f64)));
        }
        assert_eq!(warnings.len(), 1, "{warnings:?}");
        assert!(warnings[0].starts_with("stuck sensor? `current` has held exactly 1"));
        // A hold that starts after the last command is not suspect.
        let mut d = StuckDetector::new(vec!["current".into(), "count".into()], 0.1);
        d.command(0);
        for ms in 1..400 {
            assert!(d.check(&batch(ms, 0.0, 5.0)).is_empty());
        }
    }
}
