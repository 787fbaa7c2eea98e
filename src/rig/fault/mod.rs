//! Faults injected into a rig on purpose (the `[[fault]]` array, see
//! [`crate::config::FaultPlan`]), so that every row of the fault matrix
//! (`docs/reliability.md`) can be run and tested: decorators around the
//! rig's existing parts, driven by the test's own time.
//!
//! - [`FaultySensors`] (`sensors.rs`): a [`SensorStream`] whose readings
//!   stick, spike, turn NaN or infinite, whose timestamps jump, whose
//!   encoder loses counts;
//! - [`FaultyStage`] (`stage.rs`): a [`PowerStage`] that limits its
//!   current, or acknowledges the safe command (and the output disable)
//!   without acting on it;
//! - [`ProtocolFaults`] (`reply.rs`): a served Modbus device that does
//!   not answer, answers with an exception, or goes away;
//! - [`FaultyLine`] (`line.rs`): a served RTU device's line whose replies
//!   carry a wrong CRC or are preceded by garbage bytes;
//! - [`StreamRecordFate`] (`stream.rs`): a served streaming DAQ that falls
//!   silent, hangs up, or sends records with a wrong check or after
//!   garbage bytes.
//!
//! The sensor and stage faults act on the test time of the readings (the
//! stage reads it from the [`FaultClock`] the sensors keep); the protocol
//! faults act on the served plant's clock, which runs from the start of
//! the rig (the same time, give or take the setup).
//!
//! [`SensorStream`]: motorbench_drivers::SensorStream
//! [`PowerStage`]: motorbench_drivers::PowerStage

mod line;
mod reply;
mod sensors;
mod stage;
mod stream;

use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;

pub use line::FaultyLine;
pub use reply::ProtocolFaults;
pub use sensors::FaultySensors;
pub use stage::FaultyStage;
pub use stream::StreamRecordFate;

use crate::config::FaultPlan;
use crate::machine::OpenedRig;

use super::RigError;

/// The test time of the latest reading, shared by the faulty sensors
/// (which set it) and the faulty stages (which act on it).
#[derive(Debug, Clone, Default)]
pub struct FaultClock(Arc<AtomicU64>);

impl FaultClock {
    /// The latest reading's time, s.
    pub fn t_s(&self) -> f64 {
        self.0.load(Ordering::Relaxed) as f64 * 1e-9
    }

    fn set(&self, t_ns: u64) {
        self.0.fetch_max(t_ns, Ordering::Relaxed);
    }
}

/// The configuration's name of a stage's role (`power stage` →
/// `power_stage`, `DC source` → `dc_source`).
pub fn stage_role(name: &str) -> String {
    name.to_lowercase().replace(' ', "_")
}

/// `rig` with `plan`'s sensor and stage faults put in place (the protocol
/// faults are the served rig's, put in place when it is served). Refused
/// when a fault names a channel the rig does not have.
pub fn inject(mut rig: OpenedRig, plan: &FaultPlan) -> Result<OpenedRig, RigError> {
    let clock = FaultClock::default();
    let stage_faults = plan.stage_faults();
    let mut stages = Vec::with_capacity(rig.stages.len());
    for mut s in rig.stages {
        let role = stage_role(s.name);
        let mine: Vec<_> = stage_faults
            .iter()
            .filter(|f| f.target.as_deref().is_none_or(|t| t == role))
            .cloned()
            .collect();
        if !mine.is_empty() {
            s.stage = Box::new(FaultyStage::new(s.stage, mine, clock.clone()));
        }
        stages.push(s);
    }
    rig.stages = stages;
    rig.sensors = Box::new(FaultySensors::new(
        rig.sensors,
        plan.sensor_faults(),
        clock,
    )?);
    Ok(rig)
}
