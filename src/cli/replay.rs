//! `motorbench replay`: read a record (also a truncated one), identify
//! and diagnose it again, and compare with the `/bench/result` the run
//! recorded.

use std::path::PathBuf;

use clap::Args;

use super::output::{print_analysis, warn_if_damaged};
use super::Failure;
use crate::diagnose::write_residual_svg;
use crate::machine::analyse_record;
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
    let mut analysed = analyse_record(&record, diagnose);
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
    compare_with_recorded(&record, analysis.report(), diagnose, args.check)?;
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

/// Say whether the replayed report equals the recorded `/bench/result`;
/// with `check`, a difference is exit code 5.
fn compare_with_recorded(
    record: &Record,
    replayed: &IdentificationReport,
    diagnosed: bool,
    check: bool,
) -> Result<(), Failure> {
    let Some(recorded) = &record.recorded_result else {
        eprintln!("replay: the record holds no /bench/result to compare with");
        return Ok(());
    };
    if same_result(recorded, replayed, diagnosed) {
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
/// JSON is the same in both). The diagnosis is compared only when both have
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
            // Where the report came from is not part of the result.
            obj.remove("provenance");
            obj.remove("schema_version");
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
        // Anything else that differs still differs.
        let mut other = diagnosed.clone();
        other["best"] = "steady_state".into();
        assert!(!same_result(&other, &replayed, false));
    }
}
