//! `motorbench probe`: check a rig's wiring (DC or induction machine)
//! before a test; see [`crate::bench::probe()`] for what is driven.

use crate::cli::stdout::outln;
use std::path::PathBuf;

use clap::Args;
use motorbench_drivers::PowerStage;

use super::Failure;
use crate::bench::ProbeReport;
use crate::config::TestConfig;

/// `motorbench probe`.
#[derive(Debug, Args)]
pub struct ProbeArgs {
    /// Rig configuration (TOML).
    #[arg(long)]
    pub config: PathBuf,
    /// Exercise the power stage (off without it: nothing is driven).
    #[arg(long)]
    pub actuate: bool,
}

/// Probe the rig of `args.config`.
pub async fn probe(args: ProbeArgs) -> Result<(), Failure> {
    let cfg = TestConfig::load(&args.config).map_err(Failure::bad_input)?;
    let actuate = args.actuate;
    eprintln!(
        "motorbench: probing {} ({}){}",
        cfg.describe(),
        cfg.common().source,
        match (actuate, cfg.stages().len()) {
            (false, _) => ", reading only",
            (true, 1) => ", with the power stage at a harmless set point",
            (true, _) => ", with each power stage in turn at a harmless set point",
        }
    );
    let max_current = cfg.common().limits.max_current;
    let machine = cfg.into_machine();
    let mut rig = machine.open_rig(false).await.map_err(Failure::runtime)?;
    for s in &rig.stages {
        print_stage(s.name, s.stage.as_ref());
    }
    let report = crate::bench::probe(&mut rig, max_current, actuate).await;
    print_report(&report, actuate)
}

/// A stage's id and what it can do.
fn print_stage(name: &str, stage: &dyn PowerStage) {
    outln!(
        "{name}: {} (current limit: {}, largest set point {})",
        stage.id(),
        if stage.capabilities().current_limit {
            "yes"
        } else {
            "no"
        },
        stage.capabilities().max_setpoint
    );
}

/// The probe's lines and its verdict (exit code 1 when anything failed).
fn print_report(report: &ProbeReport, actuate: bool) -> Result<(), Failure> {
    for line in &report.lines {
        outln!("{line}");
    }
    if !report.passed() {
        return Err(Failure::runtime("probe: something failed (see above)"));
    }
    outln!(
        "probe: every channel read{}",
        if actuate {
            ", every command accepted"
        } else {
            ""
        }
    );
    Ok(())
}
