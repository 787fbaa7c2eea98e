//! `motorbench run`: one test on the rig its configuration names, whatever
//! the machine ([`TestConfig::into_machine`]), through the one session
//! ([`commission`]): recorded, identified, diagnosed and reported.

use std::path::PathBuf;

use clap::Args;

use super::output::{print_analysis, RunFiles};
use super::progress_bar::Bar;
use super::signal::stop_on_signal;
use super::Failure;
use crate::bench::Outcome;
use crate::config::TestConfig;
use crate::session::{commission, CommissionOptions};

/// `motorbench run`.
#[derive(Debug, Args)]
pub struct RunArgs {
    /// Rig and test configuration (TOML); default: the embedded config/sim-dc.toml.
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Directory for the record, report and plot.
    #[arg(long, default_value = "records")]
    pub out: PathBuf,
    /// Pace the simulated rig at wall-clock time instead of as fast as possible.
    #[arg(long)]
    pub realtime: bool,
    /// Print the identification as JSON (the data contract) instead of text.
    #[arg(long)]
    pub json: bool,
    /// No progress bar.
    #[arg(long, short)]
    pub quiet: bool,
    /// Skip the sim-to-real diagnosis after identification.
    #[arg(long)]
    pub no_diagnose: bool,
}

/// Run `args`' test; SIGTERM or SIGINT stops it safely (exit code 3).
pub async fn run(args: RunArgs) -> Result<(), Failure> {
    let cfg = TestConfig::load_or_default(args.config.as_deref()).map_err(Failure::bad_input)?;
    let machine = cfg.into_machine();
    let stop = stop_on_signal();
    let opts = CommissionOptions {
        out_dir: args.out,
        realtime: args.realtime,
        diagnose: !args.no_diagnose,
    };
    if !args.json && !args.quiet {
        eprintln!("motorbench: {}", machine.describe());
    }
    let progress = Bar::new(args.quiet || args.json);
    let done = commission(machine, &opts, &progress, &stop)
        .await
        .map_err(Failure::runtime)?;
    let identified = print_analysis(done.analysis.as_ref(), &done.record, args.json, None);
    if !args.json {
        RunFiles {
            mcap: done.mcap_path,
            messages: done.stats.messages,
            report: done.files.report,
            svg: done.files.svg,
            residuals_svg: done.files.residuals_svg,
        }
        .print();
    }
    if let Outcome::Aborted { reason } = &done.outcome {
        return Err(Failure::aborted(reason));
    }
    identified
}
