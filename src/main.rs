//! The `motorbench` command line: a thin layer over the library.
//!
//! Exit codes: 0 success; 1 runtime failure (I/O, recording); 2 bad input
//! (usage, configuration, CSV or MCAP); 3 the test was aborted (the rig
//! was put in its safe state; the record is still written); 4 no
//! identification method applied to the data; 5 `replay --check` found a
//! result that differs from the recorded one. `serve` and `ctl` document
//! their own (see `docs/daemon.md`).

use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Duration;

use clap::{Parser, Subcommand, ValueEnum};
use indicatif::{ProgressBar, ProgressStyle};
use motorbench::bench::{
    build_rig, commission, commission_im, im_model_of_config, is_im_sweep_config, probe,
    CommissionOptions, ImRunConfig, Outcome, Progress,
};
use motorbench::config::load_or_default;
use motorbench::diagnose::{attach_diagnosis, render_diagnosis_text, write_residual_svg};
use motorbench::identify::{identify_dc, identify_im, Identification, ImIdentification};
use motorbench::model::{Connection, ImModel};
use motorbench::record::{load_record_files, read_mcap, Record, SegmentKind};
use motorbench::report::{
    render_im_text, render_text, segment_plots, write_im_svg, write_segments_svg,
};

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
    Run {
        /// Rig and test configuration (TOML); default: the embedded config/sim-dc.toml.
        #[arg(long)]
        config: Option<PathBuf>,
        /// Directory for the record, report and plot.
        #[arg(long, default_value = "records")]
        out: PathBuf,
        /// Pace the simulated rig at wall-clock time instead of as fast as possible.
        #[arg(long)]
        realtime: bool,
        /// Print the identification as JSON (the data contract) instead of text.
        #[arg(long)]
        json: bool,
        /// No progress bar.
        #[arg(long, short)]
        quiet: bool,
        /// Skip the sim-to-real diagnosis after identification.
        #[arg(long)]
        no_diagnose: bool,
    },
    /// Check a rig's wiring: read every sensor channel once; with --actuate,
    /// also drive the power stage at a harmless set point (5 % of the
    /// voltage limit, current limited to 10 % of the current limit), read
    /// again, and return it to its safe state.
    Probe {
        /// Rig configuration (TOML).
        #[arg(long)]
        config: PathBuf,
        /// Exercise the power stage (off without it: nothing is driven).
        #[arg(long)]
        actuate: bool,
    },
    /// Read a recorded MCAP (also a truncated one) and identify the motor again.
    Replay {
        /// The record.
        log: PathBuf,
        /// Print JSON instead of text.
        #[arg(long)]
        json: bool,
        /// Also write the measured-vs-model plot here (SVG).
        #[arg(long)]
        svg: Option<PathBuf>,
        /// Exit with code 5 when the result differs from the recorded one.
        #[arg(long)]
        check: bool,
        /// Skip the sim-to-real diagnosis (the comparison with the recorded
        /// result then leaves its diagnosis out).
        #[arg(long)]
        no_diagnose: bool,
        /// Also write the diagnosis' held-out residuals, before and after, here (SVG).
        #[arg(long)]
        residuals_svg: Option<PathBuf>,
    },
    /// Identify a motor from CSV files (one segment each) or one MCAP record.
    Identify {
        /// Test kind of the data.
        #[arg(long, value_enum)]
        kind: KindArg,
        /// CSV files, or one MCAP file.
        #[arg(required = true)]
        files: Vec<PathBuf>,
        /// Nameplate (JSON object with the contract's keys).
        #[arg(long)]
        nameplate: Option<PathBuf>,
        /// Print JSON instead of text.
        #[arg(long)]
        json: bool,
        /// Also write the measured-vs-model plot here (SVG).
        #[arg(long)]
        svg: Option<PathBuf>,
        /// Induction machine: winding connection (overrides the nameplate's).
        #[arg(long, value_enum)]
        connection: Option<ConnectionArg>,
        /// Induction machine: equivalent circuit to fit.
        #[arg(long, value_enum, default_value = "single-fe")]
        model: ModelArg,
        /// Induction machine, CSV: supply frequency in Hz where the files
        /// have no frequency_Hz column (overrides the nameplate's).
        #[arg(long)]
        frequency: Option<f64>,
    },
    /// Diagnose the sim-to-real gap: where the identified model misfits the
    /// record, which unmodelled effect causes it, how far the gap shrinks
    /// once it is modelled (all on held-out segments).
    Diagnose(motorbench::diagnose::cli::DiagnoseArgs),
    /// The blind benchmark of the diagnosis: generate a suite of simulated
    /// records with withheld effects, or score the diagnosis on one.
    Blind(motorbench::diagnose::cli::BlindArgs),
    /// Run the daemon: control API, one test at a time per rig, safety
    /// supervisor, records index (SIGTERM stops tests safely and exits 0).
    Serve(motorbench::serve::cli::ServeArgs),
    /// Talk to a running daemon (status, start, follow, abort, records, fetch).
    Ctl(motorbench::serve::cli::CtlArgs),
}

/// Winding connection of an induction machine.
#[derive(Clone, Copy, ValueEnum)]
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

/// Equivalent circuit of an induction machine.
#[derive(Clone, Copy, ValueEnum)]
enum ModelArg {
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

#[derive(Clone, Copy, ValueEnum)]
#[value(rename_all = "snake_case")]
enum KindArg {
    /// The contract's names (`dc_step`, …); the kebab-case forms too.
    #[value(name = "dc_step", alias = "dc-step")]
    DcStep,
    #[value(name = "dc_coastdown", alias = "dc-coastdown")]
    DcCoastdown,
    #[value(name = "im_slip_sweep", alias = "im-slip-sweep")]
    ImSlipSweep,
}

impl From<KindArg> for SegmentKind {
    fn from(k: KindArg) -> SegmentKind {
        match k {
            KindArg::DcStep => SegmentKind::DcStep,
            KindArg::DcCoastdown => SegmentKind::DcCoastdown,
            KindArg::ImSlipSweep => SegmentKind::ImSlipSweep,
        }
    }
}

/// A failure with its exit code.
struct Failure {
    code: u8,
    message: String,
}

fn bad_input(e: impl std::fmt::Display) -> Failure {
    Failure {
        code: 2,
        message: e.to_string(),
    }
}

fn runtime(e: impl std::fmt::Display) -> Failure {
    Failure {
        code: 1,
        message: e.to_string(),
    }
}

/// A progress bar on stderr (hidden when stderr is not a terminal).
struct Bar {
    bar: ProgressBar,
    last_tick_ms: AtomicU64,
}

impl Bar {
    fn new(quiet: bool) -> Bar {
        let bar = if quiet {
            ProgressBar::hidden()
        } else {
            ProgressBar::new(0)
        };
        bar.set_style(
            ProgressStyle::with_template(
                "{spinner} [{elapsed_precise}] test time {prefix} {bar:24} segment {pos}/{len} {msg}",
            )
            .expect("valid template"),
        );
        bar.enable_steady_tick(Duration::from_millis(120));
        Bar {
            bar,
            last_tick_ms: AtomicU64::new(0),
        }
    }
}

impl Progress for Bar {
    fn segment(&self, index: usize, total: usize, label: &str) {
        self.bar.set_length(total as u64);
        self.bar.set_position(index as u64 + 1);
        self.bar.set_message(label.to_string());
    }

    fn tick(&self, t_s: f64) {
        let ms = (t_s * 1e3) as u64;
        if ms >= self.last_tick_ms.load(Ordering::Relaxed) + 100 {
            self.last_tick_ms.store(ms, Ordering::Relaxed);
            self.bar.set_prefix(format!("{t_s:.1} s"));
        }
    }

    fn done(&self, message: &str) {
        self.bar.finish_and_clear();
        if !self.bar.is_hidden() {
            eprintln!("{message}");
        }
    }
}

fn print_identification(
    id: &Identification,
    json: bool,
    truth: Option<&motorbench::model::DcParams>,
) {
    if json {
        println!("{}", id.report.to_json_pretty());
    } else {
        print!("{}", render_text(id, truth));
        print_diagnosis_text(&id.report);
    }
}

/// The diagnosis of a report, as text, after a blank line.
fn print_diagnosis_text(report: &motorbench::report::IdentificationReport) {
    if let Some(d) = &report.diagnosis {
        print!("\n{}", render_diagnosis_text(d));
    }
}

fn identified_or_code(id: &Identification) -> Result<(), Failure> {
    match id.refusal() {
        None => Ok(()),
        Some(why) => Err(Failure {
            code: 4,
            message: format!("nothing can be identified from this data: {why}"),
        }),
    }
}

/// What `run` was asked for on the command line.
struct RunArgs {
    config: Option<PathBuf>,
    out: PathBuf,
    realtime: bool,
    json: bool,
    quiet: bool,
    diagnose: bool,
}

async fn run(args: RunArgs) -> Result<(), Failure> {
    let RunArgs {
        config,
        out,
        realtime,
        json,
        quiet,
        diagnose,
    } = args;
    if let Some(path) = &config {
        let text = std::fs::read_to_string(path)
            .map_err(|e| bad_input(format!("{}: {e}", path.display())))?;
        if is_im_sweep_config(&text) {
            return run_im(path, out, realtime, json, quiet, diagnose).await;
        }
    }
    let cfg = load_or_default(config.as_ref()).map_err(bad_input)?;
    let (stop_tx, stop_rx) = tokio::sync::watch::channel(false);
    let stop = stop_signal();
    tokio::spawn(async move {
        stop.await;
        let _ = stop_tx.send(true);
    });
    let progress = Bar::new(quiet || json);
    let opts = CommissionOptions {
        out_dir: out,
        realtime,
        diagnose,
    };
    if !json && !quiet {
        eprintln!(
            "motorbench: {} on {} ({})",
            cfg.motor_id,
            cfg.backend.describe(),
            cfg.source
        );
    }
    let done = commission(&cfg, &opts, &progress, &stop_rx)
        .await
        .map_err(runtime)?;
    print_identification(&done.identification, json, done.truth.as_ref());
    if !json {
        println!(
            "\nrecord: {} ({} messages)",
            done.mcap_path.display(),
            done.stats.messages
        );
        println!("report: {}", done.report_path.display());
        println!("plot:   {}", done.svg_path.display());
        if let Some(path) = &done.residuals_svg_path {
            println!("gap:    {}", path.display());
        }
    }
    if let Outcome::Aborted { reason } = &done.outcome {
        return Err(Failure {
            code: 3,
            message: format!("test aborted: {reason}"),
        });
    }
    identified_or_code(&done.identification)
}

/// `run` with an induction-machine slip-sweep configuration.
async fn run_im(
    path: &Path,
    out: PathBuf,
    realtime: bool,
    json: bool,
    quiet: bool,
    diagnose: bool,
) -> Result<(), Failure> {
    let cfg = ImRunConfig::load(path).map_err(bad_input)?;
    let (stop_tx, stop_rx) = tokio::sync::watch::channel(false);
    let stop = stop_signal();
    tokio::spawn(async move {
        stop.await;
        let _ = stop_tx.send(true);
    });
    if !json && !quiet {
        eprintln!(
            "motorbench: {} slip sweep on {} ({})",
            cfg.motor_id,
            cfg.describe_rig(),
            cfg.source
        );
    }
    let opts = CommissionOptions {
        out_dir: out,
        realtime,
        diagnose,
    };
    let done = commission_im(&cfg, &opts, &stop_rx)
        .await
        .map_err(runtime)?;
    let identified = print_im(&done.identification, json, None);
    if !json {
        println!(
            "\nrecord: {} ({} messages)",
            done.mcap_path.display(),
            done.stats.messages
        );
        println!("report: {}", done.report_path.display());
        println!("plot:   {}", done.svg_path.display());
        if let Some(path) = &done.residuals_svg_path {
            println!("gap:    {}", path.display());
        }
    }
    if let Outcome::Aborted { reason } = &done.outcome {
        return Err(Failure {
            code: 3,
            message: format!("test aborted: {reason}"),
        });
    }
    identified
}

/// SIGTERM or SIGINT. The handlers are installed when this is called, not
/// when the future is first polled: a signal that arrives right after the
/// daemon has announced its address is then a clean stop, never the
/// default (fatal) disposition. Must be called on the runtime.
fn stop_signal() -> impl std::future::Future<Output = ()> {
    #[cfg(unix)]
    {
        use tokio::signal::unix::{signal, SignalKind};
        let term = signal(SignalKind::terminate());
        let int = signal(SignalKind::interrupt());
        async move {
            match (term, int) {
                (Ok(mut term), Ok(mut int)) => {
                    tokio::select! {
                        _ = term.recv() => {},
                        _ = int.recv() => {},
                    }
                }
                (Ok(mut one), Err(_)) | (Err(_), Ok(mut one)) => {
                    one.recv().await;
                }
                (Err(_), Err(_)) => std::future::pending().await,
            }
        }
    }
    #[cfg(not(unix))]
    {
        async {
            let _ = tokio::signal::ctrl_c().await;
        }
    }
}

async fn probe_rig(config: &Path, actuate: bool) -> Result<(), Failure> {
    let cfg = motorbench::config::Config::load(config).map_err(bad_input)?;
    eprintln!(
        "motorbench: probing {} ({}){}",
        cfg.backend.describe(),
        cfg.source,
        if actuate {
            ", with the power stage at a harmless set point"
        } else {
            ", reading only"
        }
    );
    let mut rig = build_rig(&cfg, false).await.map_err(runtime)?;
    println!(
        "power stage: {} (current limit: {}, largest set point {})",
        rig.stage.id(),
        if rig.stage.capabilities().current_limit {
            "yes"
        } else {
            "no"
        },
        rig.stage.capabilities().max_setpoint
    );
    let report = probe(&cfg, &mut rig, actuate).await;
    for line in &report.lines {
        println!("{line}");
    }
    if report.passed() {
        println!(
            "probe: every channel read{}",
            if actuate {
                ", every command accepted"
            } else {
                ""
            }
        );
        Ok(())
    } else {
        Err(runtime("probe: something failed (see above)"))
    }
}

fn write_svg(path: Option<&Path>, record: &Record, id: &Identification) -> Result<(), Failure> {
    if let Some(path) = path {
        write_segments_svg(path, &segment_plots(record, id)).map_err(runtime)?;
    }
    Ok(())
}

/// `replay`; `diagnose` is None with --no-diagnose, else where to write
/// the residual plot, if anywhere.
fn replay(
    log: &Path,
    json: bool,
    svg: Option<&Path>,
    check: bool,
    diagnose: Option<Option<&Path>>,
) -> Result<(), Failure> {
    let record = read_mcap(log).map_err(bad_input)?;
    warn_if_damaged(log, &record);
    if !record.operating_points.is_empty() {
        // An induction-machine record: the circuit its configuration named
        // (else single-fe), the nameplate's connection.
        let model = record
            .meta
            .as_ref()
            .and_then(|m| im_model_of_config(&m.config))
            .unwrap_or(ImModel::SingleFe);
        let mut id = identify_im(&record, None, model);
        diagnose_replay(&mut id.report, &record, SegmentKind::ImSlipSweep, diagnose)?;
        let identified = print_im(&id, json, svg);
        let now = serde_json::to_value(&id.report).expect("a report always serialises");
        compare_with_recorded(&record, &now, check)?;
        return identified;
    }
    let mut id = identify_dc(&record);
    diagnose_replay(&mut id.report, &record, SegmentKind::DcStep, diagnose)?;
    print_identification(&id, json, None);
    write_svg(svg, &record, &id)?;
    let now = serde_json::to_value(&id.report).expect("a report always serialises");
    compare_with_recorded(&record, &now, check)?;
    identified_or_code(&id)
}

/// Diagnose a replayed record into its report (unless `diagnose` is None)
/// and write the residual plot where asked.
fn diagnose_replay(
    report: &mut motorbench::report::IdentificationReport,
    record: &Record,
    kind: SegmentKind,
    diagnose: Option<Option<&Path>>,
) -> Result<(), Failure> {
    let Some(svg) = diagnose else {
        return Ok(());
    };
    let plot = attach_diagnosis(report, record, kind);
    if let (Some(path), Some(plot)) = (svg, plot) {
        write_residual_svg(&plot, path).map_err(runtime)?;
    }
    Ok(())
}

/// Say whether the replayed report equals the recorded `/bench/result`;
/// with `check`, a difference is exit code 5.
fn compare_with_recorded(
    record: &Record,
    now: &serde_json::Value,
    check: bool,
) -> Result<(), Failure> {
    // A record made with --no-diagnose (or before the diagnosis existed)
    // holds no diagnosis: compare the identification alone.
    let mut now = now.clone();
    if let (Some(recorded), Some(obj)) = (&record.recorded_result, now.as_object_mut()) {
        if recorded.get("diagnosis").is_none() {
            obj.remove("diagnosis");
        }
    }
    match &record.recorded_result {
        Some(recorded) if *recorded == now => {
            eprintln!("replay: identical to the recorded /bench/result")
        }
        Some(_) => {
            eprintln!("replay: DIFFERS from the recorded /bench/result");
            if check {
                return Err(Failure {
                    code: 5,
                    message: "replayed identification differs from the recorded one".into(),
                });
            }
        }
        None => eprintln!("replay: the record holds no /bench/result to compare with"),
    }
    Ok(())
}

fn load_record(
    kind: SegmentKind,
    files: &[PathBuf],
    nameplate: Option<&Path>,
    frequency: Option<f64>,
) -> Result<Record, Failure> {
    let record = load_record_files(kind, files, nameplate, frequency).map_err(bad_input)?;
    warn_if_damaged(&files[0], &record);
    Ok(record)
}

/// Say on stderr how much of a damaged record was recovered, and where
/// the damage is.
fn warn_if_damaged(path: &Path, record: &Record) {
    if let Some(r) = &record.recovery {
        eprintln!("motorbench: {} is damaged: {r}", path.display());
    }
}

/// Options of induction-machine identification from the command line.
struct ImArgs {
    connection: Option<Connection>,
    model: ImModel,
    frequency: Option<f64>,
}

fn print_im(id: &ImIdentification, json: bool, svg: Option<&Path>) -> Result<(), Failure> {
    if json {
        println!("{}", id.report.to_json_pretty());
    } else {
        print!("{}", render_im_text(id));
        print_diagnosis_text(&id.report);
    }
    if let Some(path) = svg {
        write_im_svg(path, id).map_err(runtime)?;
    }
    if id.report.best.is_some() {
        Ok(())
    } else {
        Err(Failure {
            code: 4,
            message: "no identification method applies to this data (see the warnings)".into(),
        })
    }
}

fn identify(
    kind: SegmentKind,
    files: &[PathBuf],
    nameplate: Option<&Path>,
    json: bool,
    svg: Option<&Path>,
    im: ImArgs,
) -> Result<(), Failure> {
    let record = load_record(kind, files, nameplate, im.frequency)?;
    if kind == SegmentKind::ImSlipSweep {
        let id = identify_im(&record, im.connection, im.model);
        return print_im(&id, json, svg);
    }
    motorbench::identify::check_plausible_files(&record, kind, files).map_err(bad_input)?;
    let id = identify_dc(&record);
    print_identification(&id, json, None);
    write_svg(svg, &record, &id)?;
    identified_or_code(&id)
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

fn main() -> ExitCode {
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Run {
            config,
            out,
            realtime,
            json,
            quiet,
            no_diagnose,
        } => tokio::runtime::Builder::new_multi_thread()
            .enable_all()
            .build()
            .map_err(runtime)
            .and_then(|rt| {
                rt.block_on(run(RunArgs {
                    config,
                    out,
                    realtime,
                    json,
                    quiet,
                    diagnose: !no_diagnose,
                }))
            }),
        Command::Probe { config, actuate } => tokio::runtime::Builder::new_multi_thread()
            .enable_all()
            .build()
            .map_err(runtime)
            .and_then(|rt| rt.block_on(probe_rig(&config, actuate))),
        Command::Replay {
            log,
            json,
            svg,
            check,
            no_diagnose,
            residuals_svg,
        } => replay(
            &log,
            json,
            svg.as_deref(),
            check,
            (!no_diagnose).then_some(residuals_svg.as_deref()),
        ),
        Command::Identify {
            kind,
            files,
            nameplate,
            json,
            svg,
            connection,
            model,
            frequency,
        } => identify(
            kind.into(),
            &files,
            nameplate.as_deref(),
            json,
            svg.as_deref(),
            ImArgs {
                connection: connection.map(Into::into),
                model: model.into(),
                frequency,
            },
        ),
        Command::Diagnose(args) => {
            return ExitCode::from(motorbench::diagnose::cli::run_diagnose(args))
        }
        Command::Blind(args) => return ExitCode::from(motorbench::diagnose::cli::run_blind(args)),
        Command::Serve(args) => {
            return block_on(async {
                // Before anything is bound or announced.
                let stop = stop_signal();
                motorbench::serve::cli::run_serve(args, stop).await
            });
        }
        Command::Ctl(args) => return block_on(motorbench::serve::cli::run_ctl(args)),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(f) => {
            eprintln!("motorbench: {}", f.message);
            ExitCode::from(f.code)
        }
    }
}
