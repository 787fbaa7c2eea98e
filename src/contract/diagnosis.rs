//! The diagnosis report, as the data contract's diagnosis JSON spells it
//! (`motorbench diagnose … --json`), with the extra evidence motorbench
//! adds beside the contract's required keys.

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

use super::ParamEstimate;

/// The nominal model: the paper's model as identification produces it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct NominalFit {
    /// Model name, e.g. `dc_nominal` or `single_cage`.
    pub model: String,
    /// Parameters by contract key, fitted on all segments (or points).
    pub params: BTreeMap<String, ParamEstimate>,
    /// NRMSE on the data the model was fitted to.
    pub fit_nrmse: f64,
    /// NRMSE on held-out data (leave-one-segment-out, or leave-one-voltage-out).
    pub validation_nrmse: f64,
}

/// Along which axis a region of the gap lies.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum RegionAxis {
    /// Seconds since the start of the segment (DC).
    Time,
    /// Slip, 0 synchronous to 1 locked rotor (IM).
    Slip,
    /// Line voltage, V (IM: the free-running points of a no-load test).
    Voltage,
}

/// One region of the gap: where a share of the squared residual lies.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct GapRegion {
    /// Channel, e.g. `armature_current`, `speed`, `line_current`, `input_power`.
    pub channel: String,
    /// The axis `from` and `to` are measured on.
    pub axis: RegionAxis,
    /// Start of the region on its axis.
    pub from: f64,
    /// End of the region on its axis.
    pub to: f64,
    /// What the region is: DC `transient`, `settled`, `start_up`,
    /// `coast_down`, `oscillation`; IM `low_slip`, `breakdown`, `high_slip`.
    pub label: String,
    /// Share of the whole record's squared (noise-weighted) held-out
    /// residual that falls in this region, 0–1.
    pub share: f64,
    /// Segment index (DC) or supply voltage (IM, V) the region belongs to,
    /// when it belongs to one.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub segment: Option<u32>,
    /// Supply voltage of the region (IM), V.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub voltage: Option<f64>,
}

/// A residual statistic offered as evidence (whiteness, correlation with
/// the input or with a state).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ResidualEvidence {
    /// Channel the statistic is of.
    pub channel: String,
    /// What was measured, e.g. `whiteness`, `corr_sign_speed`,
    /// `corr_abs_current`, `corr_time`, `corr_input`, `spectral_peak_hz`.
    pub statistic: String,
    /// Its value.
    pub value: f64,
    /// Its p-value under "the residual is noise", where one is defined.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub p_value: Option<f64>,
}

/// Where the gap lies.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct Gap {
    /// Regions, largest share first.
    pub regions: Vec<GapRegion>,
    /// Share of the squared residual per channel.
    #[serde(default)]
    pub channels: BTreeMap<String, f64>,
    /// Share of the squared residual per segment (DC, key = segment index)
    /// or per supply voltage (IM, key = voltage in V).
    #[serde(default)]
    pub segments: BTreeMap<String, f64>,
    /// Residual statistics.
    #[serde(default)]
    pub evidence: Vec<ResidualEvidence>,
    /// The NRMSE that noise alone would give (estimated from the data).
    pub noise_floor: f64,
}

/// One candidate effect, refitted with the nominal parameters.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Candidate {
    /// Effect name from the contract's vocabulary.
    pub effect: String,
    /// The effect's own parameters (physical units) with intervals.
    pub params: BTreeMap<String, ParamEstimate>,
    /// Held-out NRMSE of the augmented model.
    pub validation_nrmse: f64,
    /// 1 − validation_nrmse / nominal validation_nrmse.
    pub shrink: f64,
    /// Ranking score (held-out improvement with a penalty per parameter;
    /// higher is better).
    pub score: f64,
    /// p-value of "this candidate does not shrink the held-out gap",
    /// corrected for the number of candidates tried.
    pub p_value: f64,
    /// The nominal parameters refitted together with the effect.
    #[serde(default)]
    pub nominal_params: BTreeMap<String, ParamEstimate>,
}

impl Candidate {
    /// The first of its numbers that is not finite (a parameter, a bound
    /// of an interval, a score), named, with the number: JSON has no NaN
    /// or infinity, so such a candidate cannot be reported.
    pub fn non_finite(&self) -> Option<(&str, f64)> {
        let params = self
            .params
            .iter()
            .chain(&self.nominal_params)
            .flat_map(|(k, p)| {
                std::iter::once((k.as_str(), p.value))
                    .chain(p.ci95.iter().flatten().map(move |v| (k.as_str(), *v)))
            });
        let scores = [
            ("validation_nrmse", self.validation_nrmse),
            ("shrink", self.shrink),
            ("score", self.score),
            ("p_value", self.p_value),
        ];
        params.chain(scores).find(|(_, v)| !v.is_finite())
    }
}

/// `candidates` without those holding a non-finite number or a parameter
/// outside its physical range (such a candidate is never a verdict); each
/// dropped one is named, with the number, in `warnings`.
pub fn reportable(
    candidates: impl IntoIterator<Item = Candidate>,
    warnings: &mut Vec<String>,
) -> Vec<Candidate> {
    candidates
        .into_iter()
        .filter(|c| {
            let why = c
                .non_finite()
                .map(|(key, v)| match c.params.get(key) {
                    // A scale at infinity (a saturation current, a time
                    // constant) is the effect fitted away: the nominal
                    // model again.
                    Some(p) if p.value.is_infinite() => format!(
                        "its fit takes the effect away ({key} = {v}): the record shows none of it"
                    ),
                    _ => format!("its {key} = {v} is not a finite number"),
                })
                .or_else(|| {
                    crate::report::unphysical_param(&c.params)
                        .map(|what| format!("it needs {what}, outside its physical range"))
                });
            match why {
                None => true,
                Some(why) => {
                    warnings.push(format!(
                        "candidate {} left out of the report: {why}",
                        c.effect
                    ));
                    false
                }
            }
        })
        .collect()
}

/// How a nominal parameter moves once the verdict's effect is modelled.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ParamCorrection {
    /// Value of the nominal fit (biased by the unmodelled effect).
    pub nominal: f64,
    /// Value refitted with the effect.
    pub corrected: f64,
    /// (nominal − corrected) / corrected.
    pub bias: f64,
    /// Unit.
    pub unit: String,
}

/// The diagnosis' answer.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Verdict {
    /// The effect found, or `none`.
    pub effect: String,
    /// Held-out NRMSE of the nominal model.
    pub gap_before: f64,
    /// Held-out NRMSE with the effect (equal to `gap_before` for `none`).
    pub gap_after: f64,
    /// 1 − gap_after / gap_before.
    pub shrink: f64,
    /// Confidence in the verdict, 0–1 (1 − the corrected p-value for an
    /// effect; for `none`, the smallest corrected p-value of any candidate).
    pub confidence: f64,
    /// Effects the data cannot tell apart from the verdict, each with the
    /// test plan that would separate them.
    #[serde(default)]
    pub look_alikes: Vec<LookAlike>,
    /// Nominal parameters before and after modelling the effect.
    #[serde(default)]
    pub corrected_params: BTreeMap<String, ParamCorrection>,
}

/// An effect that explains the data about as well as the verdict.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LookAlike {
    /// The other effect.
    pub effect: String,
    /// Its held-out NRMSE.
    pub validation_nrmse: f64,
    /// The test plan that would separate the two.
    pub plan: String,
}

/// A whole diagnosis.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Diagnosis {
    /// Contract version.
    pub schema_version: String,
    /// Test kind, `dc_step` or `im_slip_sweep`.
    pub kind: String,
    /// The nominal model.
    pub nominal: NominalFit,
    /// Where the gap lies.
    pub gap: Gap,
    /// Every candidate tried, best score first.
    pub candidates: Vec<Candidate>,
    /// The answer.
    pub verdict: Verdict,
    /// How the held-out data was formed, e.g. `leave-one-segment-out (5 folds)`.
    pub validation: String,
    /// Things a user should know about the data or the diagnosis.
    pub warnings: Vec<String>,
}

#[cfg(test)]
mod tests {
    use super::*;

    fn estimate(value: f64) -> ParamEstimate {
        ParamEstimate {
            value,
            ci95: None,
            unit: "A".into(),
        }
    }

    fn candidate(effect: &str, isat: f64) -> Candidate {
        Candidate {
            effect: effect.into(),
            params: BTreeMap::from([
                ("s".into(), estimate(-2e-3)),
                ("Isat".into(), estimate(isat)),
            ]),
            validation_nrmse: 0.01,
            shrink: 0.1,
            score: 1.0,
            p_value: 0.5,
            nominal_params: BTreeMap::new(),
        }
    }

    /// A saturation fit with `s ≤ 0` has no saturation current: it once
    /// reached the report as `"Isat": {"value": null}`. An infinite scale
    /// is said to be the effect fitted away; any other non-finite number
    /// is named as such.
    #[test]
    fn a_candidate_with_a_non_finite_number_is_left_out_with_a_warning() {
        let mut warnings = Vec::new();
        let kept = reportable(
            [
                candidate("inductance_saturation", f64::INFINITY),
                candidate("brush_drop", 3.0),
                candidate("armature_reaction", f64::NAN),
            ],
            &mut warnings,
        );
        assert_eq!(kept.len(), 1);
        assert_eq!(kept[0].effect, "brush_drop");
        assert_eq!(
            warnings,
            [
                "candidate inductance_saturation left out of the report: its fit takes the \
                 effect away (Isat = inf): the record shows none of it",
                "candidate armature_reaction left out of the report: its Isat = NaN is not a \
                 finite number",
            ]
        );
        let json = serde_json::to_string(&kept).unwrap();
        assert!(!json.contains("\"value\":null"), "{json}");
    }
}
