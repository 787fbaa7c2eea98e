//! The bench, whatever the machine: the one reading core every plan
//! reads through (`sequencer`: select on the stop, stale-data timeout,
//! recording into the [`RecordSink`], every batch checked with the one
//! [`SafetyMonitor`], the safe state first), settle detection, limits, the
//! speed from an encoder, progress, `probe`, the safety supervisor
//! task that watches a daemon's test independently of the sequencing,
//! its escalation when a stage ignores the safe command
//! (`escalation.rs`), and the stuck-sensor warning (`stuck.rs`).
//! The machines' plans (the DC steps, the IM sweep) and rigs are in
//! [`crate::machine`].

mod encoder;
pub mod escalation;
mod interlock;
mod limits;
mod probe;
mod progress;
mod sampling;
pub(crate) mod sequencer;
mod settle;
mod sink;
mod stop_path;
mod stuck;
mod supervisor;
mod thermal;

pub use encoder::SpeedFromEncoder;
pub use interlock::{
    supervise, supervise_stages, InterlockedStage, StopReport, Supervised, SupervisedSensors,
    SupervisedStages, SupervisorHandle, SupervisorSummary, SupervisorTiming,
};
pub use limits::Trip;
pub use probe::{probe, ProbeLine, ProbeReport, PROBE_CURRENT_FRACTION, PROBE_SETPOINT_FRACTION};
pub use progress::{NoProgress, Progress};
pub use sampling::SamplingEvents;
pub use settle::SettleDetector;
pub use sink::{sensor_channels_with_speed, BenchError, Outcome, RecordSink};
pub use stop_path::StopPath;
pub use stuck::StuckDetector;
pub use supervisor::{
    HeatingBudget, MonitorError, Readings, SafetyMonitor, SafetyRules, StopCause, SUPERVISOR_ID,
};
pub use thermal::WindingTemperature;
