//! Which IM effects the data cannot tell apart, and the test plan that
//! would separate each pair.

use crate::model::Effect;

/// The test plan that separates effect `a` from effect `b`.
pub fn separating_plan(a: Effect, b: Effect) -> String {
    use Effect::*;
    let pair = |x: Effect, y: Effect| (a == x && b == y) || (a == y && b == x);
    if pair(DeepBar, LeakageSaturation) {
        "a locked-rotor test at reduced voltage (leakage saturation depends on the current, deep bar does not) \
         and at reduced frequency (deep bar depends on the rotor frequency)"
            .into()
    } else if a == MainFluxSaturation || b == MainFluxSaturation {
        "a second sweep (or a no-load test) at a reduced supply voltage, e.g. 60–80 % of rated: \
         main-flux saturation makes Xm change with the voltage"
            .into()
    } else if a == ThermalDrift || b == ThermalDrift {
        "the sweep repeated in reverse order (locked rotor first), or its first points repeated at the end: \
         thermal drift follows the time order, not the slip"
            .into()
    } else if pair(IronLoss, StrayLoadLoss) {
        "a no-load test at several voltages: iron loss grows with the air-gap voltage squared, \
         stray load loss with the load current squared"
            .into()
    } else if a == StrayLoadLoss || b == StrayLoadLoss {
        "a torque sensor on the shaft (stray load loss takes input power without producing torque) \
         or a locked-rotor test at reduced frequency"
            .into()
    } else if a == IronLoss || b == IronLoss {
        "a no-load test at several voltages (iron loss: power ∝ E², at no load)".into()
    } else {
        "a second sweep at another supply voltage, and a locked-rotor test at reduced frequency"
            .into()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn plans_are_symmetric_and_name_the_separating_test() {
        let a = separating_plan(Effect::DeepBar, Effect::LeakageSaturation);
        assert_eq!(
            a,
            separating_plan(Effect::LeakageSaturation, Effect::DeepBar)
        );
        assert!(a.contains("locked-rotor"));
        assert!(separating_plan(Effect::IronLoss, Effect::MainFluxSaturation).contains("voltage"));
        assert!(separating_plan(Effect::DeepBar, Effect::ThermalDrift).contains("reverse"));
    }
}
