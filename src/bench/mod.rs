//! The bench: test plans, settle detection, limits and the safe state, the
//! simulated rig, the sequencing that ties them to the recorder, and the
//! safety supervisor that watches a running test independently of the
//! sequencing.

mod commission;
mod encoder;
mod interlock;
mod limits;
mod plan;
mod progress;
mod runner;
mod settle;
mod sim_rig;
mod supervisor;
mod thermal;

pub use commission::{commission, CommissionError, CommissionOptions, Commissioned};
pub use encoder::SpeedFromEncoder;
pub use interlock::{
    supervise, InterlockedStage, StopReport, Supervised, SupervisedSensors, SupervisorHandle,
    SupervisorSummary, SupervisorTiming,
};
pub use limits::{check_limits, Trip};
pub use plan::{plan_steps, PlanStep};
pub use progress::{NoProgress, Progress};
pub use runner::{
    record_channels, run_test, BenchError, Outcome, RecordSink, SUPPLY_LIMIT_FRACTION,
};
pub use settle::SettleDetector;
pub use sim_rig::{sim_rig, SimPowerStage, SimSensors};
pub use supervisor::{Readings, SafetyMonitor, StopCause, SUPERVISOR_ID};
pub use thermal::WindingTemperature;
