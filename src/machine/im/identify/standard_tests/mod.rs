//! The classical reduction of the induction machine's standard tests
//! (IEEE 112 Method F's equivalent-circuit tests, IEC 60034-28,
//! IEC 60034-2-1): method `standard_tests`, from the record's
//! `im_dc_resistance`, `im_no_load` and `im_locked_rotor` segments.
//!
//! - `Rs` from the DC test, per phase for the connection, corrected with
//!   copper's α to the locked-rotor test's winding temperature (and to the
//!   no-load test's for its copper loss) when the files give them;
//! - friction and windage `Pfw` from the no-load constant losses against
//!   V², extrapolated to V = 0; per voltage the core loss, `Xm` and `Rfe`;
//!   the fitted `Xm(V)`; `Xm`, `Rfe` and the core loss `Pfe` at rated
//!   voltage;
//! - `R_lr`, `X_lr` from the locked-rotor test; `Xs` and `Xr` in the
//!   design class's ratio, `Rr` behind the magnetising branch (IEEE 112's
//!   `Xm` correction), reactances scaled to rated frequency when the
//!   locked-rotor test ran at a reduced one. With locked-rotor readings at
//!   two frequencies (rated and reduced), the circuit takes the lowest
//!   frequency's (IEEE 112: the rotor resistance nearest its running slip
//!   frequency) and the highest frequency's rotor resistance and
//!   reactance are reported beside it (`Rr_rated_frequency`,
//!   `Xr_rated_frequency`): a deep-bar or double-cage rotor shows there.
//!
//! Every element carries a 95 % interval where the regressions give one
//! (two readings or more per regression), carried through the reduction
//! by first derivatives. A missing test or unusable data make the method
//! not apply, with the reason.

mod dc_resistance;
mod error;
mod locked_rotor;
mod no_load;
mod phase;
mod reduce;
mod regression;
#[cfg(test)]
mod tests;

use std::collections::BTreeMap;

pub(crate) use dc_resistance::temperature_factor;
use dc_resistance::{dc_resistance, mean_temperature};
use locked_rotor::{common_frequency, frequency_groups, locked_rotor};
use reduce::{elements, propagate, solve, Context, Inputs};

use crate::contract::{MethodReport, ParamEstimate, StandardTestTables};
use crate::model::{Connection, ImCircuit, LeakageSplit, RotorCage};
use crate::record::ImStandardTests;

pub use error::StandardTestsError;
pub use no_load::{no_load_friction, NoLoadFriction, FRICTION_VOLTAGE_SHARE};

/// The method's key in the report.
pub const STANDARD_TESTS: &str = "standard_tests";

/// What the reduction takes from the nameplate and the caller.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct StandardTestsOptions {
    /// The leakage split's convention (NEMA design class).
    pub split: LeakageSplit,
    /// Rated line voltage, V (else the highest no-load voltage).
    pub rated_voltage: Option<f64>,
    /// Rated frequency, Hz (else the no-load test's).
    pub rated_frequency: Option<f64>,
}

/// The reduction's result.
#[derive(Debug, Clone, PartialEq)]
pub struct StandardTestsReduction {
    /// The circuit, Ω per phase at rated frequency.
    pub circuit: ImCircuit,
    /// The contract's parameters with their 95 % intervals: `Rs`, `Xs`,
    /// `Xm`, `Rfe`, `Rr`, `Xr` (Ω), `Pfw`, `Pfe` (W).
    pub params: BTreeMap<String, ParamEstimate>,
    /// The per-voltage and per-point tables and the `Xm(V)` curve.
    pub tables: StandardTestTables,
    /// The winding temperature `Rs` is at, °C: the locked-rotor test's
    /// where the DC reading and that test give one, the DC reading's
    /// where only it does; `None` when the DC reading gives none.
    pub rs_temperature: Option<f64>,
    /// The rated line voltage the reduction took, V (the nameplate's, else
    /// the highest no-load voltage).
    pub rated_voltage: f64,
    /// The no-load test's air-gap voltage per phase at rated voltage, V
    /// at rated frequency (the table's `E` interpolated to the rated line
    /// voltage, held at its ends): where `Xm` is reported.
    pub rated_air_gap_voltage: Option<f64>,
    /// What a user should know (conventions, corrections, assumptions).
    pub warnings: Vec<String>,
}

/// The tests missing for the reduction, named by their segment kinds.
fn missing(tests: &ImStandardTests) -> Option<StandardTestsError> {
    let names: Vec<&str> = [
        (
            tests.dc_resistance.is_empty(),
            "no im_dc_resistance segment",
        ),
        (tests.no_load.is_empty(), "no im_no_load segment"),
        (tests.locked_rotor.is_empty(), "no im_locked_rotor segment"),
    ]
    .into_iter()
    .filter_map(|(m, n)| m.then_some(n))
    .collect();
    (!names.is_empty()).then(|| StandardTestsError::Missing(names.join(", ")))
}

fn estimate(value: f64, hw: Option<f64>, unit: &str) -> ParamEstimate {
    ParamEstimate {
        value,
        // A positive element's interval stops at 0.
        ci95: hw.map(|h| [(value - h).max(0.0), value + h]),
        unit: unit.into(),
    }
}

/// Reduce the standard tests of a winding connected as `connection`.
pub fn reduce_standard_tests(
    tests: &ImStandardTests,
    connection: Connection,
    opts: &StandardTestsOptions,
) -> Result<StandardTestsReduction, StandardTestsError> {
    if let Some(why) = missing(tests) {
        return Err(why);
    }
    if let Some(groups) = frequency_groups(&tests.locked_rotor) {
        return reduce_two_frequencies(tests, connection, opts, groups);
    }
    let mut warnings = Vec::new();
    let dc = dc_resistance(&tests.dc_resistance, connection)?;
    let lr = locked_rotor(&tests.locked_rotor, connection)?;
    let f_nl = common_frequency(&tests.no_load, "no-load")?;
    let f_lr = common_frequency(&tests.locked_rotor, "locked-rotor")?;
    let f_rated = opts
        .rated_frequency
        .filter(|f| *f > 0.0)
        .or(f_nl.is_finite().then_some(f_nl));
    let (f_nl, f_lr) = match (f_nl.is_finite(), f_lr.is_finite()) {
        (true, true) => (f_nl, f_lr),
        (false, false) => {
            warnings.push(
                "standard_tests: no frequency given (frequency_Hz, --frequency or the nameplate): \
                 the no-load and locked-rotor tests are taken to run at one frequency"
                    .into(),
            );
            (1.0, 1.0)
        }
        (true, false) => (f_nl, f_nl),
        (false, true) => (f_lr, f_lr),
    };
    let rated_voltage = match opts.rated_voltage.filter(|v| *v > 0.0) {
        Some(v) => v,
        None => {
            let v = tests
                .no_load
                .iter()
                .map(|r| r.line_voltage)
                .fold(0.0, f64::max);
            warnings.push(format!(
                "standard_tests: no rated voltage on the nameplate (voltage_V): the highest \
                 no-load voltage, {v} V, stands for it"
            ));
            v
        }
    };
    let t_nl = mean_temperature(tests.no_load.iter().map(|r| r.winding_temperature));
    let t_lr = mean_temperature(tests.locked_rotor.iter().map(|r| r.winding_temperature));
    let ctx = Context {
        no_load: &tests.no_load,
        connection,
        k_no_load: temperature_factor(dc.temperature, t_nl),
        k_locked: temperature_factor(dc.temperature, t_lr),
        f_ratio: f_nl / f_lr,
        rated_voltage,
        split: opts.split,
    };
    let at = Inputs {
        rs_dc: dc.rs,
        rlr: lr.rlr.0,
        xlr: lr.xlr.0,
        pfw_offset: 0.0,
    };
    let s = solve(&ctx, at)?;
    let pfw_hw = s.pfw_half_width.unwrap_or(0.0);
    let hw = propagate(
        &ctx,
        at,
        [
            dc.half_width.unwrap_or(0.0),
            lr.rlr.1.unwrap_or(0.0),
            lr.xlr.1.unwrap_or(0.0),
            pfw_hw,
        ],
    );
    // An element has an interval when every input it depends on has one.
    let all_inputs = dc.half_width.is_some()
        && lr.rlr.1.is_some()
        && lr.xlr.1.is_some()
        && s.pfw_half_width.is_some();
    let hw = hw.map(|h| h.filter(|_| all_inputs));
    // To rated frequency from the no-load frequency.
    let k_f = f_rated.map_or(1.0, |f| f / f_nl);
    let v = elements(&s);
    let mut params = BTreeMap::new();
    let put = |params: &mut BTreeMap<String, ParamEstimate>,
               key: &str,
               k: usize,
               scale: f64,
               unit: &str| {
        if v[k].is_finite() {
            params.insert(
                key.to_string(),
                estimate(scale * v[k], hw[k].map(|h| scale * h), unit),
            );
        }
    };
    put(&mut params, "Rs", 0, 1.0, "ohm");
    put(&mut params, "Xs", 1, k_f, "ohm");
    put(&mut params, "Xr", 2, k_f, "ohm");
    put(&mut params, "Rr", 3, 1.0, "ohm");
    put(&mut params, "Pfw", 7, 1.0, "W");
    // Xm's and Rfe's intervals add the scatter of their own regressions
    // to the propagated one; the core loss shares Rfe's relative interval.
    let quadrature = |a: Option<f64>, b: Option<f64>| a.zip(b).map(|(a, b)| a.hypot(b));
    let xm_hw = quadrature(hw[4], s.xm_curve_half_width);
    params.insert(
        "Xm".into(),
        estimate(k_f * s.xm, xm_hw.map(|h| k_f * h), "ohm"),
    );
    if let (Some(rfe), Some(pfe)) = (s.rfe, s.pfe) {
        let rfe_hw = quadrature(hw[5], s.rfe_fit_half_width);
        params.insert("Rfe".into(), estimate(rfe, rfe_hw, "ohm"));
        params.insert(
            "Pfe".into(),
            estimate(pfe, rfe_hw.map(|h| pfe * h / rfe), "W"),
        );
    }

    warnings.push(format!(
        "standard_tests: the leakage split is a convention, not a measurement: Xs/(Xs + Xr) = \
         {} (IEEE 112's NEMA design-class ratio: A and D 0.5, B 0.4, C 0.3, wound rotor 0.5; \
         the nameplate's \"design\" picks it, 0.5 when it gives none)",
        opts.split.stator_share
    ));
    let at = match (dc.temperature, t_lr) {
        (Some(a), Some(b)) => format!(
            "taken at {a:.1} °C and corrected to the locked-rotor test's {b:.1} °C (copper, \
             α = 0.00393/K at 20 °C)"
        ),
        (Some(a), None) => format!(
            "at its own {a:.1} °C (the locked-rotor test gives no winding temperature to \
             correct it to)"
        ),
        (None, _) => "at the DC reading's unstated winding temperature".to_string(),
    };
    warnings.push(format!(
        "standard_tests: Rs is the DC reading per phase for the {connection} connection, {at}"
    ));
    if (t_nl.is_some() || t_lr.is_some()) && dc.temperature.is_none() {
        warnings.push(
            "standard_tests: the DC reading has no winding temperature: Rs is not corrected to \
             the other tests' temperatures"
                .into(),
        );
    }
    if (f_lr - f_nl).abs() > 0.01 * f_nl {
        warnings.push(format!(
            "standard_tests: the locked-rotor test ran at {f_lr} Hz: its reactances are scaled \
             to {} Hz in proportion to frequency; Rr is the rotor resistance at that slip \
             frequency",
            f_rated.unwrap_or(f_nl)
        ));
    }
    if let Some(n) = &s.friction_note {
        warnings.push(format!("standard_tests: {n}"));
    }
    if s.pfw_raw < 0.0 {
        let significant = s.pfw_raw + pfw_hw < 0.0;
        warnings.push(format!(
            "standard_tests: the no-load constant losses extrapolate to {:.2} W at V = 0{}; \
             friction and windage taken as 0 W (a wattmeter offset, or core loss not \
             proportional to V² at the voltages used)",
            s.pfw_raw,
            if significant {
                ", significantly below 0"
            } else {
                ", within its interval of 0"
            }
        ));
    }
    if s.rfe.is_none() {
        warnings.push(
            "standard_tests: no no-load reading leaves a core loss above 0 once friction and \
             windage are taken off: no Rfe"
                .into(),
        );
    }
    let skipped = s
        .rows
        .iter()
        .filter(|r| r.xm.is_none() || r.rfe.is_none())
        .count();
    if skipped > 0 {
        warnings.push(format!(
            "standard_tests: {skipped} no-load reading(s) give no Xm or no Rfe (reactive power \
             not above the stator leakage's, or core loss not above 0): left out of those columns"
        ));
    }
    let circuit = ImCircuit {
        rs: s.rs,
        xs: k_f * s.xs,
        xm: k_f * s.xm,
        rfe: s.rfe,
        rotor: RotorCage::Single {
            rr: s.rr,
            xr: k_f * s.xr,
        },
    };
    let rated_air_gap_voltage =
        no_load::interpolate(&s.rows, rated_voltage, |r| Some(r.air_gap_voltage)).map(|e| k_f * e);
    Ok(StandardTestsReduction {
        circuit,
        rated_voltage,
        rated_air_gap_voltage,
        params,
        tables: StandardTestTables {
            no_load: s.rows,
            locked_rotor: lr.rows,
            xm_curve: s.curve,
        },
        rs_temperature: dc.temperature.map(|t| t_lr.unwrap_or(t)),
        warnings,
    })
}

/// The reduction of tests whose locked-rotor readings ran at several
/// frequencies, `groups` (lowest first, each of one frequency): the
/// circuit from the lowest, the rotor from the highest beside it.
fn reduce_two_frequencies(
    tests: &ImStandardTests,
    connection: Connection,
    opts: &StandardTestsOptions,
    groups: Vec<Vec<crate::record::SupplyReading>>,
) -> Result<StandardTestsReduction, StandardTestsError> {
    let frequency = |g: &[crate::record::SupplyReading]| g[0].frequency;
    let with = |locked_rotor: &[crate::record::SupplyReading]| ImStandardTests {
        locked_rotor: locked_rotor.to_vec(),
        ..tests.clone()
    };
    let (low, high) = (&groups[0], &groups[groups.len() - 1]);
    let mut r = reduce_standard_tests(&with(low), connection, opts)?;
    let (f_low, f_high) = (frequency(low), frequency(high));
    match reduce_standard_tests(&with(high), connection, opts) {
        Ok(at_high) => {
            for key in ["Rr", "Xr"] {
                if let Some(p) = at_high.params.get(key) {
                    r.params.insert(format!("{key}_rated_frequency"), p.clone());
                }
            }
            let rr =
                |m: &BTreeMap<String, ParamEstimate>| m.get("Rr").map_or(f64::NAN, |p| p.value);
            let (rr_low, rr_high) = (rr(&r.params), rr(&at_high.params));
            r.warnings.push(format!(
                "standard_tests: locked-rotor tests at {f_low} Hz and {f_high} Hz: the circuit \
                 takes the {f_low} Hz test's (IEEE 112: nearest the rotor's running slip \
                 frequency); the {f_high} Hz test gives Rr = {rr_high:.4} ohm ({:+.1} %), \
                 reported as Rr_rated_frequency and Xr_rated_frequency (a deep-bar or \
                 double-cage rotor's resistance rises with the slip frequency)",
                100.0 * (rr_high / rr_low - 1.0)
            ));
            r.tables.locked_rotor.extend(at_high.tables.locked_rotor);
        }
        Err(why) => r.warnings.push(format!(
            "standard_tests: the locked-rotor test at {f_high} Hz does not reduce: {why}"
        )),
    }
    if groups.len() > 2 {
        r.warnings.push(format!(
            "standard_tests: locked-rotor readings at {} frequencies: those between {f_low} Hz \
             and {f_high} Hz are left out",
            groups.len()
        ));
    }
    Ok(r)
}

/// The method's report, the tables, and the warnings to add to the
/// report's; `None` when the record holds none of the standard tests (the
/// method is then left out, so slip-sweep reports stay as they were).
pub fn standard_tests_method(
    tests: &ImStandardTests,
    connection: Connection,
    opts: &StandardTestsOptions,
) -> Option<(MethodReport, Option<StandardTestsReduction>)> {
    if tests.is_empty() {
        return None;
    }
    Some(match reduce_standard_tests(tests, connection, opts) {
        Ok(r) => (MethodReport::fitted(r.params.clone(), None), Some(r)),
        Err(why) => (MethodReport::not_applicable(why.to_string()), None),
    })
}
