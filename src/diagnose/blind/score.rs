//! The blind benchmark's scorer: diagnose every case of a suite from its
//! public files alone, then — and only then — read the truth file and
//! compare.

use std::collections::BTreeMap;
use std::fmt;
use std::path::Path;
use std::time::Instant;

use serde::{Deserialize, Serialize};

use super::suite::{read_json, Manifest, TruthFile};
use super::CaseTruth;
use super::SuiteError;
use crate::contract::Diagnosis;
use crate::diagnose::{diagnose, DiagnoseOptions};
use crate::machine::ready_record;
use crate::record::{load_record_files, ColumnMap, SegmentKind};

/// The comparison of one case.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CaseScore {
    /// Case id.
    pub id: String,
    /// Test kind.
    pub kind: String,
    /// The withheld effect (`none` for none).
    pub truth: String,
    /// The verdict (or `error`).
    pub verdict: String,
    /// Whether the verdict names the withheld effect.
    pub right: bool,
    /// Whether the largest gap region is one where the effect shows
    /// (None for `none` cases and failed diagnoses).
    pub region_agrees: Option<bool>,
    /// Held-out NRMSE after the verdict's effect.
    pub gap_after: f64,
    /// The truth's noise floor.
    pub noise_floor: f64,
    /// Whether gap_after is within twice the noise floor.
    pub reaches_noise_floor: bool,
    /// Why the diagnosis failed, if it did.
    pub error: Option<String>,
    /// Who simulated the case (the truth's `source`).
    #[serde(default)]
    pub source: String,
    /// The case's plan (the truth's `plan`).
    #[serde(default)]
    pub plan: String,
    /// Relative error of the DC model's K and Ra (the verdict's refitted
    /// values, the nominal fit's for `none`) against the truth's nominal.
    #[serde(default)]
    pub param_error: BTreeMap<String, f64>,
    /// Wall time to read the case's files and diagnose them, in seconds
    /// (the diagnosis' worker threads as `MOTORBENCH_THREADS` sets them).
    #[serde(default)]
    pub seconds: f64,
}

/// A case's diagnosis should take at most this long (seconds).
pub const CASE_TIME_BOUND_S: f64 = 2.0;

/// Bounds of the parameter check: K within 1 %, Ra within 3 % of the truth.
pub const PARAM_BOUNDS: [(&str, f64); 2] = [("K", 0.01), ("Ra", 0.03)];

/// The bar's figures over a group of cases.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Tally {
    /// Cases.
    pub cases: usize,
    /// Right verdicts.
    pub right: usize,
    /// `none` cases.
    pub nones: usize,
    /// `none` cases that got an effect named.
    pub false_alarms: usize,
    /// Right verdicts with gap_after within twice the noise floor.
    pub floor_reached: usize,
    /// Cases the diagnosis refused (an error instead of a verdict).
    pub refused: usize,
    /// DC cases with K and Ra compared.
    pub params_compared: usize,
    /// Of those, K within 1 % and Ra within 3 % of the truth.
    pub params_within: usize,
}

impl Tally {
    fn add(&mut self, c: &CaseScore) {
        self.cases += 1;
        self.right += usize::from(c.right);
        if c.truth == "none" {
            self.nones += 1;
            self.false_alarms += usize::from(c.verdict != "none" && c.error.is_none());
        }
        self.floor_reached += usize::from(c.right && c.reaches_noise_floor);
        self.refused += usize::from(c.error.is_some());
        if !c.param_error.is_empty() {
            self.params_compared += 1;
            self.params_within += usize::from(
                PARAM_BOUNDS
                    .iter()
                    .all(|(k, b)| c.param_error.get(*k).is_some_and(|e| e.abs() <= *b)),
            );
        }
    }
}

/// A whole suite's score.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SuiteScore {
    /// The suite's seed.
    pub seed: u64,
    /// Every case.
    pub cases: Vec<CaseScore>,
}

impl SuiteScore {
    /// Cases whose verdict is right.
    pub fn right(&self) -> usize {
        self.cases.iter().filter(|c| c.right).count()
    }

    /// Fraction of cases whose verdict is right.
    pub fn accuracy(&self) -> f64 {
        self.right() as f64 / self.cases.len().max(1) as f64
    }

    /// `none` cases, and how many of them got an effect named (false
    /// alarms; a refused record names none and counts under [`Self::refused`]).
    pub fn false_alarms(&self) -> (usize, usize) {
        let nones: Vec<_> = self.cases.iter().filter(|c| c.truth == "none").collect();
        let alarms = nones
            .iter()
            .filter(|c| c.verdict != "none" && c.error.is_none())
            .count();
        (alarms, nones.len())
    }

    /// Cases the diagnosis refused (an error instead of a verdict).
    pub fn refused(&self) -> usize {
        self.cases.iter().filter(|c| c.error.is_some()).count()
    }

    /// Right verdicts with gap_after within twice the noise floor, of right verdicts.
    pub fn noise_floor_reached(&self) -> (usize, usize) {
        let right: Vec<_> = self.cases.iter().filter(|c| c.right).collect();
        (
            right.iter().filter(|c| c.reaches_noise_floor).count(),
            right.len(),
        )
    }

    /// The case that took longest to read and diagnose.
    pub fn slowest(&self) -> Option<&CaseScore> {
        self.cases
            .iter()
            .max_by(|a, b| a.seconds.total_cmp(&b.seconds))
    }

    /// Cases whose largest region agrees with the truth, of cases compared.
    pub fn region_agreement(&self) -> (usize, usize) {
        let compared: Vec<_> = self.cases.iter().filter_map(|c| c.region_agrees).collect();
        (compared.iter().filter(|a| **a).count(), compared.len())
    }

    /// The bar's figures per source (`"<source> all"`) and per source
    /// and plan (`"<source> <plan>"`), plans named `<machine>:<plan>`.
    pub fn per_source_and_plan(&self) -> BTreeMap<(String, String), Tally> {
        let mut table: BTreeMap<(String, String), Tally> = BTreeMap::new();
        for c in &self.cases {
            let source = if c.source.is_empty() {
                super::OWN_SOURCE.to_string()
            } else {
                c.source.clone()
            };
            let plan = format!("{} {}", machine(&c.kind), c.plan);
            table
                .entry((source.clone(), " all".to_string()))
                .or_default()
                .add(c);
            table.entry((source, plan)).or_default().add(c);
        }
        table
    }

    /// Per withheld effect: (cases, right, what was named instead).
    pub fn per_effect(&self) -> BTreeMap<String, (usize, usize, Vec<String>)> {
        let mut table: BTreeMap<String, (usize, usize, Vec<String>)> = BTreeMap::new();
        for c in &self.cases {
            let row = table
                .entry(format!("{} {}", machine(&c.kind), c.truth))
                .or_default();
            row.0 += 1;
            if c.right {
                row.1 += 1;
            } else {
                row.2.push(c.verdict.clone());
            }
        }
        table
    }
}

fn machine(kind: &str) -> &'static str {
    if kind == SegmentKind::ImSlipSweep.as_str() {
        "IM"
    } else {
        "DC"
    }
}

impl fmt::Display for SuiteScore {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let pct = |a: usize, b: usize| 100.0 * a as f64 / b.max(1) as f64;
        let n = self.cases.len();
        writeln!(f, "blind benchmark: {n} cases (seed {})", self.seed)?;
        writeln!(
            f,
            "effects correct:          {}/{n} ({:.1} %)",
            self.right(),
            pct(self.right(), n)
        )?;
        let (alarms, nones) = self.false_alarms();
        writeln!(f, "false alarms on none:     {alarms}/{nones}")?;
        writeln!(f, "refused records:          {}/{n}", self.refused())?;
        let (agree, compared) = self.region_agreement();
        writeln!(
            f,
            "region agreement:         {agree}/{compared} ({:.1} %)",
            pct(agree, compared)
        )?;
        let (floor, right) = self.noise_floor_reached();
        writeln!(
            f,
            "gap_after ≤ 2×noise floor: {floor}/{right} right verdicts ({:.1} %)",
            pct(floor, right)
        )?;
        if let Some(slow) = self.slowest() {
            writeln!(
                f,
                "slowest case:             {} ({} {}) {:.2} s; over {CASE_TIME_BOUND_S} s: {}/{n}",
                slow.id,
                slow.source,
                slow.plan,
                slow.seconds,
                self.cases
                    .iter()
                    .filter(|c| c.seconds > CASE_TIME_BOUND_S)
                    .count()
            )?;
        }
        writeln!(
            f,
            "\n{:<20} {:<18} {:>5} {:>5} {:>11} {:>11} {:>7} {:>11}",
            "source", "plan", "cases", "right", "alarms/none", "floor/right", "refused", "K1%,Ra3%"
        )?;
        for ((source, plan), t) in self.per_source_and_plan() {
            writeln!(
                f,
                "{source:<20} {:<18} {:>5} {:>5} {:>11} {:>11} {:>7} {:>11}",
                plan.trim(),
                t.cases,
                t.right,
                format!("{}/{}", t.false_alarms, t.nones),
                format!("{}/{}", t.floor_reached, t.right),
                t.refused,
                format!("{}/{}", t.params_within, t.params_compared)
            )?;
        }
        writeln!(
            f,
            "\n{:<28} {:>5} {:>5}  named instead",
            "withheld effect", "cases", "right"
        )?;
        for (effect, (cases, right, instead)) in self.per_effect() {
            writeln!(
                f,
                "{effect:<28} {cases:>5} {right:>5}  {}",
                instead.join(", ")
            )?;
        }
        let failed: Vec<_> = self.cases.iter().filter(|c| c.error.is_some()).collect();
        for c in failed {
            writeln!(
                f,
                "{} ({} {}, {}): diagnosis failed: {}",
                c.id,
                c.source,
                c.plan,
                c.truth,
                c.error.as_deref().unwrap_or("")
            )?;
        }
        Ok(())
    }
}

/// K's and Ra's relative error (DC cases; empty for IM): the verdict's
/// refitted value where it has one, else the nominal fit's.
fn param_error(d: &Diagnosis, t: &CaseTruth) -> BTreeMap<String, f64> {
    if d.kind == SegmentKind::ImSlipSweep.as_str() {
        return BTreeMap::new();
    }
    PARAM_BOUNDS
        .iter()
        .filter_map(|(key, _)| {
            let fitted = d
                .verdict
                .corrected_params
                .get(*key)
                .map(|c| c.corrected)
                .or_else(|| d.nominal.params.get(*key).map(|p| p.value))?;
            let truth = *t.nominal.get(*key)?;
            Some((key.to_string(), fitted / truth - 1.0))
        })
        .collect()
}

/// Diagnose every case of the suite in `dir`, then score against its
/// truth file. `progress` is told each case diagnosed.
pub fn score_suite(dir: &Path, progress: &dyn Fn(usize, usize)) -> Result<SuiteScore, SuiteError> {
    let manifest: Manifest = read_json(&dir.join("cases.json"))?;
    let total = manifest.cases.len();
    // First every verdict, from the public files only.
    let mut verdicts = Vec::with_capacity(total);
    for (n, case) in manifest.cases.iter().enumerate() {
        let kind = SegmentKind::parse(&case.kind).ok_or_else(|| SuiteError::UnknownKind {
            manifest: dir.join("cases.json"),
            case: case.id.clone(),
            kind: case.kind.clone(),
        })?;
        let files: Vec<_> = case.files.iter().map(|p| dir.join(p)).collect();
        let nameplate = case.nameplate.as_ref().map(|p| dir.join(p));
        let started = Instant::now();
        let record = load_record_files(
            kind,
            &files,
            nameplate.as_deref(),
            None,
            &ColumnMap::default(),
        )?;
        // Made ready as `motorbench diagnose` makes it.
        let record = ready_record(record, kind, false);
        let report = diagnose(&record, kind, &DiagnoseOptions::default()).map(|run| run.report);
        verdicts.push((report, started.elapsed().as_secs_f64()));
        progress(n + 1, total);
    }
    // Then the truth.
    let truth: TruthFile = read_json(&dir.join("truth.json"))?;
    let mut cases = Vec::with_capacity(total);
    for (case, (verdict, seconds)) in manifest.cases.iter().zip(verdicts) {
        let (_, t) = truth
            .cases
            .iter()
            .find(|(id, _)| *id == case.id)
            .ok_or_else(|| SuiteError::NoTruth {
                truth: dir.join("truth.json"),
                case: case.id.clone(),
            })?;
        cases.push(match verdict {
            Ok(d) => {
                let right = d.verdict.effect == t.effect;
                let region_agrees = (t.effect != "none").then(|| {
                    d.gap
                        .regions
                        .first()
                        .is_some_and(|r| t.regions.contains(&r.label))
                });
                CaseScore {
                    id: case.id.clone(),
                    kind: case.kind.clone(),
                    truth: t.effect.clone(),
                    verdict: d.verdict.effect.clone(),
                    right,
                    region_agrees,
                    gap_after: d.verdict.gap_after,
                    noise_floor: t.noise_floor,
                    reaches_noise_floor: d.verdict.gap_after <= 2.0 * t.noise_floor,
                    error: None,
                    source: t.source.clone(),
                    plan: t.plan.clone(),
                    param_error: param_error(&d, t),
                    seconds,
                }
            }
            Err(e) => CaseScore {
                id: case.id.clone(),
                kind: case.kind.clone(),
                truth: t.effect.clone(),
                verdict: "error".into(),
                right: false,
                region_agrees: None,
                gap_after: f64::NAN,
                noise_floor: t.noise_floor,
                reaches_noise_floor: false,
                error: Some(e.to_string()),
                source: t.source.clone(),
                plan: t.plan.clone(),
                param_error: BTreeMap::new(),
                seconds,
            },
        });
    }
    Ok(SuiteScore {
        seed: manifest.seed,
        cases,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn case(source: &str, plan: &str, truth: &str, verdict: &str, floor: bool) -> CaseScore {
        let refused = verdict == "error";
        CaseScore {
            id: format!("{source}-{plan}-{truth}"),
            kind: SegmentKind::DcStep.as_str().to_string(),
            truth: truth.into(),
            verdict: verdict.into(),
            right: truth == verdict,
            region_agrees: None,
            gap_after: if refused { f64::NAN } else { 0.01 },
            noise_floor: 0.01,
            reaches_noise_floor: floor,
            error: refused.then(|| "no start values".to_string()),
            source: source.into(),
            plan: plan.into(),
            param_error: if refused {
                BTreeMap::new()
            } else {
                BTreeMap::from([("K".to_string(), 0.005), ("Ra".to_string(), 0.05)])
            },
            seconds: if refused { 0.1 } else { 2.5 },
        }
    }

    #[test]
    fn the_table_keeps_sources_and_plans_apart_and_counts_refusals() {
        let score = SuiteScore {
            seed: 1,
            cases: vec![
                case("motorbench", "staircase", "brush_drop", "brush_drop", true),
                case("motorbench", "staircase", "none", "error", false),
                case("motorbench", "ramp", "none", "sensor_lag", false),
                case("gym-electric-motor", "prbs", "none", "none", true),
                case("gym-electric-motor", "prbs", "brush_drop", "none", false),
            ],
        };
        let t = score.per_source_and_plan();
        let own = t[&("motorbench".to_string(), " all".to_string())];
        assert_eq!((own.cases, own.right, own.refused), (3, 1, 1));
        assert_eq!((own.false_alarms, own.nones), (1, 2));
        let stairs = t[&("motorbench".to_string(), "DC staircase".to_string())];
        assert_eq!(
            (stairs.cases, stairs.floor_reached, stairs.refused),
            (2, 1, 1)
        );
        let gem = t[&("gym-electric-motor".to_string(), "DC prbs".to_string())];
        assert_eq!((gem.cases, gem.right, gem.false_alarms), (2, 1, 0));
        // A refusal is no false alarm, but it is not right either.
        assert_eq!(score.false_alarms(), (1, 3));
        assert_eq!(score.refused(), 1);
        let text = score.to_string();
        assert!(text.contains("gym-electric-motor   DC prbs"), "{text}");
        assert!(text.contains("refused records:          1/5"), "{text}");
        assert!(text.contains("2.50 s; over 2 s: 4/5"), "{text}");
    }
}
