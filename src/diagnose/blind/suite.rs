//! The blind benchmark suite: which cases to simulate, where they go on
//! disk, and the truth file kept apart from them.
//!
//! Layout of a suite directory:
//!
//! ```text
//! cases.json          the public manifest: id, kind, files, nameplate per case
//! cases/case-NN/      the record as contract CSV files (+ nameplate.json)
//! truth.json          what each case really holds — read only by the scorer
//! ```

use std::path::{Path, PathBuf};

use rand::rngs::StdRng;
use rand::seq::SliceRandom;
use rand::SeedableRng;
use serde::{Deserialize, Serialize};

use super::files::write_case_files;
use super::SuiteError;
use super::{simulate_dc_case_with, simulate_im_case, BlindRecord, CaseTruth};
use super::{DcSetup, PlanKind};
use crate::model::{Effect, Machine};
use crate::record::SegmentKind;

/// The seed CI uses; `--seed` makes fresh sets.
pub const DEFAULT_SEED: u64 = 20_261_121;

/// Cases per effect of the vocabulary, for each machine it applies to.
pub const CASES_PER_EFFECT: usize = 3;

/// Cases with no effect: DC, IM.
pub const NONE_CASES: [usize; 2] = [4, 3];

/// Which test plans a suite's DC cases use.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, clap::ValueEnum)]
pub enum SuitePlans {
    /// The settled staircase only (12 time constants per level, an open
    /// coast-down, the classic sensors): the suite before plans varied.
    Classic,
    /// Every plan in turn (staircase, ramp, PRBS, speed loop, position
    /// loop), with holds, damping, coasts and sensors drawn per case.
    #[default]
    Wide,
}

/// One case of the public manifest: what a user would know of a record.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CaseEntry {
    /// Case id, e.g. `case-07`.
    pub id: String,
    /// Test kind, `dc_step` or `im_slip_sweep`.
    pub kind: String,
    /// The record's CSV files, relative to the suite directory.
    pub files: Vec<PathBuf>,
    /// The nameplate, relative to the suite directory, if any.
    pub nameplate: Option<PathBuf>,
}

/// The public manifest (`cases.json`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Manifest {
    /// The generator's seed.
    pub seed: u64,
    /// The cases, in a shuffled order.
    pub cases: Vec<CaseEntry>,
}

/// The truth file (`truth.json`): case id → truth.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TruthFile {
    /// The generator's seed.
    pub seed: u64,
    /// Truth per case, in the manifest's order.
    pub cases: Vec<(String, CaseTruth)>,
}

/// The machines and withheld effects of a suite, shuffled by `rng`:
/// every effect [`CASES_PER_EFFECT`] times per machine it applies to,
/// plus [`NONE_CASES`].
pub fn case_plan(rng: &mut StdRng) -> Vec<(Machine, Option<Effect>)> {
    let mut plan = Vec::new();
    for (machine, nones) in [
        (Machine::Dc, NONE_CASES[0]),
        (Machine::Induction, NONE_CASES[1]),
    ] {
        for effect in Effect::ALL.iter().filter(|e| e.applies_to(machine)) {
            plan.extend(std::iter::repeat_n(
                (machine, Some(*effect)),
                CASES_PER_EFFECT,
            ));
        }
        plan.extend(std::iter::repeat_n((machine, None), nones));
    }
    plan.shuffle(rng);
    plan
}

/// Simulate a suite into `dir` (which must not exist yet, so that no old
/// case survives beside new ones). `progress` is told each case written.
pub fn generate_suite(
    dir: &Path,
    seed: u64,
    plans: SuitePlans,
    progress: &dyn Fn(usize, usize),
) -> Result<Manifest, SuiteError> {
    if dir.exists() {
        return Err(SuiteError::Exists(dir.to_path_buf()));
    }
    let plan = case_plan(&mut StdRng::seed_from_u64(seed));
    let mut manifest = Manifest {
        seed,
        cases: Vec::new(),
    };
    let mut truth = TruthFile {
        seed,
        cases: Vec::new(),
    };
    let mut dc_cases = 0usize;
    for (n, (machine, effect)) in plan.iter().enumerate() {
        let (blind, kind) = simulate_case(seed, n, *machine, *effect, dc_cases, plans);
        if *machine == Machine::Dc {
            dc_cases += 1;
        }
        let id = format!("case-{:02}", n + 1);
        let rel = PathBuf::from("cases").join(&id);
        let (files, nameplate) = write_case_files(&blind.record, &dir.join(&rel))?;
        let relative = |p: PathBuf| rel.join(p.file_name().expect("a written file has a name"));
        manifest.cases.push(CaseEntry {
            id: id.clone(),
            kind: kind.as_str().to_string(),
            files: files.into_iter().map(relative).collect(),
            nameplate: nameplate.map(relative),
        });
        truth.cases.push((id, blind.truth));
        progress(n + 1, plan.len());
    }
    write_json(&dir.join("cases.json"), &manifest)?;
    write_json(&dir.join("truth.json"), &truth)?;
    Ok(manifest)
}

/// Case `n` (from 0) of the suite of `seed`: `machine` and `effect` from
/// its plan, `dc_index` the number of DC cases before it.
fn simulate_case(
    seed: u64,
    n: usize,
    machine: Machine,
    effect: Option<Effect>,
    dc_index: usize,
    plans: SuitePlans,
) -> (BlindRecord, SegmentKind) {
    // Each case draws from its own stream, so a case does not change
    // when another machine's simulator draws differently.
    let mut case_rng =
        StdRng::seed_from_u64(seed ^ (0x9e37_79b9_7f4a_7c15_u64.wrapping_mul(n as u64 + 1)));
    match machine {
        Machine::Dc => {
            // Plans in turn, so every plan meets a mix of effects; the
            // setup from a stream of its own, so the motor and the effect
            // are those of the case's classic twin.
            let kind = PlanKind::ALL[dc_index % PlanKind::ALL.len()];
            let mut setup_rng = StdRng::seed_from_u64(
                seed ^ (0x2545_f491_4f6c_dd1d_u64.wrapping_mul(n as u64 + 1)),
            );
            let setup = match plans {
                SuitePlans::Classic => DcSetup::classic(),
                SuitePlans::Wide => DcSetup::draw(kind, &mut setup_rng),
            };
            (
                simulate_dc_case_with(effect, &setup, &mut case_rng),
                SegmentKind::DcStep,
            )
        }
        Machine::Induction => (
            simulate_im_case(effect, &mut case_rng),
            SegmentKind::ImSlipSweep,
        ),
    }
}

/// The record and truth of one case of a suite (`case-NN`, `number` = NN)
/// as [`generate_suite`] writes it, without writing anything: a test can
/// diagnose one case of a suite that once exposed a defect.
pub fn suite_case(seed: u64, number: usize, plans: SuitePlans) -> Option<BlindRecord> {
    let plan = case_plan(&mut StdRng::seed_from_u64(seed));
    let n = number.checked_sub(1)?;
    let (machine, effect) = *plan.get(n)?;
    let dc_index = plan[..n].iter().filter(|(m, _)| *m == Machine::Dc).count();
    Some(simulate_case(seed, n, machine, effect, dc_index, plans).0)
}

fn write_json(path: &Path, value: &impl Serialize) -> Result<(), SuiteError> {
    let text = serde_json::to_string_pretty(value).expect("JSON serialises");
    std::fs::write(path, text + "\n").map_err(SuiteError::io(path))
}

/// Read a JSON file of the suite, with errors naming it.
pub fn read_json<T: for<'de> Deserialize<'de>>(path: &Path) -> Result<T, SuiteError> {
    let text = std::fs::read_to_string(path).map_err(SuiteError::io(path))?;
    serde_json::from_str(&text).map_err(|source| SuiteError::Json {
        path: path.to_path_buf(),
        source,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn plan_meets_the_issue_counts() {
        let plan = case_plan(&mut StdRng::seed_from_u64(1));
        assert!(plan.len() >= 40, "{} cases", plan.len());
        let nones = plan.iter().filter(|(_, e)| e.is_none()).count();
        assert!(nones >= 6);
        for machine in [Machine::Dc, Machine::Induction] {
            for effect in Effect::ALL.iter().filter(|e| e.applies_to(machine)) {
                let n = plan
                    .iter()
                    .filter(|(m, e)| *m == machine && *e == Some(*effect))
                    .count();
                assert!(n >= 2, "{effect:?} on {machine:?}: {n}");
            }
        }
        assert_ne!(plan, case_plan(&mut StdRng::seed_from_u64(2)));
    }
}
