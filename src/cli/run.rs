//! `motorbench run`: one test on the rig its configuration names (DC or
//! induction machine, told apart only by [`TestConfig`]), recorded,
//! identified, diagnosed and reported.

use std::path::PathBuf;

use clap::Args;

use super::output::{print_dc, print_im, RunFiles};
use super::progress_bar::Bar;
use super::signal::stop_on_signal;
use super::Failure;
use crate::bench::{commission, commission_im, CommissionOptions, Outcome};
use crate::config::TestConfig;

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
    let stop = stop_on_signal();
    let opts = CommissionOptions {
        out_dir: args.out,
        realtime: args.realtime,
        diagnose: !args.no_diagnose,
    };
    let chatty = !args.json && !args.quiet;
    let (identified, outcome, files) = match &cfg {
        TestConfig::Dc(cfg) => {
            let progress = Bar::new(args.quiet || args.json);
            if chatty {
                eprintln!(
                    "motorbench: {} on {} ({})",
                    cfg.motor_id,
                    cfg.backend.describe(),
                    cfg.source
                );
            }
            let done = commission(cfg, &opts, &progress, &stop)
                .await
                .map_err(Failure::runtime)?;
            let identified = print_dc(
                &done.identification,
                None,
                args.json,
                None,
                done.truth.as_ref(),
            );
            let files = RunFiles {
                mcap: done.mcap_path,
                messages: done.stats.messages,
                report: done.report_path,
                svg: done.svg_path,
                residuals_svg: done.residuals_svg_path,
            };
            (identified, done.outcome, files)
        }
        TestConfig::Im(cfg) => {
            if chatty {
                eprintln!(
                    "motorbench: {} slip sweep on {} ({})",
                    cfg.motor_id,
                    cfg.describe_rig(),
                    cfg.source
                );
            }
            let done = commission_im(cfg, &opts, &stop)
                .await
                .map_err(Failure::runtime)?;
            let identified = print_im(&done.identification, args.json, None);
            let files = RunFiles {
                mcap: done.mcap_path,
                messages: done.stats.messages,
                report: done.report_path,
                svg: done.svg_path,
                residuals_svg: done.residuals_svg_path,
            };
            (identified, done.outcome, files)
        }
    };
    if !args.json {
        files.print();
    }
    if let Outcome::Aborted { reason } = &outcome {
        return Err(Failure::aborted(reason));
    }
    identified
}
