//! A fitted friction against the torque the record shows the motor made.
//!
//! A friction coefficient `f` or static torque `Tst` is positive and
//! finite in every method, yet a fit that a record barely excites can
//! carry it off to values no motor has (a closed-loop record read by a
//! coarse encoder gave `f = 1.6·10²⁷ N·m·s/rad`, through a voltage-noise
//! bias correction since bounded): the model then holds the
//! rotor still and the fit lets the speed residual carry the rest. The
//! record itself bounds friction. At its top speed the rotor turned, so
//! the friction there, `Tst + f·ω_max`, was overcome by the motor's
//! torque; and that torque, `K·i`, never exceeded `K·max|i|` (the inertia
//! only lends, during a deceleration, what an acceleration put in at the
//! same torque). A method whose friction at the record's top speed exceeds
//! [`FRICTION_MARGIN`] times that ceiling is made not to apply, with both
//! torques named: the answer lies outside the physical range this record
//! sets, as a negative resistance lies outside the range every record
//! sets. The decade of margin covers noise on the current, a top speed
//! reached in a coast-down from a faster start, and an estimate of `K`
//! that is itself off.

use crate::contract::{unphysical_param, IdentificationReport, MethodReport};
use crate::record::Record;

/// How many times the record's torque ceiling a friction at top speed may
/// reach before the method is refused.
pub const FRICTION_MARGIN: f64 = 10.0;

/// Make every method whose friction at the record's top speed exceeds
/// [`FRICTION_MARGIN`] times the torque the record's current can make not
/// apply, with the reason. Methods without `K` and `f` are left alone, as
/// is every method of a record without current or speed.
pub fn refuse_friction_beyond_torque(record: &Record, report: &mut IdentificationReport) {
    let largest = |values: &dyn Fn(&crate::record::DcSegment) -> &[f64]| {
        record
            .segments
            .iter()
            .flat_map(|s| values(s).iter())
            .filter(|v| v.is_finite())
            .fold(0.0f64, |m, v| m.max(v.abs()))
    };
    let w_max = largest(&|s| &s.speed);
    let i_max = largest(&|s| &s.current);
    if w_max <= 0.0 || i_max <= 0.0 {
        return;
    }
    for method in report.methods.values_mut() {
        // A value outside every record's range is refuse_unphysical's to
        // name.
        let Some(params) = method
            .params
            .as_ref()
            .filter(|p| unphysical_param(p).is_none())
        else {
            continue;
        };
        let value = |key: &str| params.get(key).map(|p| p.value);
        let (Some(k), Some(f)) = (value("K"), value("f")) else {
            continue;
        };
        let tst = value("Tst").unwrap_or(0.0);
        let friction = tst + f * w_max;
        let ceiling = k * i_max;
        if friction <= FRICTION_MARGIN * ceiling {
            continue;
        }
        *method = MethodReport::not_applicable(format!(
            "the fit gives a friction of {friction:.4e} N*m at the record's top speed \
             {w_max:.4e} rad/s (f = {f:.4e} N*m*s/rad, Tst = {tst:.4e} N*m), more than \
             {FRICTION_MARGIN} times the {ceiling:.4e} N*m the motor made at most (K = {k:.4e} \
             V*s/rad times the largest current {i_max:.4e} A): the rotor could not have turned; \
             the record does not determine the friction for this method"
        ));
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::contract::ParamEstimate;
    use crate::record::DcSegment;

    fn record(current: f64, speed: f64) -> Record {
        let mut r = Record::default();
        r.segments
            .push(DcSegment::held(10, 1e-3, 24.0, current, speed));
        r
    }

    fn report(k: f64, f: f64, tst: f64) -> IdentificationReport {
        let mut r = IdentificationReport::with_best_params(&[
            ("K", k, "V*s/rad"),
            ("f", f, "N*m*s/rad"),
            ("Tst", tst, "N*m"),
        ]);
        r.methods.insert(
            "steady_state".into(),
            MethodReport::fitted(
                [(
                    "Ra".to_string(),
                    ParamEstimate {
                        value: 1.0,
                        ci95: None,
                        unit: "ohm".into(),
                    },
                )]
                .into(),
                None,
            ),
        );
        r
    }

    #[test]
    fn a_friction_no_motor_could_overcome_is_refused() {
        // 2 A at most through K = 0.1: 0.2 N*m; at 100 rad/s a friction of
        // f = 1e27 needs 1e29 N*m.
        let mut r = report(0.1, 1e27, 0.01);
        refuse_friction_beyond_torque(&record(2.0, 100.0), &mut r);
        let oe = &r.methods["output_error"];
        assert!(!oe.applies);
        let why = oe.reason.as_deref().unwrap();
        assert!(why.contains("1.0000e29 N*m"), "{why}");
        assert!(why.contains("2.0000e-1 N*m"), "{why}");
        assert!(r.methods["steady_state"].applies, "no K, no f: left alone");
        // A negative K is refuse_unphysical's to name, not a torque ceiling.
        let mut r = report(-0.1, 1.0, 0.01);
        refuse_friction_beyond_torque(&record(2.0, 100.0), &mut r);
        assert!(r.methods["output_error"].applies);
    }

    #[test]
    fn a_friction_within_the_margin_stays() {
        // Friction at top speed 0.01 + 0.0015·100 = 0.16 N*m of the 0.2 the
        // motor made (a motor at no load spends its torque on friction),
        // and one at 9.8 times the ceiling (a poor K) is not refused either;
        // 10.1 times is.
        for f in [0.0015, 0.0195] {
            let mut r = report(0.1, f, 0.01);
            refuse_friction_beyond_torque(&record(2.0, 100.0), &mut r);
            assert!(r.methods["output_error"].applies, "f = {f}");
        }
        let mut r = report(0.1, 0.0201, 0.01);
        refuse_friction_beyond_torque(&record(2.0, 100.0), &mut r);
        assert!(!r.methods["output_error"].applies);
    }

    #[test]
    fn a_record_without_current_or_speed_checks_nothing() {
        for (i, w) in [(0.0, 100.0), (2.0, 0.0)] {
            let mut r = report(0.1, 1e27, 0.01);
            refuse_friction_beyond_torque(&record(i, w), &mut r);
            assert!(r.methods["output_error"].applies);
        }
    }
}
