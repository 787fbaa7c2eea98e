//! Detects, from the readings of a DC level, a supply that did not follow
//! its set point: it held its current limit (constant-current mode, the
//! armature current pinned at the limit the bench set) or it never reached
//! the commanded voltage (voltage compliance). Either way the segment's
//! voltage is not the step that was commanded, and the identification
//! methods that assume that step must not use it; the sequencer records
//! each stretch found on `/bench/supply_limit` and as a warning.
//!
//! Both tests use readings only, so they work on any supply, with
//! thresholds set by what a bench can measure rather than by a model:
//!
//! - current limit: at least [`MIN_PINNED_READINGS`] current readings of
//!   the segment at or beyond [`PINNED_FRACTION`] of the supply's current
//!   limit (a supply regulating its current holds it within a few percent);
//! - voltage compliance: the median of the segment's last
//!   [`TAIL_READINGS`] voltage readings short of the command by more than
//!   [`COMPLIANCE_FRACTION`] of it (and at least [`COMPLIANCE_FLOOR_V`]),
//!   beyond the accuracy of a bench voltmeter, while the current was not
//!   pinned at the end.

use std::collections::VecDeque;

use crate::record::{SupplyLimit, SupplyLimitKind};

/// A current reading at or beyond this fraction of the supply's current
/// limit counts as pinned at the limit.
pub const PINNED_FRACTION: f64 = 0.97;
/// Pinned readings a segment needs to count as current-limited.
pub const MIN_PINNED_READINGS: usize = 3;
/// Fraction of the command a settled voltage must fall short by.
pub const COMPLIANCE_FRACTION: f64 = 0.03;
/// Least shortfall of a settled voltage that counts, V.
pub const COMPLIANCE_FLOOR_V: f64 = 0.5;
/// Voltage readings at a segment's end whose median is compared.
pub const TAIL_READINGS: usize = 32;

/// The pinned readings of one segment.
#[derive(Debug, Clone, Copy)]
struct Pinned {
    from_ns: u64,
    to_ns: u64,
    readings: usize,
    peak: f64,
    /// The measured voltage furthest from the command.
    furthest_voltage: f64,
    /// The last current reading of the segment was pinned.
    at_end: bool,
}

/// Watches the readings of one level at a time. See the module docs.
#[derive(Debug, Clone)]
pub struct SupplyLimitDetector {
    current_limit: Option<f64>,
    level: Option<(u32, f64)>,
    latest_voltage: Option<f64>,
    pinned: Option<Pinned>,
    /// The largest current magnitude of the segment.
    peak: f64,
    tail: VecDeque<(u64, f64)>,
}

impl SupplyLimitDetector {
    /// A detector for a supply set to `current_limit` A (`None` when the
    /// supply has no settable limit: only compliance is then detected).
    pub fn new(current_limit: Option<f64>) -> SupplyLimitDetector {
        SupplyLimitDetector {
            current_limit: current_limit.filter(|l| l.is_finite() && *l > 0.0),
            level: None,
            latest_voltage: None,
            pinned: None,
            peak: 0.0,
            tail: VecDeque::with_capacity(TAIL_READINGS),
        }
    }

    /// A new segment, holding `commanded` V (`None`: nothing commanded,
    /// such as a coast-down, and nothing is watched).
    pub fn start(&mut self, segment: u32, commanded: Option<f64>) {
        self.level = commanded.map(|v| (segment, v));
        self.pinned = None;
        self.peak = 0.0;
        self.tail.clear();
    }

    /// The readings of one batch (either may be absent).
    pub fn reading(&mut self, t_ns: u64, voltage: Option<f64>, current: Option<f64>) {
        let Some((_, commanded)) = self.level else {
            return;
        };
        if let Some(v) = voltage.filter(|v| v.is_finite()) {
            self.latest_voltage = Some(v);
            if self.tail.len() == TAIL_READINGS {
                self.tail.pop_front();
            }
            self.tail.push_back((t_ns, v));
        }
        let Some(i) = current.filter(|i| i.is_finite()) else {
            return;
        };
        self.peak = self.peak.max(i.abs());
        let Some(limit) = self.current_limit else {
            return;
        };
        let pinned = i.abs() >= PINNED_FRACTION * limit;
        if let Some(p) = &mut self.pinned {
            p.at_end = pinned;
        }
        if !pinned {
            return;
        }
        let v = self.latest_voltage.unwrap_or(commanded);
        let p = self.pinned.get_or_insert(Pinned {
            from_ns: t_ns,
            to_ns: t_ns,
            readings: 0,
            peak: 0.0,
            furthest_voltage: v,
            at_end: true,
        });
        p.to_ns = t_ns;
        p.readings += 1;
        p.peak = p.peak.max(i.abs());
        if (v - commanded).abs() > (p.furthest_voltage - commanded).abs() {
            p.furthest_voltage = v;
        }
    }

    /// The end of the segment: what the supply did, if it limited.
    pub fn finish(&mut self) -> Vec<SupplyLimit> {
        let Some((segment, commanded)) = self.level.take() else {
            return Vec::new();
        };
        let mut out = Vec::new();
        let pinned = self.pinned.take();
        if let Some(p) = pinned.filter(|p| p.readings >= MIN_PINNED_READINGS) {
            out.push(SupplyLimit {
                segment,
                kind: SupplyLimitKind::CurrentLimit,
                from: p.from_ns as f64 * 1e-9,
                to: p.to_ns as f64 * 1e-9,
                commanded_voltage: commanded,
                measured_voltage: p.furthest_voltage,
                current_limit: self.current_limit,
                peak_current: p.peak,
            });
        }
        let pinned_at_end = pinned.is_some_and(|p| p.at_end);
        if let (Some(settled), false) = (self.settled_voltage(), pinned_at_end) {
            let short = commanded.abs() - settled.abs();
            if short > (COMPLIANCE_FRACTION * commanded.abs()).max(COMPLIANCE_FLOOR_V) {
                let (from, to) = (self.tail[0].0, self.tail[self.tail.len() - 1].0);
                out.push(SupplyLimit {
                    segment,
                    kind: SupplyLimitKind::VoltageCompliance,
                    from: from as f64 * 1e-9,
                    to: to as f64 * 1e-9,
                    commanded_voltage: commanded,
                    measured_voltage: settled,
                    current_limit: self.current_limit,
                    peak_current: self.peak,
                });
            }
        }
        self.tail.clear();
        out
    }

    /// The median of the segment's last voltage readings, once there are
    /// enough of them.
    fn settled_voltage(&self) -> Option<f64> {
        if self.tail.len() < TAIL_READINGS {
            return None;
        }
        let mut v: Vec<f64> = self.tail.iter().map(|&(_, v)| v).collect();
        v.sort_by(f64::total_cmp);
        Some(0.5 * (v[(v.len() - 1) / 2] + v[v.len() / 2]))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const MS: u64 = 1_000_000;

    #[test]
    fn a_current_pinned_at_the_limit_is_reported_with_its_stretch() {
        let mut d = SupplyLimitDetector::new(Some(1.8));
        d.start(1, Some(248.0));
        for k in 0..100u64 {
            // Pinned from 10 ms to 39 ms, the voltage held down meanwhile.
            let (u, i) = if (10..40).contains(&k) {
                (60.0 + k as f64, 1.8 - 0.01 * (k % 2) as f64)
            } else {
                (248.0, 0.5)
            };
            d.reading(k * MS, Some(u), Some(i));
        }
        let found = d.finish();
        assert_eq!(found.len(), 1, "{found:?}");
        let l = found[0];
        assert_eq!(l.kind, SupplyLimitKind::CurrentLimit);
        assert_eq!(l.segment, 1);
        assert!((l.from - 0.010).abs() < 1e-12 && (l.to - 0.039).abs() < 1e-12);
        assert!((l.measured_voltage - 70.0).abs() < 1e-12);
        assert!((l.peak_current - 1.8).abs() < 1e-12);
        assert_eq!(l.current_limit, Some(1.8));
        // The next segment starts clean.
        d.start(2, Some(60.0));
        for k in 0..100u64 {
            d.reading(k * MS, Some(60.0), Some(0.3));
        }
        assert!(d.finish().is_empty());
    }

    #[test]
    fn a_peak_below_the_limit_or_a_single_touch_is_not_limiting() {
        let mut d = SupplyLimitDetector::new(Some(1.8));
        d.start(0, Some(100.0));
        for k in 0..100u64 {
            let i = match k {
                5 => 1.79,
                6..=8 => 1.70,
                _ => 0.4,
            };
            d.reading(k * MS, Some(100.0), Some(i));
        }
        assert!(d.finish().is_empty());
    }

    #[test]
    fn a_settled_voltage_short_of_the_command_is_compliance() {
        let mut d = SupplyLimitDetector::new(None);
        d.start(3, Some(248.0));
        for k in 0..200u64 {
            let u = (k as f64 * 5.0).min(230.0) + if k % 2 == 0 { 0.3 } else { -0.3 };
            d.reading(k * MS, Some(u), Some(1.0));
        }
        let found = d.finish();
        assert_eq!(found.len(), 1, "{found:?}");
        assert_eq!(found[0].kind, SupplyLimitKind::VoltageCompliance);
        assert!((found[0].measured_voltage - 230.0).abs() < 0.31);
        // Within 3 % of the command it is measurement, not compliance.
        d.start(4, Some(248.0));
        for k in 0..200u64 {
            d.reading(k * MS, Some(242.0), Some(1.0));
        }
        assert!(d.finish().is_empty());
        // Nothing commanded (a coast-down): nothing watched.
        d.start(5, None);
        for k in 0..200u64 {
            d.reading(k * MS, Some(0.0), Some(0.0));
        }
        assert!(d.finish().is_empty());
    }
}
