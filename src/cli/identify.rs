//! `motorbench identify`: identify a motor from CSV files (one segment
//! each) or one MCAP record, with no rig.

use std::path::PathBuf;

use clap::{Args, ValueEnum};

use super::output::{print_analysis, warn_if_damaged};
use super::Failure;
use crate::identify::check_plausible_files;
use crate::machine::{analyse_dc, analyse_im};
use crate::model::{Connection, ImModel};
use crate::record::{load_record_files, SegmentKind};

/// `motorbench identify`.
#[derive(Debug, Args)]
pub struct IdentifyArgs {
    /// Test kind of the data.
    #[arg(long, value_enum)]
    pub(crate) kind: KindArg,
    /// CSV files, or one MCAP file.
    #[arg(required = true)]
    pub files: Vec<PathBuf>,
    /// Nameplate (JSON object with the contract's keys).
    #[arg(long)]
    pub nameplate: Option<PathBuf>,
    /// Print JSON instead of text.
    #[arg(long)]
    pub json: bool,
    /// Also write the measured-vs-model plot here (SVG).
    #[arg(long)]
    pub svg: Option<PathBuf>,
    /// Induction machine: winding connection (overrides the nameplate's).
    #[arg(long, value_enum)]
    pub(crate) connection: Option<ConnectionArg>,
    /// Induction machine: equivalent circuit to fit.
    #[arg(long, value_enum, default_value = "single-fe")]
    pub(crate) model: ModelArg,
    /// Induction machine, CSV: supply frequency in Hz where the files
    /// have no frequency_Hz column (overrides the nameplate's).
    #[arg(long)]
    pub frequency: Option<f64>,
}

/// Winding connection of an induction machine.
#[derive(Debug, Clone, Copy, ValueEnum)]
pub(crate) enum ConnectionArg {
    Star,
    Delta,
}

impl From<ConnectionArg> for Connection {
    fn from(c: ConnectionArg) -> Connection {
        match c {
            ConnectionArg::Star => Connection::Star,
            ConnectionArg::Delta => Connection::Delta,
        }
    }
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

/// The test kind of the data given to `identify`.
#[derive(Debug, Clone, Copy, ValueEnum)]
#[value(rename_all = "snake_case")]
pub(crate) enum KindArg {
    /// The contract's names (`dc_step`, …); the kebab-case forms too.
    #[value(name = "dc_step", alias = "dc-step")]
    DcStep,
    #[value(name = "dc_coastdown", alias = "dc-coastdown")]
    DcCoastdown,
    #[value(name = "im_slip_sweep", alias = "im-slip-sweep")]
    ImSlipSweep,
    #[value(name = "im_dc_resistance", alias = "im-dc-resistance")]
    ImDcResistance,
    #[value(name = "im_no_load", alias = "im-no-load")]
    ImNoLoad,
    #[value(name = "im_locked_rotor", alias = "im-locked-rotor")]
    ImLockedRotor,
}

impl From<KindArg> for SegmentKind {
    fn from(k: KindArg) -> SegmentKind {
        match k {
            KindArg::DcStep => SegmentKind::DcStep,
            KindArg::DcCoastdown => SegmentKind::DcCoastdown,
            KindArg::ImSlipSweep => SegmentKind::ImSlipSweep,
            KindArg::ImDcResistance => SegmentKind::ImDcResistance,
            KindArg::ImNoLoad => SegmentKind::ImNoLoad,
            KindArg::ImLockedRotor => SegmentKind::ImLockedRotor,
        }
    }
}

/// Identify the motor in `args.files`.
pub fn identify(args: IdentifyArgs) -> Result<(), Failure> {
    let kind = SegmentKind::from(args.kind);
    let record = load_record_files(kind, &args.files, args.nameplate.as_deref(), args.frequency)
        .map_err(Failure::bad_input)?;
    warn_if_damaged(&args.files[0], &record);
    let svg = args.svg.as_deref();
    let analysed = if kind.is_im() {
        analyse_im(
            &record,
            args.connection.map(Into::into),
            args.model.into(),
            false,
        )
    } else {
        check_plausible_files(&record, kind, &args.files).map_err(Failure::bad_input)?;
        analyse_dc(&record, None, false)
    };
    print_analysis(analysed.analysis.as_ref(), &record, args.json, svg)
}
