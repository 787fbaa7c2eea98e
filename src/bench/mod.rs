//! The bench: test plans, settle detection, limits and the safe state, the
//! simulated rigs (DC; induction machine with VFD and dynamometer, with the
//! `im_slip_sweep` plan), the sequencing that ties them to the recorder
//! (one reading core, `sequencer`, under both plans and both the CLI and
//! the daemon, checking every batch with the one [`SafetyMonitor`]), and
//! the safety supervisor task that watches a daemon's test independently
//! of the sequencing.

mod encoder;
mod im_config;
mod im_modbus_config;
mod im_rig;
mod im_stages;
mod im_sweep;
mod interlock;
mod limits;
mod plan;
mod probe;
mod progress;
mod rig;
mod runner;
mod sampling;
mod sequencer;
mod served;
mod served_im;
mod settle;
mod sim_im_rig;
mod sim_rig;
mod stop_path;
mod supervisor;
mod supply_limits;
mod thermal;

pub use encoder::SpeedFromEncoder;
pub use im_config::ImRunConfig;
pub use im_modbus_config::ImModbusRig;
pub use im_rig::{build_im_rig, ImRig, SERVED_IM_PLANT_RATE_HZ};
pub use im_stages::{VfdDyno, VfdSupply};
pub use im_sweep::{run_im_sweep, sweep_channels, ImSweepPlan};
pub use interlock::{
    supervise, supervise_stages, InterlockedStage, StopReport, Supervised, SupervisedSensors,
    SupervisedStages, SupervisorHandle, SupervisorSummary, SupervisorTiming,
};
pub use limits::Trip;
pub use plan::{plan_steps, PlanStep};
pub use probe::{probe, ProbeLine, ProbeReport, PROBE_CURRENT_FRACTION, PROBE_SETPOINT_FRACTION};
pub use progress::{NoProgress, Progress};
pub use rig::{build_rig, ModbusProbe, Rig, RigError, SERVED_PLANT_RATE_HZ};
pub use runner::{
    record_channels, run_test, BenchError, Outcome, RecordSink, SUPPLY_LIMIT_FRACTION,
};
pub use sampling::SamplingEvents;
pub use served::{ServeError, ServedLink, ServedRig};
pub use served_im::{ServedImRig, ServedVfd};
pub use settle::SettleDetector;
pub use sim_im_rig::{sim_im_rig, SimDyno, SimImRigConfig, SimImSensors, SimVfd, COPPER_ALPHA};
pub use sim_rig::{sim_rig, SimPowerStage, SimSensors};
pub use stop_path::StopPath;
pub use supervisor::{
    HeatingBudget, Readings, SafetyMonitor, SafetyRules, StopCause, SUPERVISOR_ID,
};
pub use supply_limits::SupplyLimitDetector;
pub use thermal::WindingTemperature;
