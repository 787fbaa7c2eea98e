//! The [`PowerStage`] trait: anything that drives the machine under test.

use async_trait::async_trait;

use crate::DriverError;

/// What a power stage can do beyond the required operations.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct StageCapabilities {
    /// The stage accepts a current limit.
    pub current_limit: bool,
    /// Largest set point magnitude the stage accepts, in its own unit.
    pub max_setpoint: f64,
}

/// A controllable output: an armature supply, a VFD, a dynamometer.
///
/// The required operations are a set point, an output enable and the safe
/// state. `safe_state` must work from any state, including after an error,
/// and must leave the output disabled with a zero set point.
#[async_trait]
pub trait PowerStage: Send {
    /// Driver id, used as `source` in recorded channel metadata.
    fn id(&self) -> &str;

    /// What this stage supports.
    fn capabilities(&self) -> StageCapabilities;

    /// Command a new set point (volts for a DC supply, rad/s for a
    /// dynamometer, …). The stage may slew towards it.
    async fn set_setpoint(&mut self, value: f64) -> Result<(), DriverError>;

    /// Enable or disable the output.
    async fn set_output_enabled(&mut self, enabled: bool) -> Result<(), DriverError>;

    /// Put the stage in its safe state: set point zero, output disabled.
    async fn safe_state(&mut self) -> Result<(), DriverError>;

    /// Limit the output current (amperes). Optional.
    async fn set_current_limit(&mut self, _amperes: f64) -> Result<(), DriverError> {
        Err(DriverError::Unsupported {
            device: self.id().to_string(),
            what: "a current limit",
        })
    }
}
