//! Command-line arguments and entry points of `motorbench diagnose` and
//! `motorbench blind` (the blind benchmark); the binary's `main` only
//! dispatches here.

use crate::cli::stdout::{out, outln};
use std::path::{Path, PathBuf};

use clap::{Args, Subcommand};
use indicatif::{ProgressBar, ProgressStyle};

use super::blind::{generate_suite, score_suite, SuitePlans, DEFAULT_SEED};
use super::{diagnose, render_diagnosis_text, write_residual_svg, DiagnoseOptions};
use crate::cli::RecordInput;

/// `motorbench diagnose`.
#[derive(Debug, Args)]
pub struct DiagnoseArgs {
    /// The data: kind, files, nameplate.
    #[command(flatten)]
    pub input: RecordInput,
    /// Print the contract's diagnosis JSON instead of text.
    #[arg(long)]
    pub json: bool,
    /// Also write the residuals before and after, per region, here (SVG).
    #[arg(long)]
    pub svg: Option<PathBuf>,
}

/// Run `diagnose`; the exit code (0 done, 1 output failed, 2 bad input,
/// 4 the data cannot be diagnosed).
pub fn run_diagnose(args: DiagnoseArgs) -> u8 {
    let record = match args.input.load() {
        Ok(r) => r,
        Err(e) => return fail(e.code, &e.message),
    };
    let options = DiagnoseOptions {
        connection: args.input.connection(),
        ..Default::default()
    };
    let run = match diagnose(&record, args.input.kind(), &options) {
        Ok(run) => run,
        Err(e) => return fail(4, &e.to_string()),
    };
    if args.json {
        outln!(
            "{}",
            serde_json::to_string_pretty(&run.report).expect("a diagnosis serialises")
        );
    } else {
        out!("{}", render_diagnosis_text(&run.report));
    }
    if let Some(path) = &args.svg {
        if let Err(e) = write_residual_svg(&run.plot, path) {
            return fail(1, &e);
        }
    }
    0
}

/// `motorbench blind`.
#[derive(Debug, Args)]
pub struct BlindArgs {
    /// What to do.
    #[command(subcommand)]
    pub command: BlindCommand,
}

/// The blind benchmark's subcommands.
#[derive(Debug, Subcommand)]
pub enum BlindCommand {
    /// Simulate a suite of records, each with one withheld effect (or
    /// none), into a new directory; the truth goes to its own file.
    Generate {
        /// The suite's directory (must not exist).
        #[arg(long)]
        out: PathBuf,
        /// Seed of the random draws; the default is the one CI scores.
        #[arg(long, default_value_t = DEFAULT_SEED)]
        seed: u64,
        /// The DC cases' test plans: `wide` (ramps, PRBS, closed loops,
        /// short holds, varied sensors) or `classic` (settled staircases).
        #[arg(long, value_enum, default_value_t = SuitePlans::Wide)]
        plans: SuitePlans,
    },
    /// Diagnose every case of a suite from its files, then score the
    /// verdicts against the truth file.
    Score {
        /// The suite's directory.
        dir: PathBuf,
        /// Print the per-case scores as JSON instead of the summary.
        #[arg(long)]
        json: bool,
    },
}

/// Run `blind`; the exit code (0 done, 2 bad input or output failure).
pub fn run_blind(args: BlindArgs) -> u8 {
    match args.command {
        BlindCommand::Generate { out, seed, plans } => {
            let bar = bar("simulating");
            let tick = |n: usize, total: usize| {
                bar.set_length(total as u64);
                bar.set_position(n as u64);
            };
            match generate_suite(&out, seed, plans, &tick) {
                Ok(m) => {
                    bar.finish_and_clear();
                    outln!(
                        "{} cases written to {} (seed {seed}); truth in {}",
                        m.cases.len(),
                        out.display(),
                        out.join("truth.json").display()
                    );
                    0
                }
                Err(e) => fail(2, &e),
            }
        }
        BlindCommand::Score { dir, json } => score(&dir, json),
    }
}

fn score(dir: &Path, json: bool) -> u8 {
    let bar = bar("diagnosing");
    let tick = |n: usize, total: usize| {
        bar.set_length(total as u64);
        bar.set_position(n as u64);
    };
    match score_suite(dir, &tick) {
        Ok(score) => {
            bar.finish_and_clear();
            if json {
                outln!(
                    "{}",
                    serde_json::to_string_pretty(&score).expect("a score serialises")
                );
            } else {
                out!("{score}");
            }
            0
        }
        Err(e) => fail(2, &e),
    }
}

fn bar(what: &str) -> ProgressBar {
    let bar = ProgressBar::new(0);
    bar.set_style(
        ProgressStyle::with_template(
            "{spinner} {msg} case {pos}/{len} {bar:24} [{elapsed_precise}]",
        )
        .expect("valid template"),
    );
    bar.set_message(what.to_string());
    bar
}

fn fail(code: u8, message: &dyn std::fmt::Display) -> u8 {
    eprintln!("motorbench: {message}");
    code
}
