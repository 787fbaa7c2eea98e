//! The bench: test plans, settle detection, limits and the safe state, the
//! simulated rigs (DC; induction machine with VFD and dynamometer, with the
//! `im_slip_sweep` plan), and the sequencing that ties them to the recorder.

mod commission;
mod encoder;
mod im_commission;
mod im_config;
mod im_sweep;
mod limits;
mod plan;
mod progress;
mod runner;
mod settle;
mod sim_im_rig;
mod sim_rig;

pub use commission::{commission, CommissionError, CommissionOptions, Commissioned};
pub use encoder::SpeedFromEncoder;
pub use im_commission::{commission_im, ImCommissioned};
pub use im_config::{im_model_of_config, is_im_sweep_config, ImRunConfig};
pub use im_sweep::{run_im_sweep, sweep_channels, ImSweepPlan};
pub use limits::{check_limits, Trip};
pub use plan::{plan_steps, PlanStep};
pub use progress::{NoProgress, Progress};
pub use runner::{
    record_channels, run_test, BenchError, Outcome, RecordSink, SUPPLY_LIMIT_FRACTION,
};
pub use settle::SettleDetector;
pub use sim_im_rig::{sim_im_rig, SimDyno, SimImRigConfig, SimImSensors, SimVfd, COPPER_ALPHA};
pub use sim_rig::{sim_rig, SimPowerStage, SimSensors};
