//! `motorbench replay`: read a record (also a truncated one), identify
//! and diagnose it again, and compare with the `/bench/result` the run
//! recorded: its last one, the whole report; or, where the run died
//! during the diagnosis, the identification it recorded first (marked
//! `diagnosis_pending`), compared with the replay's identification.

use std::path::PathBuf;

use clap::Args;

use super::output::{print_analysis, warn_if_damaged};
use super::Failure;
use crate::diagnose::write_residual_svg;
use crate::machine::{analyse_record, record_analysis_kind};
use crate::record::{read_mcap, Record};
use crate::report::{IdentificationReport, Provenance};

/// `motorbench replay`.
#[derive(Debug, Args)]
pub struct ReplayArgs {
    /// The record.
    pub log: PathBuf,
    /// Print JSON instead of text.
    #[arg(long)]
    pub json: bool,
    /// Also write the measured-vs-model plot here (SVG).
    #[arg(long)]
    pub svg: Option<PathBuf>,
    /// Exit with code 5 when the result differs from the recorded one.
    #[arg(long)]
    pub check: bool,
    /// Skip the sim-to-real diagnosis (the comparison with the recorded
    /// result then leaves its diagnosis out).
    #[arg(long)]
    pub no_diagnose: bool,
    /// Also write the diagnosis' held-out residuals, before and after, here (SVG).
    #[arg(long)]
    pub residuals_svg: Option<PathBuf>,
}

/// Replay `args.log`.
pub fn replay(args: ReplayArgs) -> Result<(), Failure> {
    let record = read_mcap(&args.log).map_err(Failure::bad_input)?;
    warn_if_damaged(&args.log, &record);
    let diagnose = !args.no_diagnose;
    let mut analysed = analyse_record(&record, false);
    // The identification alone, for a record whose run died before its
    // diagnosis was recorded.
    let identification = analysed.analysis.report().clone();
    if diagnose {
        analysed.diagnose(&record, record_analysis_kind(&record));
    }
    analysed.analysis.report_mut().provenance = provenance(&record, &args.log);
    if let (Some(path), Some(plot)) = (&args.residuals_svg, &analysed.residuals) {
        write_residual_svg(plot, path).map_err(Failure::runtime)?;
    }
    let analysis = analysed.analysis.as_ref();
    let identified = print_analysis(analysis, &record, args.json, args.svg.as_deref());
    if let Err(f) = &identified {
        if f.code != 4 {
            return identified;
        }
    }
    let replayed = Replayed {
        report: analysis.report(),
        identification: &identification,
        diagnosed: diagnose,
    };
    compare_with_recorded(&record, &replayed, args.check)?;
    identified
}

/// Where a replayed report comes from: the run's, as recorded with its
/// result (so a replay prints what the run printed), else the record's
/// metadata and `path`'s file name.
fn provenance(record: &Record, path: &std::path::Path) -> Option<Provenance> {
    let recorded = record
        .recorded_result
        .as_ref()
        .and_then(|r| r.get("provenance"))
        .and_then(|p| serde_json::from_value(p.clone()).ok());
    recorded.or_else(|| {
        let name = path.file_name()?.to_string_lossy().into_owned();
        let meta = record.meta.as_ref()?;
        Some(Provenance::new(
            &meta.motor_id,
            &meta.started_at,
            &name,
            Vec::new(),
        ))
    })
}

/// A replay's report, for the comparison with the recorded one.
struct Replayed<'a> {
    /// The whole report (with the diagnosis when `diagnosed`).
    report: &'a IdentificationReport,
    /// The identification alone, before the diagnosis ran.
    identification: &'a IdentificationReport,
    /// Whether the replay diagnosed.
    diagnosed: bool,
}

/// Say whether the replayed report equals the recorded `/bench/result`;
/// with `check`, a difference is exit code 5.
fn compare_with_recorded(
    record: &Record,
    replayed: &Replayed<'_>,
    check: bool,
) -> Result<(), Failure> {
    let Some(recorded) = &record.recorded_result else {
        eprintln!("replay: the record holds no /bench/result to compare with");
        return Ok(());
    };
    let pending = recorded
        .get("diagnosis_pending")
        .and_then(|p| p.as_bool())
        .unwrap_or(false);
    let same = if pending {
        same_result(recorded, replayed.identification, false)
    } else {
        same_result(recorded, replayed.report, replayed.diagnosed)
    };
    if same && pending {
        eprintln!(
            "replay: identical to the recorded /bench/result (the identification; \
             the run ended before its diagnosis was recorded)"
        );
        return Ok(());
    }
    if same {
        eprintln!("replay: identical to the recorded /bench/result");
        return Ok(());
    }
    eprintln!("replay: DIFFERS from the recorded /bench/result");
    if check {
        return Err(Failure {
            code: 5,
            message: "replayed identification differs from the recorded one".into(),
        });
    }
    Ok(())
}

/// Whether `replayed` equals `recorded`. The provenance (file names,
/// version) is not compared, nor the contract version the report was
/// written under (a version 1 record replays under version 2: the report's
/// JSON is the same in both), nor the `diagnosis_pending` mark. The
/// diagnosis is compared only when both have
/// one to compare: a replay with `--no-diagnose` (not `diagnosed`) leaves
/// the record's out, and a record made with `--no-diagnose` (or before the
/// diagnosis existed) has none.
fn same_result(
    recorded: &serde_json::Value,
    replayed: &IdentificationReport,
    diagnosed: bool,
) -> bool {
    let mut recorded = recorded.clone();
    let mut now = serde_json::to_value(replayed).expect("a report always serialises");
    for v in [&mut recorded, &mut now] {
        if let Some(obj) = v.as_object_mut() {
            // Where the report came from is not part of the result, nor
            // what the rig warned of during the test (read from the
            // record's events, not computed; records made before the key
            // existed lack it).
            obj.remove("provenance");
            obj.remove("test_warnings");
            obj.remove("schema_version");
            obj.remove("diagnosis_pending");
        }
    }
    if !diagnosed || recorded.get("diagnosis").is_none() {
        for v in [&mut recorded, &mut now] {
            if let Some(obj) = v.as_object_mut() {
                obj.remove("diagnosis");
            }
        }
    }
    recorded == now
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_diagnosis_is_compared_only_when_both_sides_have_one() {
        let replayed = IdentificationReport::new("dc_step");
        let plain = serde_json::to_value(&replayed).unwrap();
        let mut diagnosed = plain.clone();
        diagnosed["diagnosis"] = serde_json::json!({"verdict": "none"});
        // A default run's record, replayed with --no-diagnose.
        assert!(same_result(&diagnosed, &replayed, false));
        // A --no-diagnose record, replayed with the diagnosis.
        assert!(same_result(&plain, &replayed, false));
        assert!(same_result(&plain, &replayed, true));
        // A diagnosed record whose replay lost its diagnosis differs.
        assert!(!same_result(&diagnosed, &replayed, true));
        // Where a report came from is not its result.
        let mut moved = plain.clone();
        moved["provenance"] = serde_json::json!({"record": "renamed.mcap"});
        assert!(same_result(&moved, &replayed, true));
        // Nor is the contract version it was written under.
        let mut v1 = plain.clone();
        v1["schema_version"] = "1".into();
        assert!(same_result(&v1, &replayed, true));
        // Nor the mark of a result recorded before its diagnosis.
        let mut pending = plain.clone();
        pending["diagnosis_pending"] = true.into();
        assert!(same_result(&pending, &replayed, false));
        // Anything else that differs still differs.
        let mut other = diagnosed.clone();
        other["best"] = "steady_state".into();
        assert!(!same_result(&other, &replayed, false));
    }
}
