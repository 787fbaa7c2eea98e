//! What the subcommands print: an identification (text with its
//! diagnosis, or the contract's JSON), its plot, where a run's files went,
//! and the damage of a recovered record.

use std::path::{Path, PathBuf};

use super::Failure;
use crate::diagnose::render_diagnosis_text;
use crate::identify::{Identification, ImIdentification};
use crate::model::DcParams;
use crate::record::Record;
use crate::report::{
    render_im_text, render_text, segment_plots, write_im_svg, write_segments_svg,
    IdentificationReport,
};

/// Print a DC identification (JSON, or text with the diagnosis; `truth`
/// is the simulated motor, when known) and write its plot to `svg`, if
/// given; exit code 4 when no method applied.
pub(crate) fn print_dc(
    id: &Identification,
    record: Option<&Record>,
    json: bool,
    svg: Option<&Path>,
    truth: Option<&DcParams>,
) -> Result<(), Failure> {
    if json {
        println!("{}", id.report.to_json_pretty());
    } else {
        print!("{}", render_text(id, truth));
        print_diagnosis_text(&id.report);
    }
    if let (Some(path), Some(record)) = (svg, record) {
        write_segments_svg(path, &segment_plots(record, id)).map_err(Failure::runtime)?;
    }
    match id.refusal() {
        None => Ok(()),
        Some(why) => Err(Failure {
            code: 4,
            message: format!("nothing can be identified from this data: {why}"),
        }),
    }
}

/// Print an induction-machine identification as [`print_dc`] does.
pub(crate) fn print_im(
    id: &ImIdentification,
    json: bool,
    svg: Option<&Path>,
) -> Result<(), Failure> {
    if json {
        println!("{}", id.report.to_json_pretty());
    } else {
        print!("{}", render_im_text(id));
        print_diagnosis_text(&id.report);
    }
    if let Some(path) = svg {
        write_im_svg(path, id).map_err(Failure::runtime)?;
    }
    identified(&id.report)
}

/// Exit code 4 when no identification method applied.
fn identified(report: &IdentificationReport) -> Result<(), Failure> {
    match report.best {
        Some(_) => Ok(()),
        None => Err(Failure::not_identified()),
    }
}

/// The diagnosis of a report, as text, after a blank line.
fn print_diagnosis_text(report: &IdentificationReport) {
    if let Some(d) = &report.diagnosis {
        print!("\n{}", render_diagnosis_text(d));
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
        println!(
            "\nrecord: {} ({} messages)",
            self.mcap.display(),
            self.messages
        );
        println!("report: {}", self.report.display());
        println!("plot:   {}", self.svg.display());
        if let Some(path) = &self.residuals_svg {
            println!("gap:    {}", path.display());
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
