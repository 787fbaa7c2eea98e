//! What the subcommands print: an identification (text with its
//! diagnosis, or the contract's JSON), its plot, where a run's files went,
//! and the damage of a recovered record.

use crate::cli::stdout::{out, outln};
use std::path::{Path, PathBuf};

use super::Failure;
use crate::diagnose::render_diagnosis_text;
use crate::machine::Analysis;
use crate::record::Record;
use crate::report::IdentificationReport;

/// Print an identification (the contract's JSON, or text with the
/// diagnosis) and write its plot of `record` to `svg`, if given; exit code
/// 4 when no method applied.
pub(crate) fn print_analysis(
    analysis: &dyn Analysis,
    record: &Record,
    json: bool,
    svg: Option<&Path>,
) -> Result<(), Failure> {
    let report = analysis.report();
    if json {
        outln!("{}", report.to_json_pretty());
    } else {
        out!("{}", analysis.text());
        print_diagnosis_text(report);
    }
    if let Some(path) = svg {
        analysis
            .write_plot(record, path)
            .map_err(Failure::runtime)?;
    }
    match analysis.refusal() {
        None => Ok(()),
        Some(message) => Err(Failure { code: 4, message }),
    }
}

/// The diagnosis of a report, as text, after a blank line.
fn print_diagnosis_text(report: &IdentificationReport) {
    if let Some(d) = &report.diagnosis {
        out!("\n{}", render_diagnosis_text(d));
    }
}

/// The files a run wrote.
pub(crate) struct RunFiles {
    /// The MCAP record.
    pub mcap: PathBuf,
    /// Messages in it.
    pub messages: u64,
    /// `report.json`.
    pub report: PathBuf,
    /// The measured-vs-model plot.
    pub svg: PathBuf,
    /// The diagnosis' residual plot, when diagnosed.
    pub residuals_svg: Option<PathBuf>,
}

impl RunFiles {
    /// Say where the files went (after the text report).
    pub(crate) fn print(&self) {
        outln!(
            "\nrecord: {} ({} messages)",
            self.mcap.display(),
            self.messages
        );
        outln!("report: {}", self.report.display());
        outln!("plot:   {}", self.svg.display());
        if let Some(path) = &self.residuals_svg {
            outln!("gap:    {}", path.display());
        }
    }
}

/// Say on stderr how much of a damaged record was recovered, and where
/// the damage is.
pub(crate) fn warn_if_damaged(path: &Path, record: &Record) {
    if let Some(r) = &record.recovery {
        eprintln!("motorbench: {} is damaged: {r}", path.display());
    }
}
