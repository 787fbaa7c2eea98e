//! Which IM effects the data cannot tell apart, and the test plan that
//! would separate each pair.

use crate::model::Effect;

/// What a record already holds of the tests that separate effects.
#[derive(Debug, Clone, Copy, Default)]
pub struct HeldTests {
    /// Readings at two supply voltages or more (sweeps, or a no-load
    /// test across voltages).
    pub several_voltages: bool,
    /// No-load readings.
    pub no_load: bool,
    /// A torque reading at some point.
    pub torque: bool,
}

/// The test that separates a pair, as [`separating_plan`] names it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Separator {
    LockedRotorVoltageAndFrequency,
    ReducedVoltage,
    TimeOrder,
    NoLoadAgainstStrayLoss,
    NoLoadVoltages,
    TorqueOrLockedRotorFrequency,
    VoltageAndLockedRotorFrequency,
}

fn separator(a: Effect, b: Effect) -> Separator {
    use Effect::*;
    let pair = |x: Effect, y: Effect| (a == x && b == y) || (a == y && b == x);
    let either = |x: Effect| a == x || b == x;
    if pair(DeepBar, LeakageSaturation) {
        Separator::LockedRotorVoltageAndFrequency
    } else if either(MainFluxSaturation) {
        Separator::ReducedVoltage
    } else if either(ThermalDrift) {
        Separator::TimeOrder
    } else if pair(IronLoss, StrayLoadLoss) {
        Separator::NoLoadAgainstStrayLoss
    } else if either(IronLoss) {
        Separator::NoLoadVoltages
    } else if either(StrayLoadLoss) {
        Separator::TorqueOrLockedRotorFrequency
    } else {
        Separator::VoltageAndLockedRotorFrequency
    }
}

/// The test plan that separates effect `a` from effect `b`.
pub fn separating_plan(a: Effect, b: Effect) -> String {
    match separator(a, b) {
        Separator::LockedRotorVoltageAndFrequency => {
            "a locked-rotor test at reduced voltage (leakage saturation depends on the current, deep bar does not) \
             and at reduced frequency (deep bar depends on the rotor frequency)"
        }
        Separator::ReducedVoltage => {
            "a second sweep (or a no-load test) at a reduced supply voltage, e.g. 60–80 % of rated: \
             main-flux saturation makes Xm change with the voltage"
        }
        Separator::TimeOrder => {
            "the sweep repeated in reverse order (locked rotor first), or its first points repeated at the end: \
             thermal drift follows the time order, not the slip"
        }
        Separator::NoLoadAgainstStrayLoss => {
            "a no-load test at several voltages: iron loss grows with the air-gap voltage squared, \
             stray load loss with the load current squared"
        }
        Separator::NoLoadVoltages => "a no-load test at several voltages (iron loss: power ∝ E², at no load)",
        Separator::TorqueOrLockedRotorFrequency => {
            "a torque sensor on the shaft (stray load loss takes input power without producing torque) \
             or a locked-rotor test at reduced frequency"
        }
        Separator::VoltageAndLockedRotorFrequency => {
            "a second sweep at another supply voltage, and a locked-rotor test at reduced frequency"
        }
    }
    .into()
}

/// Where the record already holds the test that separates `a` from `b`
/// ([`separating_plan`]), what that leaves: both effects, or one in a
/// form other than its candidate's. `None` where it does not hold it.
pub fn held_note(a: Effect, b: Effect, held: HeldTests) -> Option<String> {
    let what = match separator(a, b) {
        Separator::ReducedVoltage => held
            .several_voltages
            .then_some("readings at several voltages"),
        Separator::NoLoadAgainstStrayLoss | Separator::NoLoadVoltages => {
            (held.no_load && held.several_voltages).then_some("a no-load test at several voltages")
        }
        Separator::TorqueOrLockedRotorFrequency => held.torque.then_some("a torque reading"),
        _ => None,
    }?;
    Some(format!(
        "the record holds {what}, and still the two fit alike: it likely holds both, or one \
         in a form other than its candidate's"
    ))
}

/// [`separating_plan`], followed by the [`held_note`] where there is one.
pub fn separating_plan_for(a: Effect, b: Effect, held: HeldTests) -> String {
    let plan = separating_plan(a, b);
    match held_note(a, b, held) {
        Some(note) => format!("{plan}; {note}"),
        None => plan,
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

    /// A record that holds the separating test is not asked for it again;
    /// one that lacks it gets the plan alone.
    #[test]
    fn a_test_the_record_holds_is_not_asked_for() {
        // The plan alone: the record lacks the separating test.
        let plan_alone =
            |a, b, held| assert_eq!(separating_plan_for(a, b, held), separating_plan(a, b));
        let (sat, iron) = (Effect::MainFluxSaturation, Effect::IronLoss);
        let none = HeldTests::default();
        plan_alone(sat, iron, none);
        let voltages = HeldTests {
            several_voltages: true,
            ..none
        };
        let plan = separating_plan_for(sat, iron, voltages);
        assert!(plan.starts_with(&separating_plan(sat, iron)), "{plan}");
        assert!(
            plan.contains("the record holds readings at several voltages"),
            "{plan}"
        );
        // An iron loss against stray load loss needs the no-load test.
        let stray = Effect::StrayLoadLoss;
        plan_alone(iron, stray, voltages);
        let no_load = HeldTests {
            no_load: true,
            ..voltages
        };
        assert!(separating_plan_for(iron, stray, no_load).contains("holds a no-load test"));
    }
}
