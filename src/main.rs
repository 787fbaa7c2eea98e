//! The `motorbench` command line: parse the arguments, dispatch to the
//! library ([`motorbench::cli`] for `run`, `probe`, `replay` and
//! `identify`; the diagnosis and the daemon bring their own).
//!
//! Exit codes: 0 success; 1 runtime failure (I/O, recording); 2 bad input
//! (usage, configuration, CSV or MCAP); 3 the test was aborted (the rig
//! was put in its safe state; the record is still written); 4 no
//! identification method applied to the data; 5 `replay --check` found a
//! result that differs from the recorded one. `serve` and `ctl` document
//! their own (see `docs/daemon.md`).

use std::process::ExitCode;

use clap::{CommandFactory, Parser, Subcommand};
use motorbench::cli::{
    self, CompletionsArgs, ExportArgs, Failure, IdentifyArgs, ManArgs, ProbeArgs, RecoverArgs,
    ReplayArgs, RunArgs,
};
use motorbench::diagnose::cli::{run_blind, run_diagnose, BlindArgs, DiagnoseArgs};
use motorbench::serve::cli::{run_ctl, run_serve, CtlArgs, ServeArgs};

#[derive(Parser)]
#[command(
    name = "motorbench",
    version,
    about = "Commission electric motors on a test rig: run a test, record it to MCAP, identify the motor."
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Run a test plan on a rig, record every sample to MCAP, identify the
    /// motor. Without --config: the simulated rig with the seed paper's motor.
    Run(RunArgs),
    /// Check a rig's wiring: read every sensor channel once; with --actuate,
    /// also drive the power stage at a harmless set point (5 % of the
    /// voltage limit, current limited to 10 % of the current limit), read
    /// again, and return it to its safe state.
    Probe(ProbeArgs),
    /// Read a recorded MCAP (also a truncated one) and identify the motor again.
    Replay(ReplayArgs),
    /// Finish records cut by a killed process (no summary, no index) as
    /// files indexed MCAP readers open; the cut file is kept beside.
    Recover(RecoverArgs),
    /// Identify a motor from CSV files (one segment each) or one MCAP record.
    Identify(IdentifyArgs),
    /// Export a record for other tools: each segment as contract CSV
    /// (`identify` reads it back to the same report), every channel as one
    /// Parquet file (pandas, polars, MATLAB).
    Export(ExportArgs),
    /// Diagnose the sim-to-real gap: where the identified model misfits the
    /// record, which unmodelled effect causes it, how far the gap shrinks
    /// once it is modelled (all on held-out segments).
    Diagnose(DiagnoseArgs),
    /// The blind benchmark of the diagnosis: generate a suite of simulated
    /// records with withheld effects, or score the diagnosis on one.
    Blind(BlindArgs),
    /// Run the daemon: control API, one test at a time per rig, safety
    /// supervisor, records index (SIGTERM stops tests safely and exits 0).
    Serve(ServeArgs),
    /// Talk to a running daemon (status, start, follow, abort, records, fetch).
    Ctl(CtlArgs),
    /// Print a shell completion script (bash, zsh, fish, elvish, powershell).
    Completions(CompletionsArgs),
    /// Print the man page, or write every page (one per subcommand) into a
    /// directory.
    Man(ManArgs),
}

/// Run `future` on a multi-threaded runtime; its value is the exit code.
fn block_on(future: impl std::future::Future<Output = u8>) -> ExitCode {
    match tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()
    {
        Ok(rt) => ExitCode::from(rt.block_on(future)),
        Err(e) => {
            eprintln!("motorbench: {e}");
            ExitCode::from(1)
        }
    }
}

/// Run a subcommand's `future` on a multi-threaded runtime.
fn block_on_cli(future: impl std::future::Future<Output = Result<(), Failure>>) -> ExitCode {
    Failure::exit(
        tokio::runtime::Builder::new_multi_thread()
            .enable_all()
            .build()
            .map_err(Failure::runtime)
            .and_then(|rt| rt.block_on(future)),
    )
}

fn main() -> ExitCode {
    match Cli::parse().command {
        Command::Run(args) => block_on_cli(cli::run(args)),
        Command::Probe(args) => block_on_cli(cli::probe(args)),
        Command::Replay(args) => Failure::exit(cli::replay(args)),
        Command::Recover(args) => Failure::exit(cli::recover(args)),
        Command::Identify(args) => Failure::exit(cli::identify(args)),
        Command::Export(args) => Failure::exit(cli::export(args)),
        Command::Diagnose(args) => ExitCode::from(run_diagnose(args)),
        Command::Blind(args) => ExitCode::from(run_blind(args)),
        Command::Serve(args) => {
            // A daemon runs test after test: few allocator arenas, so
            // that the memory each test frees goes back to the system.
            motorbench::serve::heap::limit_arenas();
            block_on(async {
                // Before anything is bound or announced.
                let stop = cli::stop_signal();
                run_serve(args, stop).await
            })
        }
        Command::Ctl(args) => block_on(run_ctl(args)),
        Command::Completions(args) => Failure::exit(cli::completions(args, Cli::command())),
        Command::Man(args) => Failure::exit(cli::man(args, Cli::command())),
    }
}
