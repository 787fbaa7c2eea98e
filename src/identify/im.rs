//! Induction-machine identification of a record: the operating points of
//! its `im_slip_sweep` segments in, the contract report (methods
//! `recursive` and `lm`) out.
//!
//! - `lm` ([`fit_lm`]): parameters in Ω with 95 % intervals; an element the
//!   data do not determine is left out of `params` and named in the
//!   warnings; `Xs` under the leakage-split convention is reported with a
//!   warning that says so. `validation_nrmse` is the mean, over segments, of
//!   the NRMSE of current and power on a segment left out of the fit (it
//!   needs two segments, e.g. sweeps at two voltages).
//! - `recursive` ([`recursive_estimate`]): the seed paper's estimator as
//!   printed, run in per unit (the paper's threshold `J < 10⁻⁴` only means
//!   something there) from the first classical start; it applies when it
//!   ends with physical parameters; no intervals.

use super::im_classical::classical_starts;
use super::im_lm::{fit_lm, LmFit, LmOptions};
use super::im_recursive::{recursive_estimate, RecursiveEstimate, RecursiveOptions, RecursiveStop};
use super::im_sweep::{predict, SlipSweep, SweepPoint};
use super::nrmse;
use crate::model::{Connection, ImCircuit, ImModel, PerUnitBase};
use crate::record::{Record, SegmentKind};
use crate::report::{IdentificationReport, MethodReport, ParamEstimate};

/// Everything induction-machine identification produced.
#[derive(Debug, Clone, PartialEq)]
pub struct ImIdentification {
    /// The report per the data contract.
    pub report: IdentificationReport,
    /// The sweep the fits used.
    pub sweep: SlipSweep,
    /// The per-unit base used for the recursive estimator and the text
    /// report (rated values from the nameplate, else from the data).
    pub base: Option<PerUnitBase>,
    /// The Levenberg–Marquardt fit, when it ran.
    pub lm: Option<LmFit>,
    /// The recursive estimate, when it ran (circuit in Ω).
    pub recursive: Option<RecursiveEstimate>,
}

fn nameplate_number(record: &Record, key: &str) -> Option<f64> {
    record.meta.as_ref()?.nameplate.get(key)?.as_f64()
}

/// The connection to use: the caller's, else the nameplate's.
fn connection_of(
    record: &Record,
    given: Option<Connection>,
    warnings: &mut Vec<String>,
) -> Connection {
    if let Some(c) = given {
        return c;
    }
    let from_plate = record
        .meta
        .as_ref()
        .and_then(|m| m.nameplate.get("connection"))
        .and_then(|v| v.as_str())
        .and_then(Connection::parse);
    from_plate.unwrap_or_else(|| {
        warnings.push(
            "no winding connection given (--connection or the nameplate's \"connection\"): star assumed; \
             per-phase impedances scale by 3 between star and delta"
                .into(),
        );
        Connection::Star
    })
}

/// The sweep of `record`'s operating points.
pub fn sweep_of(record: &Record, connection: Connection) -> SlipSweep {
    let points: Vec<SweepPoint> = record
        .operating_points
        .iter()
        .map(|p| SweepPoint {
            segment: p.segment,
            slip: p.slip,
            line_voltage: p.line_voltage,
            line_current: p.line_current,
            input_power: p.input_power,
            torque: p.torque,
        })
        .collect();
    let frequency = record
        .operating_points
        .iter()
        .map(|p| p.frequency)
        .find(|f| f.is_finite());
    SlipSweep {
        connection,
        frequency,
        points,
    }
}

fn params_of(
    values: &[(String, f64, Option<[f64; 2]>)],
) -> std::collections::BTreeMap<String, ParamEstimate> {
    values
        .iter()
        .map(|(k, v, ci)| {
            (
                k.clone(),
                ParamEstimate {
                    value: *v,
                    ci95: *ci,
                    unit: "ohm".into(),
                },
            )
        })
        .collect()
}

/// Mean NRMSE of current and power of `c` on `points`.
fn sweep_nrmse(c: &ImCircuit, sweep: &SlipSweep, segment: u32) -> Option<f64> {
    let part = SlipSweep {
        points: sweep
            .points
            .iter()
            .copied()
            .filter(|p| p.segment == segment)
            .collect(),
        ..sweep.clone()
    };
    let d = part.phase_data();
    let (mut i, mut p) = (Vec::new(), Vec::new());
    for k in 0..d.len() {
        let (ik, pk) = predict(c, d.slip[k], d.voltage[k]);
        i.push(ik);
        p.push(pk);
    }
    let parts: Vec<f64> = [nrmse(&d.current, &i), nrmse(&d.power, &p)]
        .into_iter()
        .flatten()
        .collect();
    (!parts.is_empty()).then(|| parts.iter().sum::<f64>() / parts.len() as f64)
}

fn lm_method(
    sweep: &SlipSweep,
    model: ImModel,
    warnings: &mut Vec<String>,
) -> (MethodReport, Option<LmFit>) {
    let data = sweep.phase_data();
    let opts = LmOptions::new(model);
    let fit = match fit_lm(&data, &opts) {
        Ok(f) => f,
        Err(reason) => return (MethodReport::not_applicable(reason), None),
    };
    let mut values = Vec::new();
    for p in &fit.params {
        if p.identifiable {
            values.push((p.param.key().to_string(), p.value, p.ci95));
        }
    }
    if !fit.identifiability.unidentifiable.is_empty() {
        let names: Vec<&str> = fit
            .identifiability
            .unidentifiable
            .iter()
            .map(|p| p.key())
            .collect();
        warnings.push(format!(
            "lm: {} not determined by these data (left out of the parameters); record input power, or fix Rs (DC test) and Xm",
            names.join(", ")
        ));
    }
    for w in &fit.identifiability.weak_before_convention {
        warnings.push(format!(
            "lm: weak direction with every element free: {}",
            w.describe()
        ));
    }
    if let Some(c) = &fit.identifiability.convention {
        warnings.push(format!(
            "lm: the leakage split is a convention, not a measurement: {c}"
        ));
    }
    warnings.extend(fit.warnings.iter().map(|w| format!("lm: {w}")));

    // Leave one segment out.
    let segments: std::collections::BTreeSet<u32> =
        sweep.points.iter().map(|p| p.segment).collect();
    let mut scores = Vec::new();
    if segments.len() >= 2 {
        for &held in &segments {
            let rest = SlipSweep {
                points: sweep
                    .points
                    .iter()
                    .copied()
                    .filter(|p| p.segment != held)
                    .collect(),
                ..sweep.clone()
            };
            if let Ok(f) = fit_lm(&rest.phase_data(), &opts) {
                scores.extend(sweep_nrmse(&f.circuit, sweep, held));
            }
        }
    } else {
        warnings.push(
            "lm: one sweep only, so no held-out validation (sweep at a second voltage for one)"
                .into(),
        );
    }
    let validation_nrmse =
        (!scores.is_empty()).then(|| scores.iter().sum::<f64>() / scores.len() as f64);
    let report = MethodReport {
        applies: true,
        params: Some(params_of(&values)),
        validation_nrmse,
        reason: None,
    };
    (report, Some(fit))
}

fn recursive_method(
    sweep: &SlipSweep,
    model: ImModel,
    base: &PerUnitBase,
    warnings: &mut Vec<String>,
) -> (MethodReport, Option<RecursiveEstimate>) {
    let data = sweep.phase_data();
    let start = match classical_starts(&data, model, Default::default(), None) {
        Ok(s) => s[0],
        Err(reason) => return (MethodReport::not_applicable(reason), None),
    };
    let pu = data.per_unit(base.phase_voltage, base.phase_current);
    let start_pu = start.to_per_unit(base);
    let mut est = recursive_estimate(&pu, &start_pu, model.params(), &RecursiveOptions::default());
    est.circuit = ImCircuit::from_per_unit(&est.circuit, base);
    let report = match est.stop {
        RecursiveStop::NonPhysical { param, value } => MethodReport::not_applicable(format!(
            "the paper's estimator stopped at its step 8 on pass {}: {param} went to {value:.4} p.u. (non-physical)",
            est.iterations
        )),
        RecursiveStop::Numerical => MethodReport::not_applicable("the paper's estimator produced a non-finite value"),
        RecursiveStop::Threshold | RecursiveStop::MaxIterations => {
            if est.stop == RecursiveStop::MaxIterations {
                warnings.push(format!(
                    "recursive: J = {:.3e} p.u.² after {} passes, above the paper's threshold 1e-4",
                    est.cost, est.iterations
                ));
            }
            let values: Vec<(String, f64, Option<[f64; 2]>)> = model
                .params()
                .iter()
                .map(|&p| (p.key().to_string(), est.circuit.get(p).unwrap_or(f64::NAN), None))
                .collect();
            MethodReport { applies: true, params: Some(params_of(&values)), validation_nrmse: None, reason: None }
        }
    };
    (report, Some(est))
}

/// Identify an induction machine from `record`'s operating points.
/// `connection` overrides the nameplate's.
pub fn identify_im(
    record: &Record,
    connection: Option<Connection>,
    model: ImModel,
) -> ImIdentification {
    let mut report = IdentificationReport::new(SegmentKind::ImSlipSweep.as_str());
    let mut warnings = Vec::new();
    let conn = connection_of(record, connection, &mut warnings);
    let sweep = sweep_of(record, conn);
    if let Some(r) = &record.recovery {
        warnings.push(format!(
            "the record was damaged: {} messages recovered ({})",
            r.messages, r.reason
        ));
    }
    if let Err(reason) = sweep.validate() {
        for key in ["lm", "recursive"] {
            report
                .methods
                .insert(key.into(), MethodReport::not_applicable(reason.clone()));
        }
        report.warnings = warnings;
        return ImIdentification {
            report,
            sweep,
            base: None,
            lm: None,
            recursive: None,
        };
    }
    let data = sweep.phase_data();
    let base = match (
        nameplate_number(record, "voltage_V"),
        nameplate_number(record, "current_A"),
    ) {
        (Some(v), Some(i)) if v > 0.0 && i > 0.0 => PerUnitBase::from_rating(v, i, conn),
        _ => {
            let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len() as f64;
            let mut sorted = data.current.clone();
            sorted.sort_by(f64::total_cmp);
            warnings.push(
                "per-unit base from the data (mean voltage, median current): the nameplate has no voltage_V and current_A"
                    .into(),
            );
            PerUnitBase {
                phase_voltage: mean(&data.voltage),
                phase_current: sorted[sorted.len() / 2],
            }
        }
    };
    let (lm_report, lm) = lm_method(&sweep, model, &mut warnings);
    let (rec_report, recursive) = recursive_method(&sweep, model, &base, &mut warnings);
    report.methods.insert("lm".into(), lm_report);
    report.methods.insert("recursive".into(), rec_report);
    report.refuse_unphysical();
    report.best = ["lm", "recursive"]
        .into_iter()
        .find(|m| report.methods[*m].applies)
        .map(String::from);
    report.warnings = warnings;
    ImIdentification {
        report,
        sweep,
        base: Some(base),
        lm,
        recursive,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::identify::im_sweep::{slip_grid, SweepNoise};
    use crate::model::{ImSupply, RotorCage};
    use crate::record::OperatingPoint;
    use rand::rngs::StdRng;
    use rand::SeedableRng;

    fn record(circuit: &ImCircuit, voltages: &[f64], noise: f64) -> Record {
        let mut rng = StdRng::seed_from_u64(11);
        let mut points = Vec::new();
        for (seg, &v) in voltages.iter().enumerate() {
            let supply = ImSupply {
                line_voltage: v,
                frequency: 50.0,
                connection: Connection::Delta,
                pole_pairs: 2,
            };
            let sw = SlipSweep::simulate(
                circuit,
                &supply,
                &slip_grid(40, 0.002),
                &SweepNoise::relative(noise),
                seg as u32,
                &mut rng,
            );
            points.extend(sw.points.iter().map(|p| OperatingPoint {
                segment: p.segment,
                slip: p.slip,
                line_voltage: p.line_voltage,
                line_current: p.line_current,
                input_power: p.input_power,
                speed: (1.0 - p.slip) * std::f64::consts::PI * 50.0,
                frequency: 50.0,
                torque: p.torque,
            }));
        }
        Record {
            operating_points: points,
            ..Record::default()
        }
    }

    fn machine() -> ImCircuit {
        ImCircuit {
            rs: 1.5,
            xs: 3.0,
            xm: 90.0,
            rfe: None,
            rotor: RotorCage::Single { rr: 1.6, xr: 3.0 },
        }
    }

    #[test]
    fn report_has_both_methods_and_validates_on_held_out_segments() {
        let id = identify_im(
            &record(&machine(), &[230.0, 180.0], 0.002),
            Some(Connection::Delta),
            ImModel::Single,
        );
        let json: serde_json::Value = serde_json::from_str(&id.report.to_json_pretty()).unwrap();
        assert_eq!(json["kind"], "im_slip_sweep");
        assert_eq!(json["best"], "lm");
        let lm = &json["methods"]["lm"];
        assert_eq!(lm["applies"], true);
        let rs = &lm["params"]["Rs"];
        assert_eq!(rs["unit"], "ohm");
        let [lo, hi] = [
            rs["ci95"][0].as_f64().unwrap(),
            rs["ci95"][1].as_f64().unwrap(),
        ];
        assert!(lo <= 1.5 && 1.5 <= hi, "Rs interval [{lo}, {hi}]");
        assert!(lm["validation_nrmse"].as_f64().unwrap() < 0.05);
        assert!(json["methods"]["recursive"].is_object());
        assert!(
            id.report.warnings.iter().any(|w| w.contains("convention")),
            "{:?}",
            id.report.warnings
        );
    }

    #[test]
    fn connection_comes_from_the_nameplate_or_is_assumed_with_a_warning() {
        let mut r = record(&machine(), &[230.0], 0.002);
        let id = identify_im(&r, None, ImModel::Single);
        assert_eq!(id.sweep.connection, Connection::Star);
        assert!(id
            .report
            .warnings
            .iter()
            .any(|w| w.contains("star assumed")));
        r.meta = Some(crate::record::TestMeta {
            schema_version: "1".into(),
            kind: SegmentKind::ImSlipSweep,
            motor_id: "m".into(),
            started_at: String::new(),
            nameplate: serde_json::json!({"connection": "delta", "voltage_V": 230.0, "current_A": 4.0}),
            config: String::new(),
        });
        let id = identify_im(&r, None, ImModel::Single);
        assert_eq!(id.sweep.connection, Connection::Delta);
        assert_eq!(id.base.unwrap().phase_current, 4.0 / 3f64.sqrt());
    }

    #[test]
    fn an_empty_record_is_not_applicable() {
        let id = identify_im(&Record::default(), Some(Connection::Star), ImModel::Double);
        assert!(id.report.best.is_none());
        assert!(!id.report.methods["lm"].applies);
        assert!(id.report.methods["lm"]
            .reason
            .as_deref()
            .unwrap()
            .contains("no operating points"));
    }
}
