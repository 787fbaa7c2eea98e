//! The record a command reads without a rig — CSV files (one segment
//! each) or one MCAP file, with its test kind, nameplate and the
//! induction machine's overrides — as one set of clap arguments shared by
//! `identify` and `diagnose`, and its loading with the checks both apply.

use std::path::PathBuf;

use clap::{Args, ValueEnum};

use super::output::warn_if_damaged;
use super::Failure;
use crate::machine::{check_record, ready_record};
use crate::model::Connection;
use crate::record::{load_record_files, ColumnMap, ColumnMapError, Record, SegmentKind};

/// The data a command reads: `--kind`, the files, `--nameplate`, and the
/// induction machine's `--connection` and `--frequency`.
#[derive(Debug, Args)]
pub struct RecordInput {
    /// Test kind of the data.
    #[arg(long, value_enum)]
    kind: KindArg,
    /// CSV files (one segment each), or one MCAP file.
    #[arg(required = true)]
    pub files: Vec<PathBuf>,
    /// Nameplate (JSON object with the contract's keys).
    #[arg(long)]
    pub nameplate: Option<PathBuf>,
    /// Induction machine: winding connection (overrides the nameplate's).
    #[arg(long, value_enum)]
    connection: Option<ConnectionArg>,
    /// Induction machine, CSV: supply frequency in Hz where the files
    /// have no frequency_Hz column (overrides the nameplate's).
    #[arg(long)]
    pub frequency: Option<f64>,
    /// DC: the voltage column holds the command as the logger issued it
    /// at each instant (applied until the next sample); move it one
    /// sample later, to the reading of the voltage applied up to that
    /// instant that motorbench's models take.
    #[arg(long)]
    pub voltage_as_issued: bool,
    /// CSV: read the header cell HEADER as the contract's column NAME,
    /// e.g. --column time_s="Time [s]" --column speed_rpm="n [rpm]"
    /// (repeat for each column the files name otherwise).
    #[arg(long = "column", value_name = "NAME=HEADER", value_parser = parse_column)]
    columns: Vec<(String, String)>,
}

/// One `--column` argument, checked as the map will take it.
fn parse_column(arg: &str) -> Result<(String, String), ColumnMapError> {
    ColumnMap::parse(&[arg])?;
    let (name, header) = arg.split_once('=').unwrap_or_default();
    Ok((name.trim().to_string(), header.trim().to_string()))
}

impl RecordInput {
    /// The test kind given.
    pub fn kind(&self) -> SegmentKind {
        self.kind.into()
    }

    /// The winding connection given, if any.
    pub fn connection(&self) -> Option<Connection> {
        self.connection.map(Into::into)
    }

    /// Load the record; warn on stderr when it is damaged (recovered up to
    /// its last good chunk); refuse values its machine cannot give
    /// ([`check_record`]), and make it ready for its machine's methods
    /// ([`ready_record`]: a DC record's single segment split, gaps cut,
    /// the voltage's timing checked or moved). Errors are bad input (exit
    /// code 2).
    pub fn load(&self) -> Result<Record, Failure> {
        let kind = self.kind();
        let columns = self
            .columns
            .iter()
            .try_fold(ColumnMap::default(), |map, (name, header)| {
                map.with(name, header)
            })
            .map_err(Failure::bad_input)?;
        let record = load_record_files(
            kind,
            &self.files,
            self.nameplate.as_deref(),
            self.frequency,
            &columns,
        )
        .map_err(Failure::bad_input)?;
        warn_if_damaged(&self.files[0], &record);
        check_record(&record, kind, &self.files, &columns).map_err(Failure::bad_input)?;
        Ok(ready_record(record, kind, self.voltage_as_issued))
    }
}

/// Winding connection of an induction machine.
#[derive(Debug, Clone, Copy, ValueEnum)]
enum ConnectionArg {
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

/// The test kind of the data.
#[derive(Debug, Clone, Copy, ValueEnum)]
#[value(rename_all = "snake_case")]
enum KindArg {
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
