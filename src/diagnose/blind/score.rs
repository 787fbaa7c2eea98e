//! The blind benchmark's scorer: diagnose every case of a suite from its
//! public files alone, then — and only then — read the truth file and
//! compare.

use std::collections::BTreeMap;
use std::fmt;
use std::path::Path;

use serde::{Deserialize, Serialize};

use super::suite::{read_json, Manifest, TruthFile};
use crate::diagnose::{diagnose, DiagnoseOptions};
use crate::record::{load_record_files, SegmentKind};

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

    /// `none` cases, and how many of them got an effect named (false alarms).
    pub fn false_alarms(&self) -> (usize, usize) {
        let nones: Vec<_> = self.cases.iter().filter(|c| c.truth == "none").collect();
        let alarms = nones.iter().filter(|c| c.verdict != "none").count();
        (alarms, nones.len())
    }

    /// Right verdicts with gap_after within twice the noise floor, of right verdicts.
    pub fn noise_floor_reached(&self) -> (usize, usize) {
        let right: Vec<_> = self.cases.iter().filter(|c| c.right).collect();
        (
            right.iter().filter(|c| c.reaches_noise_floor).count(),
            right.len(),
        )
    }

    /// Cases whose largest region agrees with the truth, of cases compared.
    pub fn region_agreement(&self) -> (usize, usize) {
        let compared: Vec<_> = self.cases.iter().filter_map(|c| c.region_agrees).collect();
        (compared.iter().filter(|a| **a).count(), compared.len())
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
                "{}: diagnosis failed: {}",
                c.id,
                c.error.as_deref().unwrap_or("")
            )?;
        }
        Ok(())
    }
}

/// Diagnose every case of the suite in `dir`, then score against its
/// truth file. `progress` is told each case diagnosed.
pub fn score_suite(dir: &Path, progress: &dyn Fn(usize, usize)) -> Result<SuiteScore, String> {
    let manifest: Manifest = read_json(&dir.join("cases.json"))?;
    let total = manifest.cases.len();
    // First every verdict, from the public files only.
    let mut verdicts = Vec::with_capacity(total);
    for (n, case) in manifest.cases.iter().enumerate() {
        let kind = SegmentKind::parse(&case.kind).ok_or_else(|| {
            format!(
                "{}: case {}: unknown kind {:?}",
                dir.join("cases.json").display(),
                case.id,
                case.kind
            )
        })?;
        let files: Vec<_> = case.files.iter().map(|p| dir.join(p)).collect();
        let nameplate = case.nameplate.as_ref().map(|p| dir.join(p));
        let record = load_record_files(kind, &files, nameplate.as_deref(), None)?;
        verdicts.push(diagnose(&record, kind, &DiagnoseOptions::default()).map(|run| run.report));
        progress(n + 1, total);
    }
    // Then the truth.
    let truth: TruthFile = read_json(&dir.join("truth.json"))?;
    let mut cases = Vec::with_capacity(total);
    for (case, verdict) in manifest.cases.iter().zip(verdicts) {
        let (_, t) = truth
            .cases
            .iter()
            .find(|(id, _)| *id == case.id)
            .ok_or_else(|| {
                format!(
                    "{}: no truth for {}",
                    dir.join("truth.json").display(),
                    case.id
                )
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
            },
        });
    }
    Ok(SuiteScore {
        seed: manifest.seed,
        cases,
    })
}
