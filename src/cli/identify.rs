//! `motorbench identify`: identify a motor from CSV files (one segment
//! each) or one MCAP record, with no rig.

use std::path::PathBuf;

use clap::{Args, ValueEnum};

use super::output::print_analysis;
use super::{Failure, RecordInput};
use crate::machine::{analyse, AnalyseOptions};
use crate::model::ImModel;

/// `motorbench identify`.
#[derive(Debug, Args)]
pub struct IdentifyArgs {
    /// The data: kind, files, nameplate.
    #[command(flatten)]
    pub input: RecordInput,
    /// Print JSON instead of text.
    #[arg(long)]
    pub json: bool,
    /// Also write the measured-vs-model plot here (SVG).
    #[arg(long)]
    pub svg: Option<PathBuf>,
    /// Induction machine: equivalent circuit to fit.
    #[arg(long, value_enum, default_value = "single-fe")]
    pub(crate) model: ModelArg,
}

/// Equivalent circuit of an induction machine.
#[derive(Debug, Clone, Copy, ValueEnum)]
pub(crate) enum ModelArg {
    Single,
    #[value(alias = "single_fe")]
    SingleFe,
    Double,
    DoubleFe,
}

impl From<ModelArg> for ImModel {
    fn from(m: ModelArg) -> ImModel {
        match m {
            ModelArg::Single => ImModel::Single,
            ModelArg::SingleFe => ImModel::SingleFe,
            ModelArg::Double => ImModel::Double,
            ModelArg::DoubleFe => ImModel::DoubleFe,
        }
    }
}

/// Identify the motor in `args.input`.
pub fn identify(args: IdentifyArgs) -> Result<(), Failure> {
    let record = args.input.load()?;
    let options = AnalyseOptions {
        connection: args.input.connection(),
        im_model: Some(args.model.into()),
    };
    let analysed = analyse(&record, args.input.kind(), &options, false);
    print_analysis(
        analysed.analysis.as_ref(),
        &record,
        args.json,
        args.svg.as_deref(),
    )
}
