//! The identified EMF constant against the motor's nameplate.
//!
//! Every DC method fits the record's speed as it was read. A speed scaled
//! by a wrong encoder resolution (`encoder_lines`), by counts the encoder
//! loses, or by a tachometer's wrong gain fits just as well: the model is
//! the same under `ω → c·ω` with `K → K/c`, `J → J/c²`, `f → f/c²` and
//! `Tst → Tst/c`. Nothing in the record tells the two apart. The nameplate
//! can: at its rated point, `K ≈ (V − Ra·I)/ω`. Rated values hold at the
//! rated field and include the brush drop and the armature reaction, so
//! they only bound `K`. The seed paper's motor gives 0.88 of its
//! nameplate's figure. A factor beyond [`K_AGREEMENT`] either way is a
//! warning that names the likely causes.

use crate::contract::IdentificationReport;

/// How far (a factor, either way) the identified `K` may lie from the
/// nameplate's before it is warned of.
pub const K_AGREEMENT: f64 = 1.5;

/// The EMF constant a nameplate implies with armature resistance `ra`:
/// `(V − Ra·I)/ω` at the rated voltage, current and speed, V·s/rad.
/// `None` where one of them is missing or the figure is not positive.
pub fn nameplate_k(nameplate: &serde_json::Value, ra: f64) -> Option<f64> {
    let rated = |key: &str| nameplate.get(key).and_then(serde_json::Value::as_f64);
    let (v, i, rpm) = (
        rated("voltage_V")?,
        rated("current_A")?,
        rated("speed_rpm")?,
    );
    let omega = rpm * std::f64::consts::PI / 30.0;
    let k = (v - ra * i) / omega;
    (k.is_finite() && k > 0.0 && omega > 0.0).then_some(k)
}

/// A warning when the best method's `K` lies beyond [`K_AGREEMENT`] of
/// what `nameplate` implies with that method's `Ra`; `None` when they
/// agree or either is missing.
pub fn k_disagrees(nameplate: &serde_json::Value, report: &IdentificationReport) -> Option<String> {
    let params = report.best_params()?;
    let (k, ra) = (params.get("K")?.value, params.get("Ra")?.value);
    let implied = nameplate_k(nameplate, ra)?;
    let ratio = k / implied;
    if (1.0 / K_AGREEMENT..=K_AGREEMENT).contains(&ratio) {
        return None;
    }
    let rated = |key: &str| nameplate[key].as_f64().unwrap_or(f64::NAN);
    Some(format!(
        "nameplate: K = {k:.4} V·s/rad is {ratio:.2} times what the nameplate implies, \
         ({} V − {ra:.3} Ω × {} A) / {} r/min = {implied:.4} V·s/rad: {}",
        rated("voltage_V"),
        rated("current_A"),
        rated("speed_rpm"),
        speed_scale_cause(ratio),
    ))
}

/// The likely cause of a `K` that is `ratio` times the nameplate's: a
/// ratio near π/30 or 30/π (within [`UNIT_RATIO_TOLERANCE`]) is a speed in
/// r/min read as rad/s or the other way round, whatever the bounds of
/// the rated point allow.
fn speed_scale_cause(ratio: f64) -> &'static str {
    let rpm_per_rad_s = 30.0 / std::f64::consts::PI;
    let near = |target: f64| (ratio / target - 1.0).abs() <= UNIT_RATIO_TOLERANCE;
    if near(1.0 / rpm_per_rad_s) {
        "the speed column is probably in r/min, not rad/s (9.55 times too large; label it \
         speed_rpm), or the nameplate is not this motor's"
    } else if near(rpm_per_rad_s) {
        "the speed column is probably in rad/s, not r/min (9.55 times too small; label it \
         speed_rad_s), or the nameplate is not this motor's"
    } else {
        "the speed reading is probably scaled wrong (the encoder's lines per revolution, \
         counts it loses, a tachometer's gain), or the nameplate is not this motor's"
    }
}

/// How close (relative) a `K` ratio must be to the r/min-to-rad/s factor
/// to be named a unit error: the seed paper's motor itself reads 0.88 of
/// its nameplate, so the band is as wide as the rated point's own spread.
const UNIT_RATIO_TOLERANCE: f64 = 0.25;

#[cfg(test)]
mod tests {
    use super::*;

    /// The seed paper's nameplate (Table 1).
    fn seed_nameplate() -> serde_json::Value {
        serde_json::json!({"power_W": 180, "voltage_V": 270, "current_A": 1.1, "speed_rpm": 1500})
    }

    fn report_with(k: f64, ra: f64) -> IdentificationReport {
        IdentificationReport::with_best_params(&[("K", k, "V*s/rad"), ("Ra", ra, "ohm")])
    }

    #[test]
    fn the_seed_motor_agrees_with_its_nameplate() {
        // (270 − 30.9·1.1)/(1500·π/30) = 1.5025; Table 4's K is 0.88 of it.
        let implied = nameplate_k(&seed_nameplate(), 30.9).unwrap();
        assert!((implied - 1.5025).abs() < 1e-4, "{implied}");
        assert_eq!(
            k_disagrees(&seed_nameplate(), &report_with(1.323, 30.9)),
            None
        );
    }

    #[test]
    fn a_speed_read_at_half_scale_is_warned_of() {
        // Half the counts lost: K comes out twice the motor's.
        let w = k_disagrees(&seed_nameplate(), &report_with(2.646, 30.9)).expect("a warning");
        assert!(
            w.starts_with("nameplate: K = 2.6460 V·s/rad is 1.76 times"),
            "{w}"
        );
        assert!(w.contains("lines per revolution"), "{w}");
        // And an encoder with more lines than configured: K comes out low.
        assert!(k_disagrees(&seed_nameplate(), &report_with(0.9, 30.9)).is_some());
    }

    #[test]
    fn a_speed_in_the_wrong_unit_is_named() {
        // r/min under speed_rad_s: the speed reads 9.55 times too large,
        // K 9.55 times too small (1.323/9.55 = 0.1385).
        let w = k_disagrees(&seed_nameplate(), &report_with(0.1385, 30.9)).expect("a warning");
        assert!(w.contains("in r/min, not rad/s"), "{w}");
        // rad/s under speed_rpm: K 9.55 times too large.
        let w = k_disagrees(&seed_nameplate(), &report_with(12.63, 30.9)).expect("a warning");
        assert!(w.contains("in rad/s, not r/min"), "{w}");
        // A factor of 3 is a scale, not a unit.
        let w = k_disagrees(&seed_nameplate(), &report_with(4.5, 30.9)).expect("a warning");
        assert!(w.contains("lines per revolution"), "{w}");
    }

    #[test]
    fn a_nameplate_without_the_rated_point_checks_nothing() {
        let partial = serde_json::json!({"voltage_V": 270, "current_A": 1.1});
        assert_eq!(k_disagrees(&partial, &report_with(5.0, 30.9)), None);
        // Nor one whose rated point leaves no EMF.
        let odd = serde_json::json!({"voltage_V": 20, "current_A": 1.1, "speed_rpm": 1500});
        assert_eq!(nameplate_k(&odd, 30.9), None);
    }
}
